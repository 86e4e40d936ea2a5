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

}  // namespace
}  // namespace evloc::sim
