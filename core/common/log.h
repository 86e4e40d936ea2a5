// The one logging facade of evloc (on spdlog): levels trace .. critical, two line formats (text
// for people, JSON lines for log collectors), and an asynchronous writer so that a thread that
// logs (a tracking worker of the service) never waits for a terminal, a pipe or a disk.
//
// A record is a level, a message, optional typed fields and an optional session id. Rendered:
//   text  NAME: MESSAGE                      (level info; the service's historical line)
//         NAME: LEVEL: MESSAGE               (any other level, e.g. "evloc-localizer: warning:
//         ...")
//   json  {"time":"2026-01-02T03:04:05.678901Z","level":"info","logger":"NAME","session":7,
//          "message":"MESSAGE","fields":{"key":value,...}}
// one record per line (a message's control characters are escaped in JSON; text messages are
// the caller's, who escapes client text: localizer/service/client_text.h). "session" and
// "fields" appear only when there are some. Library code keeps not logging (docs/conventions.md):
// the facade is for the service and the tools' main()s.
#pragma once

#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace evloc {

// Severity of a record, lowest first; kOff as a threshold logs nothing.
enum class LogLevel { kTrace, kDebug, kInfo, kWarning, kError, kCritical, kOff };

// How records are rendered into lines.
enum class LogFormat { kText, kJson };

// "trace", "debug", "info", "warning", "error", "critical", "off".
std::string_view LogLevelName(LogLevel level);

// Parses a --log-level value (one of LogLevelName's names; "warn" is taken for "warning").
// Throws UsageError "FLAG expects trace, debug, info, warning, error, critical or off, got 'X'".
LogLevel ParseLogLevel(std::string_view flag, std::string_view text);

// Parses a --log-format value, "text" or "json". Throws UsageError.
LogFormat ParseLogFormat(std::string_view flag, std::string_view text);

// One key and value of a record. Numbers stay numbers in JSON (non-finite doubles become null);
// text is escaped.
struct LogField {
  LogField(std::string_view key, std::string_view text);
  LogField(std::string_view key, const char* text) : LogField(key, std::string_view(text)) {}
  LogField(std::string_view key, const std::string& text) : LogField(key, std::string_view(text)) {}
  LogField(std::string_view key, double number);
  LogField(std::string_view key, bool value);
  template <typename Integer, typename = std::enable_if_t<std::is_integral_v<Integer> &&
                                                          !std::is_same_v<Integer, bool>>>
  LogField(std::string_view key, Integer number) : key(key), json(std::to_string(number)) {}

  // The key.
  std::string key;
  // The value as JSON text (a quoted, escaped string, a number, true/false or null).
  std::string json;
};

// How a Logger filters, renders and queues.
struct LoggerOptions {
  // Records below this level are dropped before they are rendered (cheap).
  LogLevel level = LogLevel::kInfo;
  // Line format.
  LogFormat format = LogFormat::kText;
  // Records are handed to one writer thread through a queue of this many records; a full queue
  // drops its oldest record (counted by Logger::dropped()) rather than make the caller wait.
  // false: the caller renders and writes the line itself (tests, short-lived tools).
  bool asynchronous = true;
  // Capacity of the queue of an asynchronous logger, records (>= 1).
  size_t queue_records = 8192;

  // Throws InvalidArgumentError for a zero queue.
  void Check() const;
};

// Receives every rendered line, without its newline: on the writer thread of an asynchronous
// logger (one line at a time), on the logging thread of a synchronous one (serialised by the
// logger).
using LogSink = std::function<void(std::string_view line)>;

// A sink that writes each line and a newline to standard output and flushes it (a log collector
// or `tee` sees every record at once).
LogSink StandardOutputSink();

// A named logger. Thread-safe: any thread may log; the sink sees whole lines, one at a time.
class Logger {
 public:
  // `name` is the "logger" of JSON records and the "NAME: " prefix of text lines (none when
  // empty). Throws InvalidArgumentError for invalid options.
  Logger(std::string name, const LoggerOptions& options, LogSink sink);
  // Writes the records still queued, then stops the writer thread.
  ~Logger();
  Logger(const Logger&) = delete;
  Logger& operator=(const Logger&) = delete;

  // True when a record of `level` would be written (test this before building costly fields).
  bool Enabled(LogLevel level) const;
  // Logs a record; `session` 0 means none. Never throws, never waits for the sink when
  // asynchronous (only for the queue's mutex, held for a copy).
  void Log(LogLevel level, std::string_view message, std::initializer_list<LogField> fields = {},
           uint64_t session = 0);
  // The same with fields built at run time.
  void Log(LogLevel level, std::string_view message, const std::vector<LogField>& fields,
           uint64_t session = 0);

  void Trace(std::string_view message, std::initializer_list<LogField> fields = {}) {
    Log(LogLevel::kTrace, message, fields);
  }
  void Debug(std::string_view message, std::initializer_list<LogField> fields = {}) {
    Log(LogLevel::kDebug, message, fields);
  }
  void Info(std::string_view message, std::initializer_list<LogField> fields = {}) {
    Log(LogLevel::kInfo, message, fields);
  }
  void Warning(std::string_view message, std::initializer_list<LogField> fields = {}) {
    Log(LogLevel::kWarning, message, fields);
  }
  void Error(std::string_view message, std::initializer_list<LogField> fields = {}) {
    Log(LogLevel::kError, message, fields);
  }
  void Critical(std::string_view message, std::initializer_list<LogField> fields = {}) {
    Log(LogLevel::kCritical, message, fields);
  }

  // Blocks until every record logged before the call has reached the sink.
  void Flush();
  // Records dropped because the queue was full, since construction.
  uint64_t dropped() const;
  // The line format.
  LogFormat format() const { return format_; }
  // The threshold.
  LogLevel level() const { return level_; }

 private:
  // Renders and queues (or writes) one record.
  void Submit(LogLevel level, std::string_view message, const LogField* fields_begin,
              const LogField* fields_end, uint64_t session);

  class Impl;
  LogFormat format_;
  LogLevel level_;
  std::unique_ptr<Impl> impl_;
};

// Renders one record as a line (what a Logger hands its sink; `time_ns` is since the Unix epoch,
// UTC). For tests and for the rare writer that needs a line without a Logger.
std::string RenderLogLine(LogFormat format, std::string_view logger_name, LogLevel level,
                          int64_t time_ns, std::string_view message,
                          const std::vector<LogField>& fields, uint64_t session);

// `text` as the body of a JSON string (quotes, backslashes and control characters escaped;
// invalid UTF-8 bytes become U+FFFD so that every line stays valid JSON).
std::string JsonEscape(std::string_view text);

}  // namespace evloc
