// Latency and capacity of the localizer service on loopback, measured with evloc-replay's
// library at real time on the synthetic scene (label "long": `make test-long`). Prints the
// figures quoted in docs/benchmarks.md.
#include <gtest/gtest.h>

#include <cstdio>
#include <sstream>
#include <thread>

#include "core/common/error.h"
#include "core/events/evb.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "tools/replay/replay.h"
#include "tools/sim/dataset.h"

namespace evloc::replay {
namespace {

namespace fixture = service::testing;

constexpr int64_t kDurationNs = 1'500'000'000;

class ReplayBenchmark : public ::testing::Test {
 protected:
  void SetUp() override {
    fixture::WriteTestMap(folder_.path() / "maps", fixture::kTestMapName, fixture::TestMap());
    dataset_ = fixture::WriteTestDataset(folder_.path(), kDurationNs);
    service::LocalizerServerOptions options = fixture::TestServerOptions(folder_.path() / "maps");
    options.max_sessions = 16;
    server_ = std::make_unique<service::LocalizerServer>(options);
  }

  ReplayOptions Options(int index) const {
    ReplayOptions options;
    options.server = "127.0.0.1:" + std::to_string(server_->port());
    options.map_name = fixture::kTestMapName;
    options.dataset = dataset_;
    options.output = folder_.path() / ("trajectory_" + std::to_string(index) + ".txt");
    options.speed = 1.0;
    options.step_rate_hz = 300;
    return options;
  }

  fixture::TemporaryFolder folder_;
  std::filesystem::path dataset_;
  std::unique_ptr<service::LocalizerServer> server_;
};

// Latency of one real-time session. On a machine too busy to track at real time the session
// must end with the overflow error rather than drop events; the figures are printed either way.
TEST_F(ReplayBenchmark, OneRealTimeSessionLatency) {
  std::ostringstream log;
  try {
    const ReplayResult result = RunReplay(Options(0), log);
    std::printf(
        "one session, 300 Hz, 1 ms packets, %zu poses: server latency p50 %.0f us p99 %.0f us; "
        "client latency p50 %.0f us p99 %.0f us; outside the step p50 %.0f us p99 %.0f us; "
        "median step %.2f ms\n",
        result.trajectory.size(), result.server_latency_p50_us, result.server_latency_p99_us,
        result.client_latency_p50_us, result.client_latency_p99_us, result.server_overhead_p50_us,
        result.server_overhead_p99_us, result.step_p50_ms);
    EXPECT_GE(result.trajectory.size(), 400u);
    EXPECT_EQ(result.lost_poses, 0);
    EXPECT_GT(result.server_latency_p99_us, 0);
  } catch (const Error& error) {
    std::printf("one session could not keep real time on this machine: %s\n", error.what());
    EXPECT_NE(std::string(error.what()).find("overflowed"), std::string::npos) << error.what();
  }
}

// Capacity: the most concurrent real-time sessions that all complete. A session the server
// cannot keep up with must end with the overflow error (RESOURCE_EXHAUSTED), never lose events.
TEST_F(ReplayBenchmark, ConcurrentRealTimeSessions) {
  int capacity = 0;
  for (int sessions : {1, 2, 4, 8}) {
    std::vector<ReplayResult> results(static_cast<size_t>(sessions));
    std::vector<std::string> errors(static_cast<size_t>(sessions));
    std::vector<std::thread> threads;
    for (int i = 0; i < sessions; ++i) {
      threads.emplace_back([&, i] {
        std::ostringstream log;
        try {
          results[static_cast<size_t>(i)] = RunReplay(Options(i), log);
        } catch (const std::exception& error) {
          errors[static_cast<size_t>(i)] = error.what();
        }
      });
    }
    for (auto& thread : threads) thread.join();
    double worst_p99 = 0;
    int failed = 0;
    for (size_t i = 0; i < results.size(); ++i) {
      if (!errors[i].empty()) {
        ++failed;
        EXPECT_NE(errors[i].find("overflowed"), std::string::npos) << errors[i];
        continue;
      }
      EXPECT_EQ(results[i].lost_poses, 0);
      EXPECT_GE(results[i].trajectory.size(), 400u);
      worst_p99 = std::max(worst_p99, results[i].server_latency_p99_us);
    }
    std::printf(
        "%d concurrent real-time sessions: %d failed (queue overflow), worst server p99 "
        "of the others %.0f us\n",
        sessions, failed, worst_p99);
    if (failed > 0) break;
    capacity = sessions;
  }
  std::printf("capacity: %d concurrent real-time sessions (of 1, 2, 4, 8 tried)\n", capacity);
}

}  // namespace
}  // namespace evloc::replay
