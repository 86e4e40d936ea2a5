#include "localizer/offline/handover_track.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "core/trajectory/tum_io.h"
#include "localizer/odometry/testing/handover_scene.h"
#include "localizer/offline/track_command.h"

namespace evloc::tracking {
namespace {

namespace fs = std::filesystem;

// evloc-track --handover on the hand-over scene written as a dataset with a depth camera and a
// map of the part seen first: one pose per step, odometry while the map is out of view, back on
// the map at the end; the statistics name each pose's source.
TEST(TrackWithHandover, EvlocTrackHandsOverToOdometryAndBack) {
  const fs::path root = evloc::testing::MakeTempDir("handover_track");
  const fs::path dataset = odometry::testing::WriteHandoverDataset(root);
  std::ostringstream log;
  const TrackCommandOptions options =
      ParseTrackCommandLine({"--map", (root / "map").string(), "--dataset", dataset.string(),
                             "--out", (root / "out.txt").string(), "--stats",
                             (root / "stats.json").string(), "--rate", "200", "--handover"});
  const OfflineTrackingResult result = RunTrackCommand(options, log);
  EXPECT_NE(log.str().find("back to the map (verified)"), std::string::npos) << log.str();
  ASSERT_EQ(result.pose_sources.size(), result.steps.size());
  ASSERT_FALSE(result.steps.empty());
  int away = 0;
  for (size_t i = 0; i < result.steps.size(); ++i) {
    if (i > 0) {
      EXPECT_EQ(result.steps[i].t_ns - result.steps[i - 1].t_ns, 5'000'000) << "a gap";
    }
    const int64_t t = result.steps[i].t_ns;
    if (t >= odometry::testing::kAwayNs && t <= odometry::testing::kReturnNs) {
      EXPECT_EQ(result.pose_sources[i], "odometry") << t;
      ++away;
    }
  }
  EXPECT_GT(away, 90);
  EXPECT_EQ(result.pose_sources.back(), "map");
  // The trajectory file has every pose (odometry included); the last one is on the map.
  const Trajectory written = ReadTumTrajectory(root / "out.txt");
  EXPECT_EQ(written.size(), result.steps.size());
  const TimedPose& last = written.poses().back();
  EXPECT_LT(
      (last.world_from_cam.translation - odometry::testing::HandoverMotion(last.t_ns).translation)
          .norm(),
      0.02);
  const nlohmann::json stats = nlohmann::json::parse(ReadFileToString(root / "stats.json"));
  int odometry_steps = 0;
  for (const auto& step : stats["per_step"]) odometry_steps += step["source"] == "odometry";
  EXPECT_GE(odometry_steps, away);
  fs::remove_all(root);
}

TEST(TrackWithHandover, NeedsDepthAndMapTrackingOfEvents) {
  const fs::path root = evloc::testing::MakeTempDir("handover_track_flags");
  EXPECT_THROW(ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--handover",
                                      "--mode", "frames"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--handover",
                                      "--events-per-step", "1000"}),
               InvalidArgumentError);
  // The hand-over's leave threshold: 0 (the default) is min_map_points, a negative one is refused.
  const TrackCommandOptions leave =
      ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--handover",
                             "--handover-leave-points", "900"});
  EXPECT_EQ(leave.handover_options.leave_map_points, 900);
  EXPECT_EQ(ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--handover"})
                .handover_options.leave_map_points,
            0);
  EXPECT_THROW(ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--handover",
                                      "--handover-leave-points", "-1"}),
               InvalidArgumentError);
  fs::remove_all(root);
}

}  // namespace
}  // namespace evloc::tracking
