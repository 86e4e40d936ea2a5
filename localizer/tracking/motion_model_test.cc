#include "localizer/tracking/motion_model.h"

#include <limits>

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::tracking {
namespace {

TEST(ConstantVelocityModel, ExtrapolatesAConstantTwistExactly) {
  Vector6d twist;
  twist << 0.3, -0.1, 0.2, 0.4, -0.2, 0.1;  // per second
  const Rigid3d start(ExpSO3(Eigen::Vector3d(0.2, 0.1, -0.3)), Eigen::Vector3d(1, 2, 3));
  auto pose_at = [&](double t_s) { return start * ExpSE3(twist * t_s); };
  ConstantVelocityModel model;
  model.Reset(pose_at(0.0), 0);
  // Before any update the prediction is the last pose.
  EXPECT_LT((model.Predict(5'000'000).translation - start.translation).norm(), 1e-15);
  model.Update(pose_at(0.01), 10'000'000);
  EXPECT_LT((model.velocity() - twist).norm(), 1e-9);
  const Rigid3d predicted = model.Predict(25'000'000);
  const Rigid3d truth = pose_at(0.025);
  EXPECT_LT((predicted.translation - truth.translation).norm(), 1e-12);
  EXPECT_LT(AngleBetween(predicted.rotation, truth.rotation), 1e-12);
  model.StopMotion();
  EXPECT_LT((model.Predict(25'000'000).translation - pose_at(0.01).translation).norm(), 1e-15);
}

// The noisy motion of the window tests: a constant twist from `start`, poses 3.3 ms apart with
// alternating +-1 mm along x (the worst case for a two-pose difference).
constexpr int64_t kNoisyPeriodNs = 3'333'333;
const Vector6d& NoisyTwist() {
  static const Vector6d twist = (Vector6d() << 0.3, -0.1, 0.2, 0.4, -0.2, 0.1).finished();
  return twist;
}
const Rigid3d& NoisyStart() {
  static const Rigid3d start(ExpSO3(Eigen::Vector3d(0.2, 0.1, -0.3)), Eigen::Vector3d(1, 2, 3));
  return start;
}
Rigid3d NoisyPose(int step) {
  Rigid3d pose =
      NoisyStart() * ExpSE3(NoisyTwist() * (static_cast<double>(step * kNoisyPeriodNs) * 1e-9));
  pose.translation.x() += (step % 2 == 0 ? 1.0 : -1.0) * 1e-3;
  return pose;
}
// The pose of the same twist without noise, 5 ms per step.
Rigid3d ExactPose(int step) { return NoisyStart() * ExpSE3(NoisyTwist() * (step * 0.005)); }
// Error of the translational part of an estimated twist, m/s.
double SpeedError(const Vector6d& velocity) {
  return (velocity.head<3>() - NoisyTwist().head<3>()).norm();
}

// Millimetre noise on poses 3.3 ms apart: the last-two-poses velocity is off by decimetres per
// second, the 20 ms window by a few centimetres per second.
TEST(ConstantVelocityModel, WindowAveragesPoseNoiseOut) {
  const Vector6d& twist = NoisyTwist();
  const Rigid3d& start = NoisyStart();
  const int64_t period_ns = kNoisyPeriodNs;
  ConstantVelocityModel two_poses(0);
  ConstantVelocityModel windowed(20'000'000);
  two_poses.Reset(start, 0);
  windowed.Reset(start, 0);
  EXPECT_EQ(windowed.velocity_span_ns(), 0);
  double worst_two_poses = 0;
  double worst_windowed = 0;
  for (int step = 1; step <= 60; ++step) {
    const int64_t t_ns = step * period_ns;
    const Rigid3d pose = NoisyPose(step);
    two_poses.Update(pose, t_ns);
    windowed.Update(pose, t_ns);
    if (step >= 7) {
      EXPECT_GE(windowed.velocity_span_ns(), 20'000'000);
      EXPECT_LT(windowed.velocity_span_ns(), 20'000'000 + period_ns);
      worst_two_poses = std::max(worst_two_poses, SpeedError(two_poses.velocity()));
      worst_windowed = std::max(worst_windowed, SpeedError(windowed.velocity()));
    }
  }
  EXPECT_GT(worst_two_poses, 0.5);  // 2 mm / 3.3 ms = 0.6 m/s.
  EXPECT_LT(worst_windowed, 0.12);  // 2 mm / 20 ms = 0.1 m/s.
  // A constant twist without noise is still exact over the window.
  windowed.Reset(start, 0);
  for (int step = 1; step <= 10; ++step) windowed.Update(ExactPose(step), step * 5'000'000);
  EXPECT_LT((windowed.velocity() - twist).norm(), 1e-9);
}

// The smooth window keeps the short velocity bit for bit and averages noise out further.
TEST(ConstantVelocityModel, SmoothVelocityUsesTheLongerWindow) {
  const Vector6d& twist = NoisyTwist();
  const Rigid3d& start = NoisyStart();
  const int64_t period_ns = kNoisyPeriodNs;
  ConstantVelocityModel short_only(20'000'000);
  ConstantVelocityModel both(20'000'000, 100'000'000);
  short_only.Reset(start, 0);
  both.Reset(start, 0);
  double worst_short = 0;
  double worst_smooth = 0;
  for (int step = 1; step <= 90; ++step) {
    const int64_t t_ns = step * period_ns;
    const Rigid3d pose = NoisyPose(step);
    short_only.Update(pose, t_ns);
    both.Update(pose, t_ns);
    EXPECT_EQ(both.velocity(), short_only.velocity()) << step;
    EXPECT_EQ(both.velocity_span_ns(), short_only.velocity_span_ns()) << step;
    if (step < 6) {
      EXPECT_EQ(both.smooth_velocity(), both.velocity()) << step;
    }
    if (step >= 31) {
      worst_short = std::max(worst_short, SpeedError(both.velocity()));
      worst_smooth = std::max(worst_smooth, SpeedError(both.smooth_velocity()));
    }
  }
  EXPECT_GT(worst_short, 0.08);    // 2 mm / 20 ms = 0.1 m/s.
  EXPECT_LT(worst_smooth, 0.025);  // 2 mm / 100 ms = 0.02 m/s.
  // Without noise both are exact.
  both.Reset(start, 0);
  for (int step = 1; step <= 40; ++step) both.Update(ExactPose(step), step * 5'000'000);
  EXPECT_LT((both.smooth_velocity() - twist).norm(), 1e-9);
  // PredictSmooth extrapolates along the smooth velocity as Predict does along the short one;
  // with no longer window the two are the same.
  EXPECT_LT((both.PredictSmooth(205'000'000).translation - ExactPose(41).translation).norm(), 1e-9);
  const int64_t next_ns = 91 * period_ns;
  EXPECT_EQ(short_only.PredictSmooth(next_ns).translation, short_only.Predict(next_ns).translation);
  EXPECT_NE(both.PredictSmooth(next_ns).translation, both.Predict(next_ns).translation);
}

// A Reset with a velocity (a resumed session) predicts, and spans both windows, at once; the
// estimates that follow replace the seed: after a smooth window of exact poses of another motion
// both velocities are that motion's.
TEST(ConstantVelocityModel, ResetWithAVelocityMovesOnAtOnceAndForgetsTheSeed) {
  const Vector6d& twist = NoisyTwist();
  ConstantVelocityModel model(20'000'000, 100'000'000);
  model.Reset(ExactPose(0), 0, twist);
  EXPECT_EQ(model.velocity(), twist);
  EXPECT_EQ(model.smooth_velocity(), twist);
  EXPECT_GE(model.velocity_span_ns(), 20'000'000);
  EXPECT_GE(model.smooth_velocity_span_ns(), model.smooth_window_ns());
  const Rigid3d predicted = model.Predict(5'000'000);
  EXPECT_LT((predicted.translation - ExactPose(1).translation).norm(), 1e-12);
  EXPECT_LT(AngleBetween(predicted.rotation, ExactPose(1).rotation), 1e-12);
  // The first update on the same motion keeps the velocity.
  model.Update(ExactPose(1), 5'000'000);
  EXPECT_LT((model.velocity() - twist).norm(), 1e-9);
  EXPECT_LT((model.smooth_velocity() - twist).norm(), 1e-9);

  // Seeded with the wrong velocity (zero) on a moving camera: the seed is gone once the windows
  // hold estimates only.
  model.Reset(ExactPose(0), 0, Vector6d::Zero());
  for (int step = 1; step <= 21; ++step) model.Update(ExactPose(step), step * 5'000'000);
  EXPECT_LT((model.smooth_velocity() - twist).norm(), 1e-9);
  EXPECT_LT((model.velocity() - twist).norm(), 1e-9);

  // Without a smooth window the seed spans 1 ms.
  ConstantVelocityModel two_poses;
  two_poses.Reset(ExactPose(0), 0, twist);
  EXPECT_EQ(two_poses.velocity_span_ns(), 1'000'000);
  EXPECT_EQ(two_poses.velocity(), twist);
  Vector6d bad = twist;
  bad[2] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(two_poses.Reset(ExactPose(0), 0, bad), InvalidArgumentError);
}

TEST(ConstantVelocityModel, RejectsUpdatesThatDoNotMoveForwardInTime) {
  ConstantVelocityModel model;
  EXPECT_THROW(model.Update(Rigid3d(), 10), InvalidArgumentError);
  model.Reset(Rigid3d(), 10);
  EXPECT_THROW(model.Update(Rigid3d(), 10), InvalidArgumentError);
}

// With a decay time the prediction moves by velocity * tau * (1 - exp(-dt / tau)): short steps
// nearly by velocity * dt, long gaps at most by velocity * tau. The smooth prediction (the motion
// prior's centre) and the velocity itself are not damped.
TEST(ConstantVelocityModel, ADecayTimeDampsThePredictionOnly) {
  Vector6d twist;
  twist << 1.0, -0.5, 0.25, 0.0, 0.0, 0.0;  // translation only: the distances are exact.
  ConstantVelocityModel constant(20'000'000, 100'000'000);
  ConstantVelocityModel damped(20'000'000, 100'000'000, 25'000'000);
  const Rigid3d start(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 2, 3));
  constant.Reset(start, 0, twist);
  damped.Reset(start, 0, twist);
  EXPECT_EQ(damped.velocity(), constant.velocity());
  for (const int64_t dt_ns : {3'333'333LL, 25'000'000LL, 1'000'000'000LL}) {
    const double dt = static_cast<double>(dt_ns) * 1e-9;
    const double moved = (damped.Predict(dt_ns).translation - start.translation).norm();
    EXPECT_NEAR(moved, twist.head<3>().norm() * 0.025 * (1 - std::exp(-dt / 0.025)), 1e-12);
    EXPECT_NEAR((constant.Predict(dt_ns).translation - start.translation).norm(),
                twist.head<3>().norm() * dt, 1e-12);
    EXPECT_EQ(damped.PredictSmooth(dt_ns).translation, constant.PredictSmooth(dt_ns).translation);
  }
  // One step at 300 Hz keeps 93.6 % of the constant velocity's motion; a second at most tau's.
  EXPECT_NEAR((damped.Predict(3'333'333).translation - start.translation).norm() /
                  (constant.Predict(3'333'333).translation - start.translation).norm(),
              0.936, 0.001);
  EXPECT_LT((damped.Predict(1'000'000'000).translation - start.translation).norm(),
            twist.head<3>().norm() * 0.025 + 1e-12);
  // No decay time is the constant velocity, bit for bit.
  ConstantVelocityModel zero(20'000'000, 100'000'000, 0);
  zero.Reset(start, 0, twist);
  EXPECT_EQ(zero.Predict(7'000'000).translation, constant.Predict(7'000'000).translation);
}

}  // namespace
}  // namespace evloc::tracking
