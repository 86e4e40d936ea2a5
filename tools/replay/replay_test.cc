#include "tools/replay/replay.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <sstream>
#include <thread>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/dataset/dataset.h"
#include "core/events/evb.h"
#include "core/events/event_reader.h"
#include "core/geo/geo_trajectory.h"
#include "localizer/offline/offline_tracking.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "localizer/wire/twist.h"

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

  // The offline reference: TrackEventStream over the same event file (with the motion prior
  // trusting the velocity to `prior_sigma_mps`, 0: none).
  tracking::OfflineTrackingResult Offline(
      double prior_sigma_mps = 0, const std::optional<Vector6d>& initial_velocity = {}) const {
    const Dataset dataset = ReadDataset(dataset_);
    const auto reader = OpenEventFile(*dataset.events_path);
    tracking::OfflineTrackingOptions options;
    options.tracker.step_rate_hz = 200;
    options.tracker.motion_prior_velocity_sigma_mps = prior_sigma_mps;
    options.initial_velocity = initial_velocity;
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

// The largest distance between the camera centres of two trajectories of the same steps.
double LargestPositionDifference(const Trajectory& a, const Trajectory& b) {
  EXPECT_EQ(a.size(), b.size());
  double largest_m = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) {
    largest_m = std::max(
        largest_m,
        (a.poses()[i].world_from_cam.translation - b.poses()[i].world_from_cam.translation).norm());
  }
  return largest_m;
}

// Bit-identical poses. The server also runs the steps up to the last packet's end_t_ns
// (Tracker::AdvanceTo), after the last event, where offline tracking has no later event to
// trigger them: with 1 ms packets and 200 Hz steps at most one more pose, after the others.
void ExpectSameTrajectory(const Trajectory& served, const Trajectory& offline) {
  ASSERT_GE(served.size(), offline.size());
  ASSERT_LE(served.size(), offline.size() + 1);
  ASSERT_GE(offline.size(), 50u);
  if (served.size() > offline.size()) {
    EXPECT_GT(served.poses().back().t_ns, offline.poses().back().t_ns);
  }
  for (size_t i = 0; i < offline.size(); ++i) {
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

// A session's TrackingOptions.motion_prior_* reach its tracker (the server's default is none):
// the poses are offline tracking's with the same prior, and not those without it.
TEST_F(ReplayTest, ASessionsMotionPriorReachesItsTracker) {
  ReplayOptions options = Options();
  options.motion_prior = std::make_pair(0.05, 0.0);
  std::ostringstream log;
  const ReplayResult result = RunReplay(options, log);
  const Trajectory with_prior = Offline(0.05).trajectory;
  ExpectSameTrajectory(result.trajectory, with_prior);
  const Trajectory without = Offline().trajectory;
  ASSERT_EQ(without.size(), with_prior.size());
  EXPECT_GT(LargestPositionDifference(without, with_prior), 1e-6);
}

// --initial-velocity truth reaches the session's tracker: the poses are offline tracking's
// started with the ground truth's velocity, and not those started at rest.
TEST_F(ReplayTest, TheInitialVelocityReachesTheTracker) {
  ReplayOptions options = Options();
  options.initial_velocity_from_truth = true;
  std::ostringstream log;
  const ReplayResult result = RunReplay(options, log);
  const Trajectory ground_truth = *ReadDataset(dataset_).ground_truth;
  const std::optional<Vector6d> velocity =
      ground_truth.Velocity(ground_truth.start_ns(), wire::kClientVelocityWindowNs);
  ASSERT_TRUE(velocity.has_value());
  const Trajectory moving = Offline(0, velocity).trajectory;
  ExpectSameTrajectory(result.trajectory, moving);
  const Trajectory at_rest = Offline().trajectory;
  ASSERT_EQ(at_rest.size(), moving.size());
  EXPECT_GT(LargestPositionDifference(at_rest, moving), 1e-6);
  options.start_without_pose = true;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
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
  // 5 ms packets: the 64-packet queue then holds 320 ms, so a busy machine that stalls the
  // server for a moment does not overflow it.
  options.packet_us = 5000;
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

// --init-pose none: the session starts without a pose, the server searches the map's keyframes
// (6 cm and 3 degrees off the path) and the replay gets updates without a pose until the first
// TRACKING one; no TRACKING pose is far from the truth.
TEST(ReplayWithoutPose, TheServerFindsTheCameraAndTheReplayReportsWhen) {
  fixture::TemporaryFolder folder;
  fixture::WriteTestMap(folder.path() / "maps", "beside",
                        fixture::TestMapWithKeyframesBesideThePath());
  const std::filesystem::path dataset = fixture::WriteTestDataset(folder.path(), 600'000'000);
  service::LocalizerServer server(fixture::TestServerOptions(folder.path() / "maps"));
  ReplayOptions options;
  options.server = "127.0.0.1:" + std::to_string(server.port());
  options.map_name = "beside";
  options.dataset = dataset;
  options.output = folder.path() / "trajectory.txt";
  options.report = folder.path() / "report.json";
  options.speed = std::nullopt;
  options.step_rate_hz = 200;
  options.start_without_pose = true;
  std::ostringstream log;
  const ReplayResult result = RunReplay(options, log);
  EXPECT_GT(result.searching_updates, 0);
  ASSERT_TRUE(result.first_tracking_s.has_value()) << log.str();
  EXPECT_LT(*result.first_tracking_s, 0.3);
  int tracking = 0;
  for (size_t i = 0; i < result.trajectory.size(); ++i) {
    if (!result.tracking[i]) continue;
    ++tracking;
    const TimedPose& pose = result.trajectory.poses()[i];
    EXPECT_LT(
        (pose.world_from_cam.translation - tracking::testing::SmoothMotion(pose.t_ns).translation)
            .norm(),
        0.05)
        << pose.t_ns;
  }
  EXPECT_GT(tracking, 50);
  EXPECT_NE(log.str().find("first TRACKING pose"), std::string::npos) << log.str();
  const std::string report = ReadFileToString(folder.path() / "report.json");
  EXPECT_NE(report.find("\"first_tracking_s\""), std::string::npos) << report;
}

// While the server searches, the replay sends at most the events per second the server announced
// (SessionStarted.searching_event_rate), and all of them again once a pose is verified.
TEST(ReplayWithoutPose, ThinsItsStreamToTheAnnouncedRateOnlyWhileTheServerSearches) {
  fixture::TemporaryFolder folder;
  fixture::WriteTestMap(folder.path() / "maps", "beside",
                        fixture::TestMapWithKeyframesBesideThePath());
  const std::filesystem::path dataset = fixture::WriteTestDataset(folder.path(), 600'000'000);
  service::LocalizerServerOptions server_options =
      fixture::TestServerOptions(folder.path() / "maps");
  server_options.searching_events_per_pixel_s = 0.5;  // 38,400 events/s: under the stream's 89,000
  service::LocalizerServer server(server_options);
  const auto run = [&](bool thin, const std::string& name) {
    ReplayOptions options;
    options.server = "127.0.0.1:" + std::to_string(server.port());
    options.map_name = "beside";
    options.dataset = dataset;
    options.output = folder.path() / (name + ".txt");
    options.report = folder.path() / (name + ".json");
    options.speed = std::nullopt;
    options.step_rate_hz = 200;
    options.start_without_pose = true;
    options.thin_while_searching = thin;
    std::ostringstream log;
    ReplayResult result = RunReplay(options, log);
    return std::make_pair(result, log.str());
  };
  const auto [whole, whole_log] = run(false, "whole");
  EXPECT_EQ(whole.events_thinned, 0);
  const auto [thinned, thinned_log] = run(true, "thinned");
  EXPECT_GT(thinned.events_thinned, 0) << thinned_log;
  EXPECT_EQ(thinned.events_sent + thinned.events_thinned, whole.events_sent);
  EXPECT_NE(thinned_log.find("events left out while the server searched"), std::string::npos)
      << thinned_log;
  EXPECT_NE(ReadFileToString(folder.path() / "thinned.json").find("\"events_thinned\""),
            std::string::npos);
  // Only the searching part is thinned: once TRACKING, every event goes out (a thinned
  // TRACKING stretch at 0.5 events per pixel and second would leave out most of the stream).
  if (thinned.first_tracking_s) {
    EXPECT_LT(thinned.events_thinned, whole.events_sent * 3 / 4) << thinned_log;
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
  const ReplayCommand command = ParseReplayCommandLine({"--server",
                                                        "127.0.0.1:1",
                                                        "--map",
                                                        "m",
                                                        "--dataset",
                                                        "d",
                                                        "--out",
                                                        "o.txt",
                                                        "--speed",
                                                        "max",
                                                        "--encoding",
                                                        "evt3",
                                                        "--packet-us",
                                                        "500",
                                                        "--token",
                                                        "T",
                                                        "--rate",
                                                        "250",
                                                        "--motion-prior",
                                                        "2,5",
                                                        "--init-pose",
                                                        "1 2 3 0 0 0 1",
                                                        "--max-lead-ms",
                                                        "20",
                                                        "--duration",
                                                        "2",
                                                        "--reconnect",
                                                        "5",
                                                        "--reconnect-backoff-ms",
                                                        "50",
                                                        "--reconnect-backoff-max-ms",
                                                        "400",
                                                        "--reconnect-max-s",
                                                        "30",
                                                        "--reconnect-stable-s",
                                                        "5",
                                                        "--reconnect-seed",
                                                        "42",
                                                        "--resume-prime-ms",
                                                        "80",
                                                        "--lb",
                                                        "round_robin",
                                                        "--report",
                                                        "r.json"});
  EXPECT_FALSE(command.help);
  EXPECT_FALSE(command.health_check);
  const ReplayOptions& options = command.options;
  EXPECT_FALSE(options.speed.has_value());
  EXPECT_EQ(options.encoding, WireEncoding::kEvt3);
  EXPECT_EQ(options.packet_us, 500);
  EXPECT_EQ(options.token, "T");
  EXPECT_EQ(options.step_rate_hz, 250);
  ASSERT_TRUE(options.motion_prior.has_value());
  EXPECT_EQ(options.motion_prior->first, 2);
  EXPECT_EQ(options.motion_prior->second, 5);
  EXPECT_EQ(options.initial_world_from_cam->translation.z(), 3);
  EXPECT_EQ(options.max_lead_ms, 20);
  EXPECT_EQ(options.duration_s, 2);
  EXPECT_EQ(options.reconnect, 5);
  EXPECT_EQ(options.reconnect_backoff_ms, 50);
  EXPECT_EQ(options.reconnect_backoff_max_ms, 400);
  EXPECT_EQ(options.reconnect_max_s, 30);
  EXPECT_EQ(options.reconnect_stable_s, 5);
  EXPECT_EQ(options.reconnect_seed, 42u);
  EXPECT_EQ(options.resume_prime_ms, 80);
  EXPECT_EQ(options.lb_policy, "round_robin");
  EXPECT_EQ(options.report, std::filesystem::path("r.json"));
  EXPECT_THROW(ParseReplayCommandLine({"--server", "x"}), InvalidArgumentError);
  const std::vector<std::string> required = {"--server",  "x", "--map", "m",
                                             "--dataset", "d", "--out", "o"};
  std::vector<std::string> no_pose = required;
  no_pose.insert(no_pose.end(), {"--init-pose", "none"});
  EXPECT_TRUE(ParseReplayCommandLine(no_pose).options.start_without_pose);
  EXPECT_FALSE(ParseReplayCommandLine(required).options.start_without_pose);
  EXPECT_TRUE(ParseReplayCommandLine(required).options.thin_while_searching);
  std::vector<std::string> whole = required;
  whole.insert(whole.end(), {"--thin-while-searching", "off"});
  EXPECT_FALSE(ParseReplayCommandLine(whole).options.thin_while_searching);
  std::vector<std::string> moving = required;
  moving.insert(moving.end(), {"--initial-velocity", "truth"});
  EXPECT_TRUE(ParseReplayCommandLine(moving).options.initial_velocity_from_truth);
  EXPECT_FALSE(ParseReplayCommandLine(required).options.initial_velocity_from_truth);
  moving.back() = "fast";
  EXPECT_THROW(ParseReplayCommandLine(moving), InvalidArgumentError);
  no_pose.insert(no_pose.end(), {"--init-pose", "0 0 0 0 0 0 1"});
  EXPECT_THROW(ParseReplayCommandLine(no_pose), InvalidArgumentError);
  EXPECT_THROW(ParseReplayCommandLine({"--server", "x", "--map", "m", "--dataset", "d", "--out",
                                       "o", "--encoding", "evt2"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseReplayCommandLine({"--server", "x", "--map", "m", "--dataset", "d", "--out",
                                       "o", "--lb", "random"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseReplayCommandLine({"--server", "x", "--map", "m", "--dataset", "d", "--out",
                                       "o", "--reconnect", "-1"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseReplayCommandLine({"--server", "x", "--map", "m", "--dataset", "d", "--out",
                                       "o", "--reconnect-backoff-ms", "500",
                                       "--reconnect-backoff-max-ms", "100"}),
               InvalidArgumentError);

  // A health check needs the server only.
  const ReplayCommand health =
      ParseReplayCommandLine({"--health-check", "--server", "h:1", "--health-timeout", "2",
                              "--health-service", "evloc.api.Localizer"});
  EXPECT_TRUE(health.health_check);
  EXPECT_EQ(health.health_service, "evloc.api.Localizer");
  EXPECT_EQ(health.health_timeout_s, 2);
  EXPECT_THROW(ParseReplayCommandLine({"--health-check"}), InvalidArgumentError);
  EXPECT_THROW(
      ParseReplayCommandLine({"--health-check", "--server", "h:1", "--health-timeout", "0"}),
      InvalidArgumentError);
}

TEST_F(ReplayTest, HealthCheckReportsServingUntilTheServerStops) {
  ReplayOptions options = Options();
  EXPECT_EQ(CheckHealth(options, 5.0), "SERVING");
  // Readiness: the Localizer service admits sessions; a service the server does not know is an
  // error (NOT_FOUND), not a status.
  EXPECT_EQ(CheckHealth(options, 5.0, "evloc.api.Localizer"), "SERVING");
  EXPECT_THROW(CheckHealth(options, 5.0, "no.such.Service"), Error);
  server_->Shutdown();
  EXPECT_THROW(CheckHealth(options, 1.0), Error);
}

// Shuts `server` down (gracefully, as on SIGTERM: running sessions stop within a step and end
// UNAVAILABLE "draining") once it has sent `poses` more poses.
std::thread ShutDownAfterPoses(service::LocalizerServer& server, int64_t poses) {
  const int64_t target = server.counters().poses + poses;
  return std::thread([&server, target] {
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (server.counters().poses < target && std::chrono::steady_clock::now() < give_up) {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    server.Shutdown();
  });
}

TEST_F(ReplayTest, ReconnectsToAnotherServerAndResumesFromTheLastPose) {
  // The reference: the same replay without a failure.
  std::ostringstream reference_log;
  const Trajectory reference = RunReplay(Options(), reference_log).trajectory;

  service::LocalizerServerOptions second_options =
      fixture::TestServerOptions(folder_.path() / "maps");
  second_options.queue_packets = 64;
  service::LocalizerServer second(second_options);
  ReplayOptions options = Options();
  // pick_first over both replicas: the stream starts on the first one and, once it is gone,
  // the channel moves to the second.
  options.server = "ipv4:127.0.0.1:" + std::to_string(server_->port()) +
                   ",127.0.0.1:" + std::to_string(second.port());
  // Slower than real time; the drain stops the first session within a step of the shutdown,
  // which comes after 25 poses: mid-stream, past the first steps.
  options.speed = 0.15;
  options.reconnect = 3;
  options.reconnect_backoff_ms = 20;
  options.report = folder_.path() / "report.json";
  std::thread stopper = ShutDownAfterPoses(*server_, 25);
  std::ostringstream log;
  ReplayResult result;
  try {
    result = RunReplay(options, log);
  } catch (const std::exception& error) {
    stopper.join();  // Not left joinable: the failure is reported, not std::terminate.
    FAIL() << "the replay failed: " << error.what() << "\n" << log.str();
  }
  stopper.join();

  ASSERT_EQ(result.outages.size(), 1u) << log.str();
  const Outage& outage = result.outages[0];
  EXPECT_TRUE(outage.status_code == grpc::StatusCode::CANCELLED ||
              outage.status_code == grpc::StatusCode::UNAVAILABLE)
      << outage.status_code << " " << outage.status_message;
  EXPECT_GE(outage.attempts, 1);
  EXPECT_GT(outage.resume_ms, 0);
  EXPECT_GE(outage.interruption_ms, outage.resume_ms);
  EXPECT_EQ(second.counters().sessions_started, 1);
  EXPECT_GT(second.counters().poses, 10);
  EXPECT_GT(result.packets_resent, 0);
  EXPECT_NE(log.str().find("resumed after"), std::string::npos) << log.str();
  EXPECT_EQ(result.events_sent, Offline().measurements);

  // The trajectory continues across the failure: one pose per step at the same step times as
  // without the failure, identical up to the resume pose. After it the new session starts with
  // fresh time surfaces (primed by the last 100 ms of events) and the velocity of the last poses,
  // so the poses differ slightly: they must stay as close to the ground truth as the
  // uninterrupted ones (this scene's tracking error is 1-16 mm), and within 5 mm of them
  // (2.4 mm measured; resumed at rest 5.5 mm, from a wrong pose, e.g. the initial one, ~7 cm).
  const Trajectory& served = result.trajectory;
  ASSERT_EQ(served.size(), reference.size()) << log.str();
  const Trajectory ground_truth = *ReadDataset(dataset_).ground_truth;
  double worst_m = 0;
  double worst_rad = 0;
  double served_sq = 0;
  double reference_sq = 0;
  size_t resume_index = served.size();
  for (size_t i = 0; i < served.size(); ++i) {
    const TimedPose& a = served.poses()[i];
    const TimedPose& b = reference.poses()[i];
    ASSERT_EQ(a.t_ns, b.t_ns) << "pose " << i;
    if (a.t_ns == outage.resume_t_ns) resume_index = i;
    if (a.t_ns <= outage.resume_t_ns) {
      EXPECT_EQ(a.world_from_cam.translation, b.world_from_cam.translation) << "pose " << i;
      continue;
    }
    worst_m =
        std::max(worst_m, (a.world_from_cam.translation - b.world_from_cam.translation).norm());
    worst_rad =
        std::max(worst_rad, a.world_from_cam.rotation.angularDistance(b.world_from_cam.rotation));
    const Rigid3d truth = *ground_truth.Lookup(a.t_ns);
    served_sq += (a.world_from_cam.translation - truth.translation).squaredNorm();
    reference_sq += (b.world_from_cam.translation - truth.translation).squaredNorm();
  }
  ASSERT_GE(resume_index, 9u) << "the resume pose is one the first server sent";
  ASSERT_LT(resume_index + 10, served.size()) << "the failure should come mid-stream";
  const double after = static_cast<double>(served.size() - resume_index - 1);
  const double served_rms_m = std::sqrt(served_sq / after);
  const double reference_rms_m = std::sqrt(reference_sq / after);
  EXPECT_LT(worst_m, 0.005) << "worst translation difference to the uninterrupted poses, m";
  EXPECT_LT(worst_rad, 0.25 * M_PI / 180) << "worst rotation difference, rad";
  EXPECT_LT(served_rms_m, 1.5 * reference_rms_m + 0.001)
      << "translation RMS error after the resume, m (uninterrupted: " << reference_rms_m << ")";
  const std::string report = ReadFileToString(folder_.path() / "report.json");
  EXPECT_NE(report.find("\"interruption_ms\""), std::string::npos) << report;
  std::cout << "resumed after " << outage.resume_ms << " ms at pose " << resume_index << " of "
            << served.size() << "; after it: RMS error " << served_rms_m * 1e3
            << " mm (uninterrupted " << reference_rms_m * 1e3 << " mm), worst difference "
            << worst_m * 1e3 << " mm, " << worst_rad * 180 / M_PI << " deg\n";
}

TEST_F(ReplayTest, RetriesAFullServerUntilASessionEnds) {
  service::LocalizerServerOptions full_options =
      fixture::TestServerOptions(folder_.path() / "maps");
  full_options.max_sessions = 1;
  service::LocalizerServer full(full_options);
  // Another client holds the only session for a while.
  auto stub = fixture::ConnectStub(full.port());
  grpc::ClientContext holder_context;
  auto holder = stub->Track(&holder_context);
  api::TrackResponse started;
  ASSERT_TRUE(holder->Write(fixture::TestSessionStart()));
  ASSERT_TRUE(holder->Read(&started));
  ASSERT_TRUE(started.has_started());
  std::thread release([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    holder->WritesDone();
    api::TrackResponse response;
    while (holder->Read(&response)) {
    }
    holder->Finish();
  });

  ReplayOptions options = Options();
  options.server = "127.0.0.1:" + std::to_string(full.port());
  options.reconnect = 10;
  options.reconnect_backoff_ms = 50;
  options.duration_s = 0.1;
  std::ostringstream log;
  const ReplayResult result = RunReplay(options, log);
  release.join();
  ASSERT_EQ(result.outages.size(), 1u) << log.str();
  EXPECT_EQ(result.outages[0].status_code, grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_GE(result.outages[0].attempts, 2) << log.str();
  EXPECT_GE(result.trajectory.size(), 15u);
}

TEST_F(ReplayTest, GivesUpAfterTheReconnectAttempts) {
  ReplayOptions options = Options();
  options.reconnect = 2;
  options.reconnect_backoff_ms = 10;
  server_->Shutdown();
  std::ostringstream log;
  try {
    RunReplay(options, log);
    FAIL() << "expected an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("gave up after 2 reconnect attempts"),
              std::string::npos)
        << error.what();
  }
  EXPECT_NE(log.str().find("reconnect 2/2"), std::string::npos) << log.str();
}

TEST_F(ReplayTest, WithoutReconnectAVanishedServerFailsTheReplay) {
  ReplayOptions options = Options();
  server_->Shutdown();
  std::ostringstream log;
  EXPECT_THROW(RunReplay(options, log), Error);
  EXPECT_EQ(log.str().find("reconnect"), std::string::npos) << log.str();
}

}  // namespace
}  // namespace evloc::replay

namespace evloc::replay {
namespace {

// evloc-replay --geo (docs/geo.md): with an anchored map the server's geodetic poses are written
// and equal the offline conversion (the same estimates through the same anchor) byte for byte;
// without an anchor the replay fails with the remedy, after writing its TUM trajectory.
TEST_F(ReplayTest, GeoOutputHasTheOfflineGeodeticPoses) {
  GeoAnchor anchor;
  anchor.origin = {-33.8568, 151.2153, 25.0};
  anchor.enu_from_map =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ())), {10, 5, 0});
  anchor.source = kGeoAnchorSourceSurvey;
  Map anchored = fixture::TestMap();
  anchored.geo_anchor = anchor;
  fixture::WriteTestMap(folder_.path() / "maps", "anchored", anchored);
  ReplayOptions options = Options();
  options.map_name = "anchored";
  options.geo_output = folder_.path() / "geo.txt";
  std::ostringstream log;
  const ReplayResult result = RunReplay(options, log);
  const auto offline = Offline();
  ExpectSameTrajectory(result.trajectory, offline.trajectory);
  const GeoReference reference(anchor);
  std::vector<TimedGeoPose> expected;
  for (const TimedPose& pose : result.trajectory.poses()) {
    expected.push_back({pose.t_ns, reference.PoseFromMap(pose.world_from_cam)});
  }
  EXPECT_EQ(ReadFileToString(*options.geo_output), FormatGeoTrajectory(anchor, expected));

  ReplayOptions plain = Options();
  plain.geo_output = folder_.path() / "plain_geo.txt";
  try {
    RunReplay(plain, log);
    FAIL() << "--geo on a map without an anchor";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("has no geo anchor"), std::string::npos);
  }
  EXPECT_TRUE(std::filesystem::exists(plain.output));
  EXPECT_FALSE(std::filesystem::exists(*plain.geo_output));
}

// --gnss-sigma (a simulated receiver, docs/geo.md): a fix at the start and one per --gnss-period
// of session time, which the server accepts on an anchored map (a wrong fix would end the session
// with INVALID_ARGUMENT or FAILED_PRECONDITION); the poses are those of the run without fixes (a
// fix only narrows searches). A map without an anchor is refused with the remedy.
TEST_F(ReplayTest, GnssSigmaSendsAFixEveryPeriodAndRequiresAnAnchor) {
  GeoAnchor anchor;
  anchor.origin = {47.3769, 8.5417, 408.0};
  Map anchored = fixture::TestMap();
  anchored.geo_anchor = anchor;
  fixture::WriteTestMap(folder_.path() / "maps", "anchored", anchored);
  ReplayOptions options = Options();
  options.map_name = "anchored";
  options.gnss_sigma_m = 3.0;
  options.gnss_period_s = 0.1;
  std::ostringstream log;
  const ReplayResult result = RunReplay(options, log);
  const Dataset dataset = ReadDataset(dataset_);
  const double span_s =
      static_cast<double>(dataset.ground_truth->end_ns() - dataset.ground_truth->start_ns()) * 1e-9;
  EXPECT_GE(result.gnss_fixes_sent, static_cast<int64_t>(span_s / 0.1) - 1) << log.str();
  EXPECT_LE(result.gnss_fixes_sent, static_cast<int64_t>(span_s / 0.1) + 2) << log.str();
  ExpectSameTrajectory(result.trajectory, Offline().trajectory);

  ReplayOptions plain = Options();
  plain.gnss_sigma_m = 3.0;
  try {
    RunReplay(plain, log);
    FAIL() << "--gnss-sigma on a map without an anchor";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("has no geo anchor"), std::string::npos)
        << error.what();
  }
}

}  // namespace
}  // namespace evloc::replay
