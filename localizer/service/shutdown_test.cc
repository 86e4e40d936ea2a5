// The shutdown target of issue 14: a real `evloc-localizer serve` process with 8 sessions
// streaming in real time gets SIGTERM; every session gets a final status within the drain
// timeout and the process exits 0. Prints the figure (time from SIGTERM to exit, statuses) that
// docs/reliability.md quotes.
// Also: the process's JSON logs (--log-format json) are one object per line.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "localizer/service/testing/service_fixture.h"
#include "localizer/wire/status_name.h"

namespace evloc::service {
namespace {

using Clock = std::chrono::steady_clock;

// A child process running `arguments` with its standard output on a pipe.
class ChildProcess {
 public:
  explicit ChildProcess(const std::vector<std::string>& arguments) {
    int pipe_ends[2];
    if (::pipe(pipe_ends) != 0) return;
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(pipe_ends[1], STDOUT_FILENO);
      ::close(pipe_ends[0]);
      ::close(pipe_ends[1]);
      std::vector<char*> argv;
      for (const std::string& argument : arguments)
        argv.push_back(const_cast<char*>(argument.c_str()));
      argv.push_back(nullptr);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    ::close(pipe_ends[1]);
    output_ = ::fdopen(pipe_ends[0], "r");
    reader_ = std::thread([this] {
      char line[4096];
      while (output_ && std::fgets(line, sizeof(line), output_)) {
        std::lock_guard<std::mutex> lock(mutex_);
        lines_.emplace_back(line);
      }
    });
  }
  ~ChildProcess() {
    if (pid_ > 0 && !exited_) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (reader_.joinable()) reader_.join();
    if (output_) std::fclose(output_);
  }

  pid_t pid() const { return pid_; }
  std::vector<std::string> lines() {
    std::lock_guard<std::mutex> lock(mutex_);
    return lines_;
  }
  // Waits up to `timeout` for the exit; the wait status, or nullopt when still running.
  std::optional<int> WaitForExit(Clock::duration timeout) {
    const auto end = Clock::now() + timeout;
    while (Clock::now() < end) {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        exited_ = true;
        return status;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return std::nullopt;
  }

 private:
  pid_t pid_ = -1;
  bool exited_ = false;
  FILE* output_ = nullptr;
  std::thread reader_;
  std::mutex mutex_;
  std::vector<std::string> lines_;
};

// What one streaming client saw.
struct ClientResult {
  bool started = false;
  std::atomic<int> poses{0};
  bool session_end = false;
  grpc::Status status;
  Clock::time_point finished;
};

// Streams the synthetic events in 1 ms packets at real time at most (then empty packets), at
// most 30 ms of session time ahead of the last pose (on a loaded machine the stream slows down
// instead of overflowing the queue), until the stream fails or `stop` is set; records the final
// status.
void StreamUntilEnded(api::Localizer::Stub& stub, const std::vector<api::TrackRequest>& packets,
                      const std::atomic<bool>& stop, ClientResult* result) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
  auto stream = stub.Track(&context);
  api::TrackResponse response;
  if (!stream->Write(testing::TestSessionStart()) || !stream->Read(&response) ||
      !response.has_started()) {
    result->status = stream->Finish();
    result->finished = Clock::now();
    return;
  }
  result->started = true;
  std::atomic<int64_t> last_pose_t_ns{testing::kInitialTimeNs};
  std::thread reader([&] {
    while (stream->Read(&response)) {
      if (response.has_pose()) {
        ++result->poses;
        last_pose_t_ns = response.pose().t_ns();
      }
      if (response.has_end()) result->session_end = true;
    }
  });
  const auto start = Clock::now();
  int64_t end_t_ns = packets.back().events().end_t_ns();
  for (size_t i = 0; !stop; ++i) {
    std::this_thread::sleep_until(start + std::chrono::milliseconds(i));
    api::TrackRequest packet;
    if (i < packets.size()) {
      packet = packets[i];
    } else {
      end_t_ns += 1'000'000;
      packet.mutable_events()->set_end_t_ns(end_t_ns);
    }
    while (!stop && packet.events().end_t_ns() > last_pose_t_ns + 30'000'000) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    if (!stream->Write(packet)) break;
  }
  stream->WritesDone();
  reader.join();
  result->status = stream->Finish();
  result->finished = Clock::now();
}

TEST(LocalizerShutdown, SigtermEndsEightStreamingSessionsWithinTheDrainTimeoutAndExitsZero) {
  constexpr int kSessions = 8;
  constexpr double kDrainTimeoutS = 5.0;
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), testing::kTestMapName, testing::TestMap());
  ChildProcess server({EVLOC_LOCALIZER_BINARY, "serve", "--maps", folder.path().string(),
                       "--listen", "127.0.0.1:0", "--max-sessions", std::to_string(kSessions),
                       "--drain-timeout", std::to_string(kDrainTimeoutS)});
  ASSERT_GT(server.pid(), 0);
  int port = 0;
  for (int i = 0; i < 3000 && port == 0; ++i) {
    for (const std::string& line : server.lines()) {
      const size_t at = line.find("serving on port ");
      if (at != std::string::npos) port = std::stoi(line.substr(at + 16));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_NE(port, 0) << "the server did not start";
  const auto packets = testing::PackedPackets(testing::TestEvents(1'000'000'000), 1'000'000);
  auto stub = testing::ConnectStub(port);
  std::atomic<bool> stop{false};
  std::vector<ClientResult> results(kSessions);
  std::vector<std::thread> clients;
  for (int i = 0; i < kSessions; ++i) {
    clients.emplace_back([&, i] { StreamUntilEnded(*stub, packets, stop, &results[i]); });
  }
  // Every session runs and has sent poses.
  bool running = false;
  for (int i = 0; i < 3000 && !running; ++i) {
    running = true;
    for (const ClientResult& result : results) running &= result.poses >= 20;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(running) << "not every session tracked";
  const auto sigterm = Clock::now();
  ASSERT_EQ(::kill(server.pid(), SIGTERM), 0);
  const std::optional<int> exit_status =
      server.WaitForExit(std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(kDrainTimeoutS + 10)));
  const auto exited = Clock::now();
  stop = true;
  for (std::thread& client : clients) client.join();
  ASSERT_TRUE(exit_status.has_value()) << "the server did not exit";
  EXPECT_TRUE(WIFEXITED(*exit_status) && WEXITSTATUS(*exit_status) == 0) << *exit_status;
  const double to_exit_s = std::chrono::duration<double>(exited - sigterm).count();
  EXPECT_LT(to_exit_s, kDrainTimeoutS + 1.0);
  std::map<std::string, int> statuses;
  double last_status_s = 0;
  for (const ClientResult& result : results) {
    EXPECT_TRUE(result.started);
    const bool draining = result.status.error_code() == grpc::StatusCode::UNAVAILABLE &&
                          result.status.error_message().find("draining") != std::string::npos;
    EXPECT_TRUE(draining || (result.status.ok() && result.session_end))
        << wire::StatusCodeName(result.status.error_code()) << ": "
        << result.status.error_message();
    ++statuses[std::string(wire::StatusCodeName(result.status.error_code())) +
               (draining ? " draining" : "")];
    last_status_s =
        std::max(last_status_s, std::chrono::duration<double>(result.finished - sigterm).count());
  }
  EXPECT_LT(last_status_s, kDrainTimeoutS);
  std::string figure = "SIGTERM with " + std::to_string(kSessions) + " sessions: exit 0 after " +
                       std::to_string(to_exit_s) + " s; last final status after " +
                       std::to_string(last_status_s) + " s; statuses:";
  for (const auto& [name, count] : statuses) figure += " " + std::to_string(count) + " " + name;
  std::cout << figure << std::endl;
  ::testing::Test::RecordProperty("figure", figure);
}

// `serve --log-format json`: every line the process writes, from the configuration to
// "stopped", is one JSON object; a session's records carry its id.
TEST(LocalizerProcessLogs, JsonFormatWritesOneObjectPerLine) {
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), testing::kTestMapName, testing::TestMap());
  ChildProcess server({EVLOC_LOCALIZER_BINARY, "serve", "--maps", folder.path().string(),
                       "--listen", "127.0.0.1:0", "--log-format", "json", "--log-level", "info"});
  ASSERT_GT(server.pid(), 0);
  int port = 0;
  for (int i = 0; i < 3000 && port == 0; ++i) {
    for (const std::string& line : server.lines()) {
      const nlohmann::json record = nlohmann::json::parse(line, nullptr, false);
      if (!record.is_discarded() && record.contains("fields") &&
          record["fields"].contains("port")) {
        port = record["fields"]["port"];
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_NE(port, 0) << "the server did not start";
  auto stub = testing::ConnectStub(port);
  const auto packets = testing::PackedPackets(testing::TestEvents(1'000'000'000), 1'000'000);
  std::atomic<bool> stop{false};
  ClientResult result;
  std::thread client([&] { StreamUntilEnded(*stub, packets, stop, &result); });
  for (int i = 0; i < 3000 && result.poses < 20; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  stop = true;
  client.join();
  EXPECT_TRUE(result.status.ok()) << result.status.error_message();
  ASSERT_EQ(::kill(server.pid(), SIGTERM), 0);
  const std::optional<int> exit_status = server.WaitForExit(std::chrono::seconds(20));
  ASSERT_TRUE(exit_status.has_value()) << "the server did not exit";
  EXPECT_TRUE(WIFEXITED(*exit_status) && WEXITSTATUS(*exit_status) == 0) << *exit_status;
  std::vector<std::string> messages;
  int session_records = 0;
  for (const std::string& line : server.lines()) {
    nlohmann::json record;
    ASSERT_NO_THROW(record = nlohmann::json::parse(line)) << line;
    ASSERT_TRUE(record.is_object()) << line;
    EXPECT_EQ(record["logger"], "evloc-localizer") << line;
    EXPECT_EQ(record["level"], "info") << line;
    EXPECT_TRUE(record["time"].is_string()) << line;
    messages.push_back(record["message"]);
    if (record.contains("session")) {
      EXPECT_EQ(record["session"], 1) << line;
      ++session_records;
    }
  }
  EXPECT_EQ(session_records, 2);  // Start and end.
  ASSERT_GE(messages.size(), 5u);
  EXPECT_EQ(messages.front(), "effective configuration");
  EXPECT_EQ(messages.back(), "stopped");
}

}  // namespace
}  // namespace evloc::service
