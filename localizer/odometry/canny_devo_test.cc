#include "localizer/odometry/canny_devo.h"

#include <algorithm>
#include <cstdio>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "localizer/odometry/testing/handover_scene.h"

namespace evloc::odometry {
namespace {

using testing::HandoverMotion;

struct SceneRun {
  std::vector<tracking::PoseEstimate> steps;
  std::vector<ReferenceFrameInfo> references;
  // Points in the local map at the end.
  size_t local_map_points = 0;
};

// Canny-DEVO alone (no map) over the hand-over scene: the camera turns 55 degrees to the right,
// stays, and turns back to where it started. Events one 5 ms step at a time, each depth frame
// after the events up to its time; started at the first depth frame after 30 ms at the truth.
SceneRun RunDevoOverTheScene(const CannyDevoOptions& options) {
  CannyDevo devo(testing::HandoverEventCamera(), testing::HandoverDepthCamera(),
                 testing::HandoverEventFromDepth(), options);
  const EventBuffer events = testing::HandoverEvents();
  const std::vector<int64_t> depth_times = testing::HandoverDepthTimes();
  SceneRun run;
  size_t next_event = 0;
  EventBuffer part;
  auto give_events_until = [&](int64_t t_ns) {
    const size_t begin = next_event;
    while (next_event < events.size() && events.t_ns[next_event] <= t_ns) ++next_event;
    part.clear();
    part.Append(events, begin, next_event - begin);
    for (tracking::PoseEstimate& step : devo.AddEvents(part)) run.steps.push_back(step);
  };
  for (const int64_t t_ns : depth_times) {
    give_events_until(t_ns);
    const cv::Mat depth = testing::HandoverDepthFrame(t_ns);
    if (!devo.started()) {
      if (t_ns >= 30'000'000) devo.Start(HandoverMotion(t_ns), t_ns, depth);
      continue;
    }
    for (tracking::PoseEstimate& step : devo.AddDepthFrame(t_ns, depth)) {
      run.steps.push_back(step);
    }
  }
  run.references = devo.reference_frames();
  run.local_map_points = devo.local_map().points().size();
  return run;
}

// The run with the default options (computed once: the scene's events take seconds).
const SceneRun& DefaultRun() {
  static const SceneRun run = RunDevoOverTheScene(CannyDevoOptions());
  return run;
}

// Reference frames taken in [begin_ns, end_ns).
int FramesTakenBetween(const SceneRun& run, int64_t begin_ns, int64_t end_ns) {
  return static_cast<int>(std::count_if(
      run.references.begin(), run.references.end(),
      [&](const ReferenceFrameInfo& info) { return info.t_ns >= begin_ns && info.t_ns < end_ns; }));
}

// The worst position error of the steps in [begin_ns, end_ns], metres.
double WorstErrorBetween(const SceneRun& run, int64_t begin_ns, int64_t end_ns) {
  double worst = 0;
  for (const tracking::PoseEstimate& step : run.steps) {
    if (step.t_ns < begin_ns || step.t_ns > end_ns) continue;
    worst = std::max(
        worst, (step.world_from_cam.translation - HandoverMotion(step.t_ns).translation).norm());
  }
  return worst;
}

TEST(CannyDevo, ACameraThatComesBackRegistersToTheFramesItTookOnTheWayOut) {
  const SceneRun& run = DefaultRun();
  ASSERT_GT(run.steps.size(), 500u);
  const int outward = FramesTakenBetween(run, 0, testing::kReturnNs);
  const int back = FramesTakenBetween(run, testing::kReturnNs, testing::kEndNs);
  const double worst_end_m = WorstErrorBetween(run, testing::kBackNs, testing::kEndNs);
  std::printf("kept frames: %d reference frames out, %d back, worst error at the end %.1f mm\n",
              outward, back, worst_end_m * 1e3);
  // A 55 degree turn at 10 degrees per frame.
  EXPECT_GE(outward, 5);
  // On the way back every pose is within the thresholds of a frame taken on the way out.
  EXPECT_EQ(back, 0);

  // Keeping only as many frames as the local map holds forgets the first ones: the way back
  // needs new frames, each taken at a pose that has drifted.
  CannyDevoOptions forgetful;
  forgetful.max_kept_frames = forgetful.local_map_frames;
  const SceneRun forgetful_run = RunDevoOverTheScene(forgetful);
  const int forgetful_back = FramesTakenBetween(forgetful_run, testing::kReturnNs, testing::kEndNs);
  std::printf("forgetful: %d reference frames back, worst error at the end %.1f mm\n",
              forgetful_back,
              WorstErrorBetween(forgetful_run, testing::kBackNs, testing::kEndNs) * 1e3);
  EXPECT_GE(forgetful_back, 1);
}

TEST(CannyDevo, TheLocalMapIsTheUnionOfTheNearestKeptFrames) {
  CannyDevoOptions single;
  single.local_map_frames = 1;
  single.max_kept_frames = 1;
  const SceneRun one = RunDevoOverTheScene(single);
  ASSERT_GE(one.references.size(), 2u);
  // One frame: the local map is the newest reference frame.
  EXPECT_EQ(one.local_map_points, static_cast<size_t>(one.references.back().points));

  const SceneRun& four = DefaultRun();
  ASSERT_GE(four.references.size(), 4u);
  // Back where it started: the local map holds four of the kept frames, among them the first
  // (taken here), so more points than any one frame and no more than the four largest.
  std::vector<int> sizes;
  for (const ReferenceFrameInfo& info : four.references) sizes.push_back(info.points);
  std::sort(sizes.rbegin(), sizes.rend());
  EXPECT_GT(four.local_map_points, static_cast<size_t>(sizes.front()));
  EXPECT_LE(four.local_map_points, static_cast<size_t>(sizes[0] + sizes[1] + sizes[2] + sizes[3]));
}

TEST(ReferenceMapSource, ReplaceSwapsThePointsAndReserveKeepsThem) {
  ReferenceMapSource source;
  std::vector<Eigen::Vector3f> positions = {Eigen::Vector3f(1, 2, 3), Eigen::Vector3f(4, 5, 6)};
  std::vector<Eigen::Vector3f> gradients = {Eigen::Vector3f::UnitX(), Eigen::Vector3f::UnitY()};
  const uint64_t generation = source.generation();
  source.Replace(&positions, &gradients);
  EXPECT_EQ(source.generation(), generation + 1);
  EXPECT_TRUE(positions.empty()) << "the previous (empty) points come back for reuse";
  ASSERT_EQ(source.points().positions.size(), 2u);
  source.Reserve(1000);
  EXPECT_EQ(source.generation(), generation + 1);
  ASSERT_EQ(source.points().positions.size(), 2u);
  EXPECT_EQ(source.points().positions[1], Eigen::Vector3f(4, 5, 6));
  EXPECT_EQ(source.points().gradients[0], Eigen::Vector3f::UnitX());
  std::vector<Eigen::Vector3f> one_position(1);
  EXPECT_THROW(source.Replace(&one_position, &gradients), InvalidArgumentError);
}

TEST(CannyDevo, RefusesBadKeptFrameOptions) {
  CannyDevoOptions options;
  options.local_map_frames = 0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options.local_map_frames = 4;
  options.max_kept_frames = 3;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options.max_kept_frames = 4;
  EXPECT_NO_THROW(options.Check());
}

}  // namespace
}  // namespace evloc::odometry
