#include "tools/sim/motion.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/trajectory/tum_io.h"

namespace evloc::sim {
namespace {

SmoothMotionOptions RoomOptions(MotionProfile profile, uint64_t seed) {
  SmoothMotionOptions options;
  options.profile = profile;
  options.duration_s = 6;
  options.seed = seed;
  options.camera_region =
      Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1.5, 1), Eigen::Vector3d(1, -0.2, 1.8));
  options.viewpoint.look_at = Eigen::Vector3d(0, 1, 1);
  return options;
}

TEST(SmoothMotion, PeakSpeedsMatchThePreset) {
  for (MotionProfile profile : {MotionProfile::kSlow, MotionProfile::kMid, MotionProfile::kFast,
                                MotionProfile::kAggressive}) {
    const SmoothMotion motion(RoomOptions(profile, 3));
    const PeakSpeeds measured = MeasurePeakSpeeds(motion);
    const PeakSpeeds target = PeakSpeedsOf(profile);
    EXPECT_NEAR(measured.linear_m_per_s, target.linear_m_per_s, 0.01 * target.linear_m_per_s)
        << MotionProfileName(profile);
    EXPECT_NEAR(measured.angular_rad_per_s, target.angular_rad_per_s,
                0.01 * target.angular_rad_per_s)
        << MotionProfileName(profile);
  }
}

TEST(SmoothMotion, StaysInsideTheCameraRegionAndLooksTowardsTheTarget) {
  const SmoothMotionOptions options = RoomOptions(MotionProfile::kFast, 5);
  const SmoothMotion motion(options);
  for (int64_t t = 0; t <= motion.duration_ns(); t += 10'000'000) {
    const Rigid3d pose = motion.WorldFromCam(t);
    EXPECT_TRUE(options.camera_region.contains(pose.translation)) << t;
    const Eigen::Vector3d optical_axis = pose.rotation * Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d to_target = (options.viewpoint.look_at - pose.translation).normalized();
    // Yaw 30 + pitch 15 degrees at most, plus the parallax of the position.
    EXPECT_GT(optical_axis.dot(to_target), std::cos(60.0 * M_PI / 180)) << t;
  }
}

TEST(SmoothMotion, SameSeedSameMotionOtherSeedOtherMotion) {
  const SmoothMotion a(RoomOptions(MotionProfile::kMid, 9));
  const SmoothMotion b(RoomOptions(MotionProfile::kMid, 9));
  const SmoothMotion c(RoomOptions(MotionProfile::kMid, 10));
  const Rigid3d pose_a = a.WorldFromCam(1'234'567'890);
  EXPECT_EQ(pose_a.translation, b.WorldFromCam(1'234'567'890).translation);
  EXPECT_GT((pose_a.translation - c.WorldFromCam(1'234'567'890).translation).norm(), 1e-3);
}

TEST(LookAtRotation, OpticalAxisThroughTargetImageDownAlongGravity) {
  const Eigen::Quaterniond rotation =
      LookAtRotation(Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0, 2, 1), Eigen::Vector3d::UnitZ());
  EXPECT_TRUE((rotation * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitY()));
  EXPECT_TRUE((rotation * Eigen::Vector3d::UnitY()).isApprox(-Eigen::Vector3d::UnitZ()));
  EXPECT_TRUE((rotation * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitX()));
  EXPECT_THROW(
      LookAtRotation(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitZ()),
      InvalidArgumentError);
}

TEST(RecordedMotion, ReplaysRelativeMotionAtTheAnchor) {
  EVLOC_REQUIRE_SHARED_DATA(path, "tum-trajectories/fr1_xyz_groundtruth.txt");
  const Trajectory recorded = ReadTumTrajectory(path);
  const Rigid3d anchor(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ())),
                       Eigen::Vector3d(0.2, -0.8, 1.4));
  const RecordedMotion motion(recorded, anchor, std::nullopt);
  EXPECT_EQ(motion.duration_ns(), recorded.duration_ns());
  const Rigid3d start = motion.WorldFromCam(0);
  EXPECT_LT((start.translation - anchor.translation).norm(), 1e-9);
  // Relative motion between any two times is the recorded one.
  const int64_t t1 = 7'000'000'000;
  const int64_t t2 = 12'500'000'000;
  const Rigid3d replayed = motion.WorldFromCam(t1).Inverse() * motion.WorldFromCam(t2);
  const Rigid3d original = recorded.Lookup(recorded.start_ns() + t1)->Inverse() *
                           *recorded.Lookup(recorded.start_ns() + t2);
  EXPECT_LT((replayed.translation - original.translation).norm(), 1e-9);
  EXPECT_LT(AngleBetween(replayed.rotation, original.rotation), 1e-9);
  EXPECT_THROW(RecordedMotion(recorded, anchor, recorded.duration_ns() + 1), InvalidArgumentError);
}

TEST(SampleMotion, SamplesAtTheRateAndEndsAtTheEnd) {
  const SmoothMotion motion(RoomOptions(MotionProfile::kSlow, 1));
  const Trajectory sampled = SampleMotion(motion, 200);
  EXPECT_EQ(sampled.start_ns(), 0);
  EXPECT_EQ(sampled.end_ns(), motion.duration_ns());
  EXPECT_EQ(sampled.size(), 6u * 200 + 1);
  EXPECT_EQ(sampled.poses()[1].t_ns, 5'000'000);
}

TEST(MotionProfile, ParsesNamesAndRejectsOthers) {
  EXPECT_EQ(ParseMotionProfile("aggressive"), MotionProfile::kAggressive);
  EXPECT_THROW(ParseMotionProfile("medium"), InvalidArgumentError);
}

// An L-shaped route: 30 m east, then 30 m north (a sharp corner the heading window smooths).
std::vector<Eigen::Vector2d> LRoute() {
  std::vector<Eigen::Vector2d> route;
  for (int i = 0; i <= 300; ++i) route.emplace_back(0.1 * i, 0);
  for (int i = 1; i <= 300; ++i) route.emplace_back(30, 0.1 * i);
  return route;
}

TEST(PathMotion, MovesAtTheSpeedAlongTheRouteLookingAhead) {
  for (double speed : {5.0, 10.0}) {
    PathMotionOptions options = VehiclePathOptions(LRoute(), speed, 1);
    options.duration_s = 5.0;
    const PathMotion motion(options);
    EXPECT_EQ(motion.duration_ns(), 5'000'000'000);
    EXPECT_NEAR(motion.length_m(), 60.0, 1e-9);
    // On the first straight (t <= 2.5 s at 10 m/s): x = speed * t, y = 0, z = 1.5 m +- 7 mm, the
    // optical axis east and 5 degrees down within the vibrations (0.33 degrees).
    for (double t : {0.0, 0.5, 1.0, 2.0}) {
      const Rigid3d pose = motion.WorldFromCam(static_cast<int64_t>(t * 1e9));
      EXPECT_NEAR(pose.translation.x(), speed * t, 1e-9);
      EXPECT_NEAR(pose.translation.y(), 0.0, 1e-9);
      EXPECT_NEAR(pose.translation.z(), 1.5, 0.0071);
      const Eigen::Vector3d axis = pose.rotation * Eigen::Vector3d::UnitZ();
      EXPECT_NEAR(std::atan2(axis.y(), axis.x()) * 180 / M_PI, 0.0, 0.15) << t;
      EXPECT_NEAR(std::asin(-axis.z()) * 180 / M_PI, 5.0, 0.34) << t;
      // Image rows point down: the camera y axis has a negative world z.
      EXPECT_LT((pose.rotation * Eigen::Vector3d::UnitY()).z(), -0.9);
    }
    const PeakSpeeds peak = MeasurePeakSpeeds(motion);
    EXPECT_NEAR(peak.linear_m_per_s, speed, 0.03 * speed);
  }
  // After the corner the axis points north.
  PathMotionOptions options = VehiclePathOptions(LRoute(), 5, 1);
  const PathMotion motion(options);
  const Rigid3d late = motion.WorldFromCam(motion.duration_ns() - 200'000'000);
  const Eigen::Vector3d axis = late.rotation * Eigen::Vector3d::UnitZ();
  EXPECT_NEAR(std::atan2(axis.y(), axis.x()) * 180 / M_PI, 90.0, 0.2);
}

TEST(PathMotion, PedestrianWalksAtWalkingPaceWithAGaitBob) {
  const PathMotion motion(PedestrianPathOptions(LRoute(), 3));
  EXPECT_NEAR(motion.duration_ns() * 1e-9, 60.0 / 1.4, 1e-6);
  double lowest = 10, highest = 0;
  for (int64_t t = 0; t < 10'000'000'000; t += 10'000'000) {
    const double z = motion.WorldFromCam(t).translation.z();
    lowest = std::min(lowest, z);
    highest = std::max(highest, z);
  }
  EXPECT_NEAR(highest - lowest, 0.05, 0.002);  // a 2.5 cm bob either way
  EXPECT_NEAR((lowest + highest) / 2, 1.4, 0.002);
}

TEST(PathMotion, RejectsBadOptions) {
  PathMotionOptions options = VehiclePathOptions(LRoute(), 5, 1);
  options.duration_s = 13.0;  // 65 m on a 60 m route
  EXPECT_THROW(PathMotion{options}, InvalidArgumentError);
  options.duration_s.reset();
  options.start_m = 61;
  EXPECT_THROW(PathMotion{options}, InvalidArgumentError);
  options.start_m = 0;
  options.speed_m_per_s = 0;
  EXPECT_THROW(PathMotion{options}, InvalidArgumentError);
  options.speed_m_per_s = 5;
  options.route.resize(1);
  EXPECT_THROW(PathMotion{options}, InvalidArgumentError);
  options = VehiclePathOptions(LRoute(), 5, 1);
  options.pitch_vibration.push_back(Vibration{NAN, 1, 0});
  EXPECT_THROW(PathMotion{options}, InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::sim
