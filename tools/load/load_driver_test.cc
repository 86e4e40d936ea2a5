#include "tools/load/load_driver.h"

#include <gtest/gtest.h>

#include <iostream>
#include <sstream>
#include <thread>

#include "core/common/error.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"

namespace evloc::load {
namespace {

namespace fixture = service::testing;

TEST(LoadDriver, SessionsEndAsPlannedAndTheServerIsClean) {
  fixture::TemporaryFolder folder;
  fixture::WriteTestMap(folder.path() / "maps", fixture::kTestMapName, fixture::TestMap());
  service::LocalizerServerOptions server_options =
      fixture::TestServerOptions(folder.path() / "maps");
  // A cancelled session keeps its server slot until the server has noticed the cancel (up to a
  // step later) while the client slot opens the next one: room for more than the 3 slots.
  server_options.max_sessions = 8;
  service::LocalizerServer server(server_options);

  LoadOptions options;
  options.server = "127.0.0.1:" + std::to_string(server.port());
  options.map_name = fixture::kTestMapName;
  options.dataset = fixture::WriteTestDataset(folder.path(), 150'000'000);
  options.sessions = 3;
  options.session_s = 0.1;
  options.duration_s = 1.0;
  options.speed = std::nullopt;
  options.step_rate_hz = 200;
  options.cancel_fraction = 0.3;
  options.bad_fraction = 0.3;
  options.report = folder.path() / "load.json";
  std::ostringstream log;
  const LoadResult result = RunLoad(options, log);
  EXPECT_GE(result.sessions, 3);
  EXPECT_EQ(result.sessions_as_planned, result.sessions) << log.str();
  EXPECT_EQ(result.normal_sessions + result.cancelled_sessions + result.bad_packet_sessions,
            result.sessions);
  EXPECT_GT(result.poses, 10);
  EXPECT_GT(result.server_latency_p50_us, 0);
  EXPECT_GE(result.client_latency_max_us, result.client_latency_p99_us);
  EXPECT_TRUE(std::filesystem::exists(folder.path() / "load.json"));
  // Every session, however it ended, has released its slot.
  for (int i = 0; i < 500 && server.counters().sessions_active != 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(server.counters().sessions_active, 0);
}

// --stagger: the sessions start along the dataset from its ground truth there (a wrong start
// pose would be LOST on the moving test scene), with its velocity there on request, and a
// stagger beyond the dataset is refused.
TEST(LoadDriver, StaggeredSessionsStartAlongTheDatasetFromItsGroundTruth) {
  fixture::TemporaryFolder folder;
  fixture::WriteTestMap(folder.path() / "maps", fixture::kTestMapName, fixture::TestMap());
  service::LocalizerServer server(fixture::TestServerOptions(folder.path() / "maps"));
  LoadOptions options;
  options.server = "127.0.0.1:" + std::to_string(server.port());
  options.map_name = fixture::kTestMapName;
  // Events fired as rendered ones are (see the velocity below).
  options.dataset = fixture::WriteTestDataset(folder.path(), 600'000'000,
                                              tracking::testing::EdgeEventTiming::kCrossCentre);
  options.sessions = 3;
  options.session_s = 0.1;
  options.speed = std::nullopt;
  options.step_rate_hz = 200;
  options.stagger_count = 3;
  options.stagger_s = 0.2;
  std::ostringstream log;
  const LoadResult result = RunLoad(options, log);
  EXPECT_EQ(result.sessions, 3);
  EXPECT_EQ(result.sessions_as_planned, 3) << log.str();
  EXPECT_NE(log.str().find("the first of 3 starts"), std::string::npos) << log.str();
  // 0.1 s at 200 Hz per session.
  EXPECT_GE(result.poses, 3 * 18);
  EXPECT_EQ(server.counters().lost_poses, 0);
  EXPECT_LT(result.error_max_m, 0.02);  // every session tracked from its own start

  // --initial-velocity truth: the sessions start moving with the scene's camera instead of at
  // rest, so their first steps do not fall behind it (largest error 8.4 mm against 12.8 mm).
  options.initial_velocity_from_truth = true;
  const LoadResult moving = RunLoad(options, log);
  std::cout << "largest error: at rest " << result.error_max_m * 1e3 << " mm, with the velocity "
            << moving.error_max_m * 1e3 << " mm\n";
  EXPECT_EQ(moving.sessions_as_planned, 3) << log.str();
  EXPECT_LT(moving.error_max_m, result.error_max_m);
  options.initial_velocity_from_truth = false;

  options.stagger_s = 0.3;  // the last session would end at 0.7 s
  try {
    RunLoad(options, log);
    ADD_FAILURE() << "a stagger beyond the dataset was accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("--stagger"), std::string::npos) << error.what();
  }
}

TEST(LoadDriver, CommandLineMapsToOptions) {
  bool help = false;
  const LoadOptions options = ParseLoadCommandLine({"--server",
                                                    "h:1",
                                                    "--map",
                                                    "m",
                                                    "--dataset",
                                                    "d",
                                                    "--sessions",
                                                    "32",
                                                    "--session-s",
                                                    "0.5",
                                                    "--duration",
                                                    "600",
                                                    "--speed",
                                                    "max",
                                                    "--cancel-fraction",
                                                    "0.1",
                                                    "--bad-fraction",
                                                    "0.2",
                                                    "--seed",
                                                    "7",
                                                    "--rate",
                                                    "300",
                                                    "--packet-us",
                                                    "500",
                                                    "--stagger",
                                                    "20:2.5",
                                                    "--initial-velocity",
                                                    "truth",
                                                    "--report",
                                                    "r.json"},
                                                   &help);
  EXPECT_EQ(options.sessions, 32);
  EXPECT_EQ(options.session_s, 0.5);
  EXPECT_EQ(options.duration_s, 600);
  EXPECT_FALSE(options.speed.has_value());
  EXPECT_EQ(options.bad_fraction, 0.2);
  EXPECT_EQ(options.packet_us, 500);
  EXPECT_EQ(options.stagger_count, 20);
  EXPECT_EQ(options.stagger_s, 2.5);
  EXPECT_TRUE(options.initial_velocity_from_truth);
  EXPECT_FALSE(ParseLoadCommandLine({"--server", "h:1", "--map", "m", "--dataset", "d"}, &help)
                   .initial_velocity_from_truth);
  EXPECT_THROW(ParseLoadCommandLine({"--server", "h:1", "--map", "m", "--dataset", "d",
                                     "--initial-velocity", "wheels"},
                                    &help),
               InvalidArgumentError);
  EXPECT_THROW(ParseLoadCommandLine(
                   {"--server", "h:1", "--map", "m", "--dataset", "d", "--stagger", "20"}, &help),
               InvalidArgumentError);
  EXPECT_THROW(ParseLoadCommandLine(
                   {"--server", "h:1", "--map", "m", "--dataset", "d", "--stagger", "4:0"}, &help),
               InvalidArgumentError);
  EXPECT_THROW(ParseLoadCommandLine({"--server", "h:1", "--map", "m", "--dataset", "d",
                                     "--cancel-fraction", "0.7", "--bad-fraction", "0.5"},
                                    &help),
               InvalidArgumentError);
  EXPECT_THROW(ParseLoadCommandLine({"--sessions", "2"}, &help), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::load
