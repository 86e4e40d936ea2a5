#include "core/common/log.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <thread>

#include <spdlog/async.h>
#include <spdlog/async_logger.h>
#include <spdlog/details/thread_pool.h>
#include <spdlog/logger.h>
#include <spdlog/sinks/base_sink.h>

#include "core/common/cli.h"
#include "core/common/error.h"

namespace evloc {
namespace {

// Every level with its spdlog level and its name.
struct LevelEntry {
  LogLevel level;
  spdlog::level::level_enum spdlog_level;
  std::string_view name;
};
constexpr LevelEntry kLevels[] = {{LogLevel::kTrace, spdlog::level::trace, "trace"},
                                  {LogLevel::kDebug, spdlog::level::debug, "debug"},
                                  {LogLevel::kInfo, spdlog::level::info, "info"},
                                  {LogLevel::kWarning, spdlog::level::warn, "warning"},
                                  {LogLevel::kError, spdlog::level::err, "error"},
                                  {LogLevel::kCritical, spdlog::level::critical, "critical"},
                                  {LogLevel::kOff, spdlog::level::off, "off"}};

spdlog::level::level_enum ToSpdlog(LogLevel level) {
  for (const LevelEntry& entry : kLevels) {
    if (entry.level == level) return entry.spdlog_level;
  }
  return spdlog::level::off;
}

LogLevel FromSpdlog(spdlog::level::level_enum level) {
  for (const LevelEntry& entry : kLevels) {
    if (entry.spdlog_level == level) return entry.level;
  }
  return LogLevel::kOff;
}

// The length of the valid UTF-8 sequence at text[i] (0 when invalid).
size_t Utf8SequenceLength(std::string_view text, size_t i) {
  const auto byte = [&](size_t k) { return static_cast<unsigned char>(text[k]); };
  const unsigned char lead = byte(i);
  size_t length = 0;
  uint32_t code = 0;
  if (lead >= 0xC2 && lead <= 0xDF) {
    length = 2;
    code = lead & 0x1F;
  } else if (lead >= 0xE0 && lead <= 0xEF) {
    length = 3;
    code = lead & 0x0F;
  } else if (lead >= 0xF0 && lead <= 0xF4) {
    length = 4;
    code = lead & 0x07;
  } else {
    return 0;
  }
  if (i + length > text.size()) return 0;
  for (size_t k = 1; k < length; ++k) {
    if ((byte(i + k) & 0xC0) != 0x80) return 0;
    code = (code << 6) | (byte(i + k) & 0x3F);
  }
  // No overlong forms, no surrogates, nothing above U+10FFFF.
  if ((length == 3 && code < 0x800) || (length == 4 && (code < 0x10000 || code > 0x10FFFF)) ||
      (code >= 0xD800 && code <= 0xDFFF)) {
    return 0;
  }
  return length;
}

// The part of a line the logging thread renders: everything but time, level and logger name.
std::string RenderPayload(LogFormat format, std::string_view message, const LogField* fields_begin,
                          const LogField* fields_end, uint64_t session) {
  if (format == LogFormat::kText) return std::string(message);
  std::string payload;
  payload.reserve(message.size() + 64);
  if (session != 0) payload += "\"session\":" + std::to_string(session) + ",";
  payload += "\"message\":\"" + JsonEscape(message) + "\"";
  if (fields_begin != fields_end) {
    payload += ",\"fields\":{";
    for (const LogField* field = fields_begin; field != fields_end; ++field) {
      if (field != fields_begin) payload += ',';
      payload += '"' + JsonEscape(field->key) + "\":" + field->json;
    }
    payload += '}';
  }
  return payload;
}

// The whole line from the payload.
void ComposeLine(LogFormat format, std::string_view logger_name, LogLevel level, int64_t time_ns,
                 std::string_view payload, std::string* line) {
  if (format == LogFormat::kText) {
    if (!logger_name.empty()) line->append(logger_name).append(": ");
    if (level != LogLevel::kInfo) line->append(LogLevelName(level)).append(": ");
    line->append(payload);
    return;
  }
  const std::time_t seconds = static_cast<std::time_t>(time_ns / 1'000'000'000);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char time_text[48];
  std::snprintf(time_text, sizeof(time_text), "%04d-%02d-%02dT%02d:%02d:%02d.%06dZ",
                utc.tm_year + 1900, utc.tm_mon + 1, utc.tm_mday, utc.tm_hour, utc.tm_min,
                utc.tm_sec, static_cast<int>((time_ns % 1'000'000'000) / 1000));
  line->append("{\"time\":\"").append(time_text).append("\",\"level\":\"");
  line->append(LogLevelName(level)).append("\",\"logger\":\"").append(JsonEscape(logger_name));
  line->append("\",").append(payload).append("}");
}

int64_t NanosecondsSinceEpoch(std::chrono::system_clock::time_point time) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(time.time_since_epoch()).count();
}

// The spdlog sink of a Logger: composes each record's line and hands it to the LogSink,
// counting what it wrote (for Flush).
class CallbackSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  CallbackSink(LogFormat format, LogSink sink) : format_(format), sink_(std::move(sink)) {}

  uint64_t written() const { return written_.load(); }

 protected:
  void sink_it_(const spdlog::details::log_msg& message) override {
    line_.clear();
    ComposeLine(format_, std::string_view(message.logger_name.data(), message.logger_name.size()),
                FromSpdlog(message.level), NanosecondsSinceEpoch(message.time),
                std::string_view(message.payload.data(), message.payload.size()), &line_);
    // Counted even when the sink throws (spdlog reports that on stderr), so Flush never waits
    // for a record that will not come.
    struct CountOnExit {
      std::atomic<uint64_t>* written;
      ~CountOnExit() { written->fetch_add(1); }
    } count{&written_};
    sink_(line_);
  }
  void flush_() override {}

 private:
  const LogFormat format_;
  const LogSink sink_;
  std::string line_;
  std::atomic<uint64_t> written_{0};
};

}  // namespace

std::string_view LogLevelName(LogLevel level) {
  for (const LevelEntry& entry : kLevels) {
    if (entry.level == level) return entry.name;
  }
  return "off";
}

LogLevel ParseLogLevel(std::string_view flag, std::string_view text) {
  for (const LevelEntry& entry : kLevels) {
    if (text == entry.name) return entry.level;
  }
  if (text == "warn") return LogLevel::kWarning;
  throw UsageError(std::string(flag) +
                   " expects trace, debug, info, warning, error, critical or off, got '" +
                   std::string(text) + "'");
}

LogFormat ParseLogFormat(std::string_view flag, std::string_view text) {
  if (text == "text") return LogFormat::kText;
  if (text == "json") return LogFormat::kJson;
  throw UsageError(std::string(flag) + " expects text or json, got '" + std::string(text) + "'");
}

std::string JsonEscape(std::string_view text) {
  std::string escaped;
  escaped.reserve(text.size() + 8);
  for (size_t i = 0; i < text.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '"' || c == '\\') {
      escaped += '\\';
      escaped += static_cast<char>(c);
    } else if (c == '\n') {
      escaped += "\\n";
    } else if (c == '\t') {
      escaped += "\\t";
    } else if (c == '\r') {
      escaped += "\\r";
    } else if (c < 0x20 || c == 0x7F) {
      char code[8];
      std::snprintf(code, sizeof(code), "\\u%04x", c);
      escaped += code;
    } else if (c < 0x80) {
      escaped += static_cast<char>(c);
    } else if (const size_t length = Utf8SequenceLength(text, i); length > 0) {
      escaped.append(text.substr(i, length));
      i += length - 1;
    } else {
      escaped += "\\ufffd";
    }
  }
  return escaped;
}

LogField::LogField(std::string_view key, std::string_view text)
    : key(key), json("\"" + JsonEscape(text) + "\"") {}

LogField::LogField(std::string_view key, double number) : key(key) {
  if (!std::isfinite(number)) {
    json = "null";
    return;
  }
  char text[32];
  std::snprintf(text, sizeof(text), "%.17g", number);
  json = text;
}

LogField::LogField(std::string_view key, bool value) : key(key), json(value ? "true" : "false") {}

void LoggerOptions::Check() const {
  if (asynchronous && queue_records == 0) {
    throw InvalidArgumentError("the log queue must hold at least one record");
  }
}

LogSink StandardOutputSink() {
  return [](std::string_view line) {
    std::fwrite(line.data(), 1, line.size(), stdout);
    std::fputc('\n', stdout);
    std::fflush(stdout);
  };
}

std::string RenderLogLine(LogFormat format, std::string_view logger_name, LogLevel level,
                          int64_t time_ns, std::string_view message,
                          const std::vector<LogField>& fields, uint64_t session) {
  const std::string payload =
      RenderPayload(format, message, fields.data(), fields.data() + fields.size(), session);
  std::string line;
  ComposeLine(format, logger_name, level, time_ns, payload, &line);
  return line;
}

class Logger::Impl {
 public:
  std::shared_ptr<CallbackSink> sink;
  // Only for an asynchronous logger: the queue and its writer thread.
  std::shared_ptr<spdlog::details::thread_pool> pool;
  std::shared_ptr<spdlog::logger> logger;
  // Records handed to spdlog.
  std::atomic<uint64_t> submitted{0};
};

Logger::Logger(std::string name, const LoggerOptions& options, LogSink sink)
    : format_(options.format), level_(options.level), impl_(std::make_unique<Impl>()) {
  options.Check();
  if (!sink) throw InvalidArgumentError("a logger needs a sink");
  impl_->sink = std::make_shared<CallbackSink>(options.format, std::move(sink));
  if (options.asynchronous) {
    impl_->pool = std::make_shared<spdlog::details::thread_pool>(options.queue_records, 1);
    impl_->logger = std::make_shared<spdlog::async_logger>(
        std::move(name), impl_->sink, impl_->pool, spdlog::async_overflow_policy::overrun_oldest);
  } else {
    impl_->logger = std::make_shared<spdlog::logger>(std::move(name), impl_->sink);
  }
  impl_->logger->set_level(spdlog::level::trace);  // Filtered by Enabled() before rendering.
  impl_->logger->flush_on(spdlog::level::off);
}

Logger::~Logger() {
  Flush();
  impl_->logger.reset();
  impl_->pool.reset();  // Joins the writer thread.
}

bool Logger::Enabled(LogLevel level) const { return level != LogLevel::kOff && level >= level_; }

void Logger::Log(LogLevel level, std::string_view message, std::initializer_list<LogField> fields,
                 uint64_t session) {
  Submit(level, message, fields.begin(), fields.end(), session);
}

void Logger::Log(LogLevel level, std::string_view message, const std::vector<LogField>& fields,
                 uint64_t session) {
  Submit(level, message, fields.data(), fields.data() + fields.size(), session);
}

void Logger::Submit(LogLevel level, std::string_view message, const LogField* fields_begin,
                    const LogField* fields_end, uint64_t session) {
  if (!Enabled(level)) return;
  try {
    const std::string payload = RenderPayload(format_, message, fields_begin, fields_end, session);
    impl_->submitted.fetch_add(1);
    impl_->logger->log(ToSpdlog(level), spdlog::string_view_t(payload.data(), payload.size()));
  } catch (...) {
    // A record that cannot be rendered (out of memory) is lost; logging never throws.
  }
}

void Logger::Flush() {
  const uint64_t target = impl_->submitted.load();
  if (!impl_->pool) return;
  // The writer thread takes records in order: wait until every record submitted so far was
  // written or dropped.
  while (impl_->sink->written() + impl_->pool->overrun_counter() < target) {
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
}

uint64_t Logger::dropped() const { return impl_->pool ? impl_->pool->overrun_counter() : 0; }

}  // namespace evloc
