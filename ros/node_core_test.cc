// The ROS-free half of the node: the steps it returns for events given message by message are
// evloc-track's (TrackEventStream) on the same events, and its inputs are checked.
#include "ros/node_core.h"

#include <cstdio>
#include <filesystem>
#include <mutex>
#include <string>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/dataset/pose_text.h"
#include "localizer/offline/offline_tracking.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "maps/map.h"
#include "maps/visibility.h"

namespace evloc::ros_node {
namespace {

CameraInfoFields PinholeInfo() {
  CameraInfoFields info;
  info.width = 320;
  info.height = 240;
  info.distortion_model = "plumb_bob";
  info.d = {0, 0, 0, 0, 0};
  info.k = {250, 0, 159.5, 0, 250, 119.5, 0, 0, 1};
  return info;
}

std::string PoseText(const Rigid3d& pose) {
  char text[256];
  std::snprintf(text, sizeof(text), "%.17g %.17g %.17g %.17g %.17g %.17g %.17g",
                pose.translation.x(), pose.translation.y(), pose.translation.z(), pose.rotation.x(),
                pose.rotation.y(), pose.rotation.z(), pose.rotation.w());
  return text;
}

// The events of [begin, end) as the columns of one message.
EventColumns Slice(const EventBuffer& events, size_t begin, size_t end) {
  EventColumns columns;
  for (size_t i = begin; i < end; ++i) {
    columns.t_ns.push_back(events.t_ns[i]);
    columns.x.push_back(events.x[i]);
    columns.y.push_back(events.y[i]);
    columns.polarity.push_back(events.polarity[i]);
  }
  return columns;
}

struct Scene {
  std::filesystem::path map_path;
  Map map;
  EventBuffer events;
};

const Scene& TestScene() {
  static const Scene scene = [] {
    Scene s;
    s.map = tracking::testing::MakeRectangleMap(tracking::testing::DefaultRectangles(), 0.01);
    s.map_path = evloc::testing::MakeTempDir("evloc-ros-node-core") / "map.evmap";
    SaveMap(s.map_path, s.map);
    s.events = tracking::testing::SimulateEdgeEvents(
        s.map, Camera::Pinhole(320, 240, 250, 250, 159.5, 119.5),
        [](int64_t t) { return tracking::testing::SmoothMotion(t); }, 0, 400'000'000);
    return s;
  }();
  return scene;
}

TEST(NodeCore, MessagesGiveEvlocTracksSteps) {
  const Scene& scene = TestScene();
  ASSERT_GT(scene.events.size(), 10000u);
  const int64_t initial_t_ns = 20'000'000;
  NodeCoreOptions options;
  options.map_path = scene.map_path.string();
  options.init_pose = PoseText(tracking::testing::SmoothMotion(initial_t_ns));
  options.init_stamp = "0.020000000";
  options.step_rate_hz = 200;
  NodeCore core(options);
  std::vector<StepOutput> steps;
  ASSERT_TRUE(core.SetCameraInfo(PinholeInfo(), &steps));
  EXPECT_TRUE(steps.empty());
  EXPECT_EQ(core.waiting_for(), "events");
  // Messages of 1 ms of events, as rosbag play publishes a driver's packets.
  size_t begin = 0;
  while (begin < scene.events.size()) {
    size_t end = begin;
    const int64_t message_end = (scene.events.t_ns[begin] / 1'000'000 + 1) * 1'000'000;
    while (end < scene.events.size() && scene.events.t_ns[end] < message_end) ++end;
    for (StepOutput& step : core.AddEventArray(320, 240, Slice(scene.events, begin, end))) {
      steps.push_back(step);
    }
    begin = end;
  }
  EXPECT_EQ(core.waiting_for(), "");

  tracking::OfflineTrackingOptions reference_options;
  reference_options.tracker.step_rate_hz = 200;
  const VisibilityIndex visibility(scene.map);
  BufferEventReader reader(scene.events);
  const auto reference = tracking::TrackEventStream(
      reader, scene.map, &visibility, Camera::Pinhole(320, 240, 250, 250, 159.5, 119.5),
      ParsePoseText("pose", options.init_pose), initial_t_ns, reference_options);
  ASSERT_GE(reference.steps.size(), 70u);
  ASSERT_EQ(steps.size(), reference.steps.size());
  for (size_t i = 0; i < steps.size(); ++i) {
    const tracking::PoseEstimate& expected = reference.steps[i];
    ASSERT_EQ(steps[i].t_ns, expected.t_ns) << i;
    EXPECT_EQ(steps[i].status, tracking::TrackingStatusName(expected.status)) << i;
    EXPECT_EQ(steps[i].pose.position[0], expected.world_from_cam.translation.x()) << i;
    EXPECT_EQ(steps[i].pose.position[2], expected.world_from_cam.translation.z()) << i;
    EXPECT_EQ(steps[i].pose.orientation[3], expected.world_from_cam.rotation.w()) << i;
  }
  EXPECT_EQ(core.counters().events, scene.events.size());
  EXPECT_EQ(core.counters().steps, steps.size());
}

// Streaming to a server from no pose: while the server searches, the node sends at most the
// events per second the server announced (here 0.5 per pixel and second: 38,400 events/s, under
// the scene's rate), and with ~thin_while_searching off every event.
TEST(NodeCore, StreamingWhileTheServerSearchesThinsToTheAnnouncedRate) {
  const Scene& scene = TestScene();
  service::testing::TemporaryFolder folder;
  service::testing::WriteTestMap(folder.path() / "maps", "beside",
                                 service::testing::TestMapWithKeyframesBesideThePath());
  service::LocalizerServerOptions server_options =
      service::testing::TestServerOptions(folder.path() / "maps");
  server_options.searching_events_per_pixel_s = 0.5;
  service::LocalizerServer server(server_options);
  uint64_t thinned[2] = {0, 0};
  for (const bool thin : {false, true}) {
    NodeCoreOptions options;
    options.server = "127.0.0.1:" + std::to_string(server.port());
    options.map_name = "beside";
    options.init_pose = "none";
    options.step_rate_hz = 200;
    options.thin_while_searching = thin;
    std::mutex mutex;
    std::string end_error = "no end";
    {
      NodeCore core(
          options, [](const StepOutput&) {},
          [&](const std::string& error) {
            std::lock_guard<std::mutex> lock(mutex);
            end_error = error;
          });
      std::vector<StepOutput> steps;
      ASSERT_TRUE(core.SetCameraInfo(PinholeInfo(), &steps));
      size_t begin = 0;
      while (begin < scene.events.size()) {
        size_t end = begin;
        const int64_t message_end = (scene.events.t_ns[begin] / 1'000'000 + 1) * 1'000'000;
        while (end < scene.events.size() && scene.events.t_ns[end] < message_end) ++end;
        core.AddEventArray(320, 240, Slice(scene.events, begin, end));
        core.Poll();
        begin = end;
      }
      thinned[thin] = core.counters().thinned_events;
    }  // The destructor ends the session and waits for the server's end.
    std::lock_guard<std::mutex> lock(mutex);
    EXPECT_EQ(end_error, "") << (thin ? "thinning" : "not thinning");
  }
  EXPECT_EQ(thinned[false], 0u);
  EXPECT_GT(thinned[true], 0u);
}

TEST(NodeCore, WaitsForTheCameraAndAPoseHintKeepingRecentEvents) {
  const Scene& scene = TestScene();
  NodeCoreOptions options;
  options.map_path = scene.map_path.string();
  options.buffer_s = 0.05;
  NodeCore core(options);
  EXPECT_EQ(core.waiting_for(), "camera_info");
  // 100 ms of events in 10 ms messages before anything else.
  size_t begin = 0;
  for (int message = 0; message < 10; ++message) {
    size_t end = begin;
    while (end < scene.events.size() && scene.events.t_ns[end] < (message + 1) * 10'000'000) ++end;
    EXPECT_TRUE(core.AddEventArray(320, 240, Slice(scene.events, begin, end)).empty());
    begin = end;
  }
  EXPECT_GT(core.counters().buffer_dropped_events, 0u);
  std::vector<StepOutput> steps;
  ASSERT_TRUE(core.SetCameraInfo(PinholeInfo(), &steps));
  EXPECT_FALSE(core.SetCameraInfo(PinholeInfo(), &steps));
  EXPECT_EQ(core.waiting_for(), "a pose on initialpose");
  const Rigid3d pose = tracking::testing::SmoothMotion(100'000'000);
  PoseFields fields;
  fields.position = {pose.translation.x(), pose.translation.y(), pose.translation.z()};
  fields.orientation = {pose.rotation.x(), pose.rotation.y(), pose.rotation.z(), pose.rotation.w()};
  core.SetPoseHint(fields, 100'000'000, &steps);
  EXPECT_EQ(core.waiting_for(), "");
  size_t end = begin;
  while (end < scene.events.size() && scene.events.t_ns[end] < 200'000'000) ++end;
  for (StepOutput& step : core.AddEventArray(320, 240, Slice(scene.events, begin, end))) {
    steps.push_back(step);
  }
  ASSERT_GE(steps.size(), 25u);
  EXPECT_EQ(steps.back().status, "TRACKING");
  // The covariance of a TRACKING step is a small, symmetric, positive diagonal.
  EXPECT_GT(steps.back().covariance[0], 0);
  EXPECT_LT(steps.back().covariance[0], 1);
  EXPECT_EQ(steps.back().covariance[1], steps.back().covariance[6]);

  fields.orientation = {0, 0, 0, 2};
  EXPECT_THROW(core.SetPoseHint(fields, 0, &steps), InvalidArgumentError);
}

TEST(NodeCore, RejectsMessagesOutOfOrderOrMalformed) {
  const Scene& scene = TestScene();
  NodeCoreOptions options;
  options.map_path = scene.map_path.string();
  options.init_pose = "none";
  NodeCore core(options);
  EventColumns later = Slice(scene.events, 1000, 1010);
  EventColumns earlier = Slice(scene.events, 0, 10);
  EXPECT_TRUE(core.AddEventArray(320, 240, later).empty());
  EXPECT_THROW(core.AddEventArray(320, 240, earlier), InvalidArgumentError);
  EventColumns shuffled = Slice(scene.events, 2000, 2010);
  std::swap(shuffled.t_ns.front(), shuffled.t_ns.back());
  EXPECT_THROW(core.AddEventArray(320, 240, shuffled), InvalidArgumentError);
  EXPECT_THROW(core.AddEventArray(70000, 240, Slice(scene.events, 3000, 3001)),
               InvalidArgumentError);
  EXPECT_EQ(core.counters().rejected_messages, 3u);
  // Mono packets: one event inside 320x240, one outside; a partial word; an unknown encoding.
  const auto word = [](uint64_t dt, uint64_t x, uint64_t y, uint64_t on) {
    return (on << 63) | (y << 48) | (x << 32) | dt;
  };
  std::vector<uint8_t> bytes;
  for (const uint64_t value : {word(7, 10, 20, 1), word(9, 400, 20, 0)}) {
    for (int byte = 0; byte < 8; ++byte) bytes.push_back((value >> (8 * byte)) & 0xff);
  }
  const int64_t stamp = scene.events.t_ns[5000];
  core.AddEventPacket(320, 240, stamp, "mono", false, bytes.data(), bytes.size());
  EXPECT_EQ(core.counters().decoder_dropped_events, 1u);
  EXPECT_THROW(core.AddEventPacket(320, 240, stamp + 100, "mono", false, bytes.data(), 15),
               InvalidArgumentError);
  EXPECT_THROW(core.AddEventPacket(320, 240, stamp + 100, "evt21", false, bytes.data(), 16),
               InvalidArgumentError);
  EXPECT_THROW(core.AddEventPacket(320, 240, stamp + 100, "mono", true, bytes.data(), 16),
               InvalidArgumentError);
  CameraInfoFields bad = PinholeInfo();
  bad.distortion_model = "rational_polynomial";
  bad.d = {0.1, 0, 0, 0, 0, 0, 0, 0};
  std::vector<StepOutput> steps;
  try {
    core.SetCameraInfo(bad, &steps);
    FAIL() << "an unsupported camera model was accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("rational_polynomial"), std::string::npos);
  }
  EXPECT_FALSE(core.has_camera());
  // A camera the tracker's tables would not fit in memory for (found by the fuzzer).
  CameraInfoFields huge = PinholeInfo();
  huge.width = 65535;
  huge.height = 65535;
  EXPECT_THROW(core.SetCameraInfo(huge, &steps), InvalidArgumentError);
  EXPECT_FALSE(core.has_camera());
}

TEST(NodeCore, AJumpForwardRestartsInsteadOfSteppingThroughIt) {
  const Scene& scene = TestScene();
  NodeCoreOptions options;
  options.map_path = scene.map_path.string();
  options.init_pose = PoseText(tracking::testing::SmoothMotion(0));
  options.init_stamp = "0";
  NodeCore core(options);
  std::vector<StepOutput> steps;
  core.SetCameraInfo(PinholeInfo(), &steps);
  size_t end = 0;
  while (scene.events.t_ns[end] < 50'000'000) ++end;
  const size_t first_steps = core.AddEventArray(320, 240, Slice(scene.events, 0, end)).size();
  EXPECT_GE(first_steps, 10u);
  // The same events an hour later: a restart, not a million steps.
  EventColumns later = Slice(scene.events, end, end + 2000);
  for (int64_t& t : later.t_ns) t += int64_t{3600} * 1'000'000'000;
  const auto after = core.AddEventArray(320, 240, later);
  EXPECT_EQ(core.counters().restarts, 1u);
  // Only the steps of the new events' own span (300 Hz), not the hour's million.
  const double span_steps = static_cast<double>(later.t_ns.back() - later.t_ns.front()) * 300e-9;
  EXPECT_LE(static_cast<double>(after.size()), span_steps + 2);
  // A message spanning more than max_gap_s is refused.
  EventColumns long_message = Slice(scene.events, end + 3000, end + 3002);
  long_message.t_ns[0] = later.t_ns.back() + 1;
  long_message.t_ns[1] = long_message.t_ns[0] + 6'000'000'000;
  EXPECT_THROW(core.AddEventArray(320, 240, long_message), InvalidArgumentError);
}

TEST(NodeCore, ParametersAreChecked) {
  const Scene& scene = TestScene();
  NodeCoreOptions options;
  EXPECT_THROW(NodeCore{options}, InvalidArgumentError);
  options.map_path = scene.map_path.string();
  options.init_pose = "1 2 3";
  EXPECT_THROW(NodeCore{options}, InvalidArgumentError);
  options.init_pose = "none";
  options.init_stamp = "12.5s";
  EXPECT_THROW(NodeCore{options}, InvalidArgumentError);
  options.init_stamp = "";
  options.step_rate_hz = -3;
  EXPECT_THROW(NodeCore{options}, InvalidArgumentError);
  options.step_rate_hz = 0;
  options.max_gap_s = 0;
  EXPECT_THROW(NodeCore{options}, InvalidArgumentError);
  options.max_gap_s = 5;
  options.map_path = "/nonexistent/map.evmap";
  EXPECT_THROW(NodeCore{options}, Error);
}

}  // namespace
}  // namespace evloc::ros_node
