#include "localizer/tracking/motion_model.h"

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

TEST(ConstantVelocityModel, RejectsUpdatesThatDoNotMoveForwardInTime) {
  ConstantVelocityModel model;
  EXPECT_THROW(model.Update(Rigid3d(), 10), InvalidArgumentError);
  model.Reset(Rigid3d(), 10);
  EXPECT_THROW(model.Update(Rigid3d(), 10), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::tracking
