#include "tools/replay/replay.h"

#include <gtest/gtest.h>

#include <sstream>

#include "core/common/error.h"
#include "core/events/evb.h"
#include "core/events/event_reader.h"
#include "localizer/offline/offline_tracking.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "tools/sim/dataset.h"

namespace evloc::replay {
namespace {

namespace fixture = service::testing;

constexpr int64_t kDurationNs = 300'000'000;

class ReplayTest : public ::testing::Test {
 protected:
  void SetUp() override {
    fixture::WriteTestMap(folder_.path() / "maps", fixture::kTestMapName, fixture::TestMap());
    dataset_ = fixture::WriteTestDataset(folder_.path(), kDurationNs);
    service::LocalizerServerOptions options = fixture::TestServerOptions(folder_.path() / "maps");
    options.queue_packets = 64;
    server_ = std::make_unique<service::LocalizerServer>(options);
  }

  ReplayOptions Options() const {
    ReplayOptions options;
    options.server = "127.0.0.1:" + std::to_string(server_->port());
    options.map_name = fixture::kTestMapName;
    options.dataset = dataset_;
    options.output = folder_.path() / "trajectory.txt";
    options.speed = std::nullopt;
    options.step_rate_hz = 200;
    return options;
  }

  // The offline reference: TrackEventStream over the same event file.
  tracking::OfflineTrackingResult Offline() const {
    const sim::Dataset dataset = sim::ReadDataset(dataset_);
    const auto reader = OpenEventFile(*dataset.events_path);
    tracking::OfflineTrackingOptions options;
    options.tracker.step_rate_hz = 200;
    const Map map = fixture::TestMap();
    const VisibilityIndex visibility(map);
    return tracking::TrackEventStream(*reader, map, &visibility, dataset.camera,
                                      dataset.ground_truth->poses().front().world_from_cam,
                                      dataset.ground_truth->start_ns(), options);
  }

  fixture::TemporaryFolder folder_;
  std::filesystem::path dataset_;
  std::unique_ptr<service::LocalizerServer> server_;
};

void ExpectSameTrajectory(const Trajectory& served, const Trajectory& offline) {
  ASSERT_EQ(served.size(), offline.size());
  ASSERT_GE(served.size(), 50u);
  for (size_t i = 0; i < served.size(); ++i) {
    EXPECT_EQ(served.poses()[i].t_ns, offline.poses()[i].t_ns);
    EXPECT_EQ(served.poses()[i].world_from_cam.translation,
              offline.poses()[i].world_from_cam.translation)
        << "pose " << i;
    EXPECT_EQ(served.poses()[i].world_from_cam.rotation.coeffs(),
              offline.poses()[i].world_from_cam.rotation.coeffs());
  }
}

TEST_F(ReplayTest, PackedReplayReproducesOfflineTrackingExactly) {
  std::ostringstream log;
  const ReplayResult result = RunReplay(Options(), log);
  const auto offline = Offline();
  EXPECT_EQ(result.events_sent, offline.measurements);
  EXPECT_EQ(result.lost_poses, 0);
  ExpectSameTrajectory(result.trajectory, offline.trajectory);
  EXPECT_TRUE(std::filesystem::exists(folder_.path() / "trajectory.txt"));
  EXPECT_GT(result.server_latency_p50_us, 0);
  EXPECT_GE(result.client_latency_p99_us, result.client_latency_p50_us);
  EXPECT_NE(log.str().find("poses (0 LOST)"), std::string::npos) << log.str();
}

TEST_F(ReplayTest, Evt3ReplayOfWholeMicrosecondEventsReproducesOfflineTracking) {
  // The synthetic events lie on whole microseconds, so EVT 3.0 carries them exactly.
  ReplayOptions options = Options();
  options.encoding = WireEncoding::kEvt3;
  options.packet_us = 700;
  std::ostringstream log;
  const ReplayResult result = RunReplay(options, log);
  ExpectSameTrajectory(result.trajectory, Offline().trajectory);
}

TEST_F(ReplayTest, RealTimeReplayKeepsPace) {
  ReplayOptions options = Options();
  options.speed = 1.0;
  options.duration_s = 0.1;
  std::ostringstream log;
  const ReplayResult result = RunReplay(options, log);
  // Real-time pacing: the replay cannot finish before 0.1 s of session time has elapsed on the
  // wall clock (the upper bound only catches a stall: the machine may be busy).
  EXPECT_GE(result.wall_s, 0.1);
  EXPECT_LT(result.wall_s, 5.0);
  EXPECT_GE(result.trajectory.size(), 15u);
  EXPECT_GT(result.client_latency_p50_us, 0);
}

TEST_F(ReplayTest, ServerErrorsBecomeClearFailures) {
  ReplayOptions options = Options();
  options.map_name = "atlantis";
  std::ostringstream log;
  try {
    RunReplay(options, log);
    FAIL() << "expected an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("atlantis"), std::string::npos) << error.what();
  }
}

TEST(ReplayTls, ReplaysOverTls) {
  if (std::system("openssl version > /dev/null 2>&1") != 0) {
    GTEST_SKIP() << "the openssl command is not installed: cannot make a test certificate";
  }
  fixture::TemporaryFolder folder;
  const auto cert = folder.path() / "cert.pem";
  const auto key = folder.path() / "key.pem";
  const std::string command =
      "openssl req -x509 -newkey rsa:2048 -nodes -days 1 -subj /CN=localhost -addext "
      "subjectAltName=DNS:localhost -keyout '" +
      key.string() + "' -out '" + cert.string() + "' > /dev/null 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0);
  fixture::WriteTestMap(folder.path() / "maps", fixture::kTestMapName, fixture::TestMap());
  service::LocalizerServerOptions server_options =
      fixture::TestServerOptions(folder.path() / "maps");
  server_options.tls_cert_file = cert;
  server_options.tls_key_file = key;
  service::LocalizerServer server(server_options);

  ReplayOptions options;
  options.server = "127.0.0.1:" + std::to_string(server.port());
  options.map_name = fixture::kTestMapName;
  options.dataset = fixture::WriteTestDataset(folder.path(), kDurationNs);
  options.output = folder.path() / "trajectory.txt";
  options.speed = std::nullopt;
  options.duration_s = 0.1;
  options.tls_ca_file = cert;
  options.tls_server_name = "localhost";
  std::ostringstream log;
  EXPECT_GE(RunReplay(options, log).trajectory.size(), 25u);

  options.tls_ca_file.reset();
  options.tls_server_name.reset();
  EXPECT_THROW(RunReplay(options, log), Error) << "plaintext to a TLS server";
}

TEST(ReplayCommandLine, FlagsMapToOptions) {
  bool help = false;
  const ReplayOptions options = ParseReplayCommandLine(
      {"--server",    "127.0.0.1:1",   "--map",         "m",   "--dataset",  "d",
       "--out",       "o.txt",         "--speed",       "max", "--encoding", "evt3",
       "--packet-us", "500",           "--token",       "T",   "--rate",     "250",
       "--init-pose", "1 2 3 0 0 0 1", "--max-lead-ms", "20",  "--duration", "2"},
      &help);
  EXPECT_FALSE(help);
  EXPECT_FALSE(options.speed.has_value());
  EXPECT_EQ(options.encoding, WireEncoding::kEvt3);
  EXPECT_EQ(options.packet_us, 500);
  EXPECT_EQ(options.token, "T");
  EXPECT_EQ(options.step_rate_hz, 250);
  EXPECT_EQ(options.initial_world_from_cam->translation.z(), 3);
  EXPECT_EQ(options.max_lead_ms, 20);
  EXPECT_EQ(options.duration_s, 2);
  EXPECT_THROW(ParseReplayCommandLine({"--server", "x"}, &help), InvalidArgumentError);
  EXPECT_THROW(ParseReplayCommandLine({"--server", "x", "--map", "m", "--dataset", "d", "--out",
                                       "o", "--encoding", "evt2"},
                                      &help),
               InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::replay
