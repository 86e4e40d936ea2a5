#include "core/trajectory/trajectory.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc {
namespace {

Rigid3d PoseAboutZ(double angle_rad, const Eigen::Vector3d& translation) {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(angle_rad, Eigen::Vector3d::UnitZ())),
                 translation);
}

TEST(Trajectory, ConstructorRejectsNonIncreasingTimes) {
  EXPECT_THROW(Trajectory({{10, Rigid3d()}, {10, Rigid3d()}}), InvalidArgumentError);
  EXPECT_THROW(Trajectory({{10, Rigid3d()}, {5, Rigid3d()}}), InvalidArgumentError);
  EXPECT_NO_THROW(Trajectory({{10, Rigid3d()}, {11, Rigid3d()}}));
}

TEST(Trajectory, AppendRequiresIncreasingTime) {
  Trajectory trajectory;
  EXPECT_TRUE(trajectory.empty());
  trajectory.Append({100, Rigid3d()});
  EXPECT_THROW(trajectory.Append({100, Rigid3d()}), InvalidArgumentError);
  EXPECT_THROW(trajectory.Append({99, Rigid3d()}), InvalidArgumentError);
  trajectory.Append({200, Rigid3d()});
  EXPECT_EQ(trajectory.size(), 2u);
  EXPECT_EQ(trajectory.start_ns(), 100);
  EXPECT_EQ(trajectory.end_ns(), 200);
  EXPECT_EQ(trajectory.duration_ns(), 100);
}

TEST(Trajectory, RejectsNonFinitePose) {
  Trajectory trajectory;
  Rigid3d pose;
  pose.translation.x() = std::nan("");
  EXPECT_THROW(trajectory.Append({1, pose}), InvalidArgumentError);
}

TEST(Trajectory, StartAndEndOfEmptyThrow) {
  const Trajectory trajectory;
  EXPECT_THROW(trajectory.start_ns(), InvalidArgumentError);
  EXPECT_THROW(trajectory.end_ns(), InvalidArgumentError);
  EXPECT_FALSE(trajectory.Lookup(0).has_value());
}

TEST(Trajectory, LookupReturnsSamplesAtTheirTimesAndNothingOutside) {
  const Rigid3d first = PoseAboutZ(0.1, {1, 2, 3});
  const Rigid3d second = PoseAboutZ(0.5, {2, 2, 3});
  const Trajectory trajectory({{1000, first}, {2000, second}});
  ASSERT_TRUE(trajectory.Lookup(1000).has_value());
  EXPECT_TRUE(trajectory.Lookup(1000)->translation.isApprox(first.translation));
  EXPECT_NEAR(AngleBetween(trajectory.Lookup(1000)->rotation, first.rotation), 0.0, 1e-12);
  ASSERT_TRUE(trajectory.Lookup(2000).has_value());
  EXPECT_NEAR(AngleBetween(trajectory.Lookup(2000)->rotation, second.rotation), 0.0, 1e-12);
  EXPECT_FALSE(trajectory.Lookup(999).has_value());
  EXPECT_FALSE(trajectory.Lookup(2001).has_value());
}

TEST(Trajectory, LookupInterpolatesTranslationLinearlyAndRotationBySlerp) {
  const Trajectory trajectory({{0, PoseAboutZ(0.2, {0, 0, 0})},
                               {1000, PoseAboutZ(0.6, {4, -2, 1})},
                               {3000, PoseAboutZ(0.6, {4, -2, 1})}});
  const std::optional<Rigid3d> midpoint = trajectory.Lookup(500);
  ASSERT_TRUE(midpoint.has_value());
  EXPECT_NEAR((midpoint->translation - Eigen::Vector3d(2, -1, 0.5)).norm(), 0.0, 1e-12);
  // Slerp about a fixed axis: the angle is linear in time.
  EXPECT_NEAR(AngleBetween(midpoint->rotation, PoseAboutZ(0.4, {0, 0, 0}).rotation), 0.0, 1e-12);
  const std::optional<Rigid3d> quarter = trajectory.Lookup(250);
  ASSERT_TRUE(quarter.has_value());
  EXPECT_NEAR((quarter->translation - Eigen::Vector3d(1, -0.5, 0.25)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(AngleBetween(quarter->rotation, PoseAboutZ(0.3, {0, 0, 0}).rotation), 0.0, 1e-12);
  // In the second, constant segment.
  const std::optional<Rigid3d> later = trajectory.Lookup(2345);
  ASSERT_TRUE(later.has_value());
  EXPECT_NEAR((later->translation - Eigen::Vector3d(4, -2, 1)).norm(), 0.0, 1e-12);
}

TEST(Trajectory, LookupTakesTheShorterArcAcrossQuaternionSignFlip) {
  // The same orientations with opposite quaternion signs must interpolate the short way.
  const Eigen::Quaterniond a(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()));
  Eigen::Quaterniond b(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()));
  b.coeffs() = -b.coeffs();
  const Trajectory trajectory(
      {{0, Rigid3d(a, Eigen::Vector3d::Zero())}, {100, Rigid3d(b, Eigen::Vector3d::Zero())}});
  const Eigen::Quaterniond expected(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitX()));
  EXPECT_NEAR(AngleBetween(trajectory.Lookup(50)->rotation, expected), 0.0, 1e-12);
}

TEST(Trajectory, IndexAtOrBefore) {
  const Trajectory trajectory({{10, Rigid3d()}, {20, Rigid3d()}, {30, Rigid3d()}});
  EXPECT_FALSE(trajectory.IndexAtOrBefore(9).has_value());
  EXPECT_EQ(*trajectory.IndexAtOrBefore(10), 0u);
  EXPECT_EQ(*trajectory.IndexAtOrBefore(29), 1u);
  EXPECT_EQ(*trajectory.IndexAtOrBefore(1000), 2u);
}

// A constant body twist sampled every 10 ms: Velocity gives it back over any window inside the
// trajectory (the window after t near the start), and nothing outside it.
TEST(Trajectory, VelocityIsTheBodyTwistOverTheWindow) {
  Vector6d twist;
  twist << 5.0, -0.5, 0.2, 0.1, -0.3, 0.4;  // m/s, rad/s in the camera frame
  const Rigid3d start(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Vector3d(10, -4, 2));
  std::vector<TimedPose> poses;
  for (int i = 0; i <= 100; ++i) {
    poses.push_back({i * 10'000'000LL, start * ExpSE3(twist * (i * 0.01))});
  }
  const Trajectory trajectory(std::move(poses));
  // At samples (0 and 10 ms: the window after t) exactly ...
  for (const int64_t t_ns : {0LL, 10'000'000LL, 500'000'000LL, 1'000'000'000LL}) {
    const std::optional<Vector6d> velocity = trajectory.Velocity(t_ns, 20'000'000);
    ASSERT_TRUE(velocity.has_value()) << t_ns;
    EXPECT_LT((*velocity - twist).norm(), 1e-9) << t_ns;
  }
  // ... and between them up to the interpolation (linear translation, not the screw motion).
  const std::optional<Vector6d> between = trajectory.Velocity(505'000'000, 20'000'000);
  ASSERT_TRUE(between.has_value());
  EXPECT_LT((*between - twist).norm(), 1e-4);
  EXPECT_FALSE(trajectory.Velocity(1'000'000'001LL, 20'000'000).has_value());
  EXPECT_FALSE(trajectory.Velocity(-1, 20'000'000).has_value());
  EXPECT_FALSE(trajectory.Velocity(0, 2'000'000'000LL).has_value());
  EXPECT_FALSE(Trajectory().Velocity(0, 1).has_value());
  EXPECT_THROW(trajectory.Velocity(0, 0), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc
