// Latency and capacity of the localizer service on loopback at real time on the small synthetic
// scene (320x240), with evloc-replay's and evloc-load's libraries (label "long": `make
// test-long`): checks that an overloaded server refuses with RESOURCE_EXHAUSTED rather than
// losing events, and prints the figures. The quoted figures (docs/benchmarks.md §4) come from
// scripts/bench-service.sh on the 640x480 `mid` sequence.
#include <gtest/gtest.h>

#include <cstdio>
#include <sstream>

#include "core/common/error.h"
#include "core/events/evb.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "tools/load/load_driver.h"
#include "tools/replay/replay.h"

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

// Capacity on the synthetic scene: the most concurrent real-time sessions (evloc-load's driver)
// that all end OK without a Backpressure notice. A session the server cannot keep up with must end
// with the overflow error (RESOURCE_EXHAUSTED), never lose events. The figures of
// docs/benchmarks.md §4 come from scripts/bench-service.sh on the 640x480 `mid` sequence.
TEST_F(ReplayBenchmark, ConcurrentRealTimeSessions) {
  int capacity = 0;
  for (int sessions : {1, 2, 4, 8}) {
    load::LoadOptions options;
    options.server = "127.0.0.1:" + std::to_string(server_->port());
    options.map_name = fixture::kTestMapName;
    options.dataset = dataset_;
    options.sessions = sessions;
    options.session_s = 1.0;
    options.step_rate_hz = 300;
    std::ostringstream log;
    const load::LoadResult result = load::RunLoad(options, log);
    for (const auto& [status, count] : result.unplanned) {
      EXPECT_EQ(status, "RESOURCE_EXHAUSTED") << log.str();
    }
    const bool kept_up =
        result.sessions_as_planned == result.sessions && result.backpressure_notices == 0;
    std::printf(
        "%d concurrent real-time sessions: %s; %lld of %lld OK, %lld backpressure notices, "
        "server latency p50 %.0f us p99 %.0f us, client p99 %.0f us\n",
        sessions, kept_up ? "kept up" : "fell behind",
        static_cast<long long>(result.sessions_as_planned), static_cast<long long>(result.sessions),
        static_cast<long long>(result.backpressure_notices), result.server_latency_p50_us,
        result.server_latency_p99_us, result.client_latency_p99_us);
    if (!kept_up) break;
    capacity = sessions;
  }
  std::printf("capacity: %d concurrent real-time sessions (of 1, 2, 4, 8 tried)\n", capacity);
}

}  // namespace
}  // namespace evloc::replay
