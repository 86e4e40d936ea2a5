// The logging facade: levels filter, text lines keep the service's historical form, every JSON
// line parses with the documented keys, and an asynchronous logger never makes its caller wait
// for a stuck sink (it drops the oldest records and counts them).
#include "core/common/log.h"

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/common/cli.h"

namespace evloc {
namespace {

// Collects lines; thread-safe.
struct Lines {
  LogSink Sink() {
    return [this](std::string_view line) {
      std::lock_guard<std::mutex> lock(mutex);
      lines.emplace_back(line);
    };
  }
  std::vector<std::string> Get() {
    std::lock_guard<std::mutex> lock(mutex);
    return lines;
  }
  std::mutex mutex;
  std::vector<std::string> lines;
};

TEST(Log, LevelsBelowTheThresholdAreDropped) {
  for (const bool asynchronous : {false, true}) {
    Lines lines;
    LoggerOptions options;
    options.level = LogLevel::kWarning;
    options.asynchronous = asynchronous;
    Logger logger("tool", options, lines.Sink());
    EXPECT_FALSE(logger.Enabled(LogLevel::kInfo));
    EXPECT_TRUE(logger.Enabled(LogLevel::kError));
    logger.Trace("t");
    logger.Debug("d");
    logger.Info("i");
    logger.Warning("w");
    logger.Error("e");
    logger.Critical("c");
    logger.Flush();
    EXPECT_EQ(lines.Get(), (std::vector<std::string>{"tool: warning: w", "tool: error: e",
                                                     "tool: critical: c"}));
  }
  Lines none;
  LoggerOptions off;
  off.level = LogLevel::kOff;
  Logger silent("tool", off, none.Sink());
  silent.Critical("c");
  silent.Flush();
  EXPECT_TRUE(none.Get().empty());
}

TEST(Log, TextLinesAreTheMessageAfterTheName) {
  Lines lines;
  LoggerOptions options;
  options.asynchronous = false;
  options.level = LogLevel::kTrace;
  Logger named("evloc-localizer", options, lines.Sink());
  named.Log(LogLevel::kInfo, "session 3 start: map room", {{"map", "room"}}, 3);
  named.Debug("detail");
  Logger unnamed("", options, lines.Sink());
  unnamed.Info("bare");
  EXPECT_EQ(lines.Get(), (std::vector<std::string>{"evloc-localizer: session 3 start: map room",
                                                   "evloc-localizer: debug: detail", "bare"}));
}

TEST(Log, EveryJsonLineParsesWithTimeLevelLoggerSessionMessageAndFields) {
  Lines lines;
  LoggerOptions options;
  options.format = LogFormat::kJson;
  options.level = LogLevel::kDebug;
  {
    Logger logger("evloc-localizer", options, lines.Sink());
    // Hostile text: quotes, backslashes, newlines, control bytes, invalid UTF-8, and valid UTF-8.
    const std::string hostile = std::string("a\"b\\c\nd\te\x01\x7f") + "\xff\xc3(" + "caf\xc3\xa9";
    logger.Log(LogLevel::kInfo, "session 7 start",
               {{"map", "room"}, {"points", 1234}, {"rate_hz", 300.5}, {"frames", false}}, 7);
    logger.Warning(hostile, {{hostile, hostile}, {"nan", std::nan("")}});
    logger.Debug("no fields");
    logger.Trace("filtered");
  }  // The destructor writes what is queued.
  const std::vector<std::string> got = lines.Get();
  ASSERT_EQ(got.size(), 3u);
  std::vector<nlohmann::json> records;
  for (const std::string& line : got) {
    EXPECT_EQ(line.find('\n'), std::string::npos) << line;
    ASSERT_NO_THROW(records.push_back(nlohmann::json::parse(line))) << line;
    const nlohmann::json& record = records.back();
    for (const char* key : {"time", "level", "logger", "message"}) {
      EXPECT_TRUE(record.contains(key)) << key << " in " << line;
    }
    EXPECT_EQ(record["logger"], "evloc-localizer");
    // 2026-11-25T14:30:00.123456Z
    const std::string time = record["time"];
    EXPECT_EQ(time.size(), 27u) << time;
    EXPECT_EQ(time.back(), 'Z');
    EXPECT_EQ(time[10], 'T');
  }
  EXPECT_EQ(records[0]["level"], "info");
  EXPECT_EQ(records[0]["session"], 7);
  EXPECT_EQ(records[0]["message"], "session 7 start");
  EXPECT_EQ(records[0]["fields"]["map"], "room");
  EXPECT_EQ(records[0]["fields"]["points"], 1234);
  EXPECT_DOUBLE_EQ(records[0]["fields"]["rate_hz"].get<double>(), 300.5);
  EXPECT_EQ(records[0]["fields"]["frames"], false);
  EXPECT_EQ(records[1]["level"], "warning");
  EXPECT_FALSE(records[1].contains("session"));
  const std::string expected_text =
      std::string("a\"b\\c\nd\te\x01\x7f") + "\xef\xbf\xbd\xef\xbf\xbd(" + "caf\xc3\xa9";
  EXPECT_EQ(records[1]["message"], expected_text);
  EXPECT_EQ(records[1]["fields"][expected_text], expected_text);
  EXPECT_TRUE(records[1]["fields"]["nan"].is_null());
  EXPECT_EQ(records[2]["level"], "debug");
  EXPECT_FALSE(records[2].contains("fields"));
}

TEST(Log, RenderLogLineStampsUtcTime) {
  const std::string line = RenderLogLine(LogFormat::kJson, "x", LogLevel::kError,
                                         int64_t{1'700'000'000'123'456'789}, "m", {}, 0);
  EXPECT_EQ(line,
            R"({"time":"2023-11-14T22:13:20.123456Z","level":"error","logger":"x","message":"m"})");
}

// A sink stuck on a full pipe must not stall a tracking worker: logging returns at once, the
// queue keeps the newest records, and the drops are counted.
TEST(Log, AFullQueueDropsTheOldestInsteadOfWaiting) {
  std::mutex mutex;
  std::condition_variable released;
  bool release = false;
  std::vector<std::string> written;
  LoggerOptions options;
  options.queue_records = 4;
  Logger logger("x", options, [&](std::string_view line) {
    std::unique_lock<std::mutex> lock(mutex);
    released.wait(lock, [&] { return release; });
    written.emplace_back(line);
  });
  const auto start = std::chrono::steady_clock::now();
  constexpr int kRecords = 1000;
  for (int i = 0; i < kRecords; ++i) logger.Info(std::to_string(i));
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_LT(seconds, 1.0);  // 1000 records while the sink is stuck: no waiting on it.
  // The writer holds at most one record; the queue keeps 4; the rest were dropped.
  EXPECT_GE(logger.dropped(), static_cast<uint64_t>(kRecords - 4 - 1));
  {
    std::lock_guard<std::mutex> lock(mutex);
    release = true;
  }
  released.notify_all();
  logger.Flush();
  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_EQ(written.size() + logger.dropped(), static_cast<size_t>(kRecords));
  ASSERT_FALSE(written.empty());
  EXPECT_EQ(written.back(), "x: 999");  // The newest record survives.
}

TEST(Log, FlagValuesAreStrict) {
  EXPECT_EQ(ParseLogLevel("--log-level", "trace"), LogLevel::kTrace);
  EXPECT_EQ(ParseLogLevel("--log-level", "warn"), LogLevel::kWarning);
  EXPECT_EQ(ParseLogLevel("--log-level", "critical"), LogLevel::kCritical);
  EXPECT_EQ(ParseLogLevel("--log-level", "off"), LogLevel::kOff);
  EXPECT_EQ(ParseLogFormat("--log-format", "json"), LogFormat::kJson);
  try {
    ParseLogLevel("--log-level", "INFO");
    FAIL() << "accepted INFO";
  } catch (const UsageError& error) {
    EXPECT_STREQ(error.what(),
                 "--log-level expects trace, debug, info, warning, error, critical or off, got "
                 "'INFO'");
  }
  EXPECT_THROW(ParseLogFormat("--log-format", "xml"), UsageError);
  LoggerOptions options;
  options.queue_records = 0;
  EXPECT_THROW(Logger("x", options, [](std::string_view) {}), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc
