#include "mapper/pose_alignment.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>
#include <optional>
#include <random>
#include <string>

#include "core/common/error.h"

namespace evloc::mapper {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;

Sim3d TrueReferenceFromModel() {
  Sim3d transform;
  transform.scale = 0.37;
  transform.rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.8, Eigen::Vector3d(1, -2, 0.5).normalized()));
  transform.translation = Eigen::Vector3d(1.0, -0.5, 2.0);
  return transform;
}

// A short, nearly straight video path in the model frame (0.8 units long, 2 % sideways bend),
// cameras looking sideways with a little jitter.
std::vector<Rigid3d> ShortPath(int count) {
  std::vector<Rigid3d> poses;
  for (int i = 0; i < count; ++i) {
    const double u = static_cast<double>(i) / (count - 1);
    const Eigen::Vector3d centre(0.8 * u, 0.016 * std::sin(std::numbers::pi * u), 0.0);
    const Eigen::Quaterniond rotation(
        Eigen::AngleAxisd(0.1 * u, Eigen::Vector3d::UnitY()) *
        Eigen::AngleAxisd(0.05 * std::cos(7.0 * u), Eigen::Vector3d::UnitX()));
    poses.emplace_back(rotation, centre);
  }
  return poses;
}

double RotationErrorDeg(const Sim3d& estimate, const Sim3d& truth) {
  return AngleBetween(estimate.rotation, truth.rotation) / kDegree;
}

TEST(PoseAlignment, RecoversAnExactSimilarity) {
  const Sim3d truth = TrueReferenceFromModel();
  const std::vector<Rigid3d> model = ShortPath(20);
  std::vector<Rigid3d> reference;
  for (const Rigid3d& pose : model) reference.push_back(truth.TransformPose(pose));
  const PoseAlignment alignment = AlignPoses(model, reference);
  EXPECT_EQ(alignment.num_poses, 20u);
  EXPECT_NEAR(alignment.reference_from_model.scale, truth.scale, 1e-9);
  EXPECT_LT(RotationErrorDeg(alignment.reference_from_model, truth), 1e-6);
  EXPECT_LT((alignment.reference_from_model.translation - truth.translation).norm(), 1e-9);
  EXPECT_LT(alignment.centre_max, 1e-9);
  EXPECT_LT(alignment.rotation_max_deg, 1e-6);
}

// Centre noise of 3 mm on a short, nearly straight path leaves the roll about the path to the
// noise when only centres are aligned; the orientations fix it.
TEST(PoseAlignment, OrientationsFixTheRollOfAShortPath) {
  const Sim3d truth = TrueReferenceFromModel();
  const std::vector<Rigid3d> model = ShortPath(30);
  std::mt19937 random(5);
  std::normal_distribution<double> centre_noise(0.0, 0.003);
  std::normal_distribution<double> angle_noise(0.0, 0.05 * kDegree);
  std::vector<Rigid3d> reference;
  for (const Rigid3d& pose : model) {
    Rigid3d noisy = truth.TransformPose(pose);
    noisy.translation +=
        Eigen::Vector3d(centre_noise(random), centre_noise(random), centre_noise(random));
    noisy.rotation =
        ExpSO3(Eigen::Vector3d(angle_noise(random), angle_noise(random), angle_noise(random))) *
        noisy.rotation;
    reference.push_back(noisy);
  }
  Eigen::Matrix3Xd source(3, model.size());
  Eigen::Matrix3Xd target(3, model.size());
  for (size_t i = 0; i < model.size(); ++i) {
    source.col(static_cast<Eigen::Index>(i)) = model[i].translation;
    target.col(static_cast<Eigen::Index>(i)) = reference[i].translation;
  }
  const double centres_only_error = RotationErrorDeg(AlignUmeyama(source, target, true), truth);
  const PoseAlignment alignment = AlignPoses(model, reference);
  const double error = RotationErrorDeg(alignment.reference_from_model, truth);
  std::cout << "rotation error: centres only " << centres_only_error << " deg, centres and "
            << "orientations " << error << " deg\n";
  EXPECT_GT(centres_only_error, 1.0);
  EXPECT_LT(error, 0.1) << "centres only: " << centres_only_error << " deg";
  EXPECT_NEAR(alignment.reference_from_model.scale, truth.scale, 0.01 * truth.scale);
  EXPECT_LT(alignment.centre_rms, 0.01);
  EXPECT_LT(alignment.rotation_rms_deg, 0.2);
  EXPECT_GT(alignment.orientation_weight, 0.0);
}

// A circle of cameras looking at its middle (radius 1, 40 cameras), the model frame.
std::vector<Rigid3d> Circle(int count) {
  std::vector<Rigid3d> poses;
  for (int i = 0; i < count; ++i) {
    const double angle = 2.0 * std::numbers::pi * i / count;
    const Eigen::Vector3d centre(std::cos(angle), std::sin(angle), 0.1 * std::sin(3.0 * angle));
    // Optical axis (z) towards the middle, x along the path.
    Eigen::Matrix3d rotation;
    rotation.col(2) = -centre.normalized();
    rotation.col(0) = Eigen::Vector3d(-std::sin(angle), std::cos(angle), 0.0);
    rotation.col(1) = rotation.col(2).cross(rotation.col(0));
    poses.emplace_back(Eigen::Quaterniond(rotation).normalized(), centre);
  }
  return poses;
}

// The noise of a correct model (1 % of the path, 0.3 deg) is within the limits; a model folded
// onto itself (the second half of the circle traced back over the first) or with scrambled
// orientations is not, and the message says by how much.
TEST(PoseAlignment, LimitsSeparateNoiseFromAWrongModel) {
  const Sim3d truth = TrueReferenceFromModel();
  const std::vector<Rigid3d> model = Circle(40);
  std::mt19937 random(3);
  std::normal_distribution<double> centre_noise(0.0, 0.01 / std::sqrt(3.0));
  std::normal_distribution<double> angle_noise(0.0, 0.3 * kDegree / std::sqrt(3.0));
  std::vector<Rigid3d> noisy;
  std::vector<Rigid3d> folded;
  std::vector<Rigid3d> turned;
  for (size_t i = 0; i < model.size(); ++i) {
    Rigid3d pose = model[i];
    pose.translation +=
        Eigen::Vector3d(centre_noise(random), centre_noise(random), centre_noise(random));
    pose.rotation =
        ExpSO3(Eigen::Vector3d(angle_noise(random), angle_noise(random), angle_noise(random))) *
        pose.rotation;
    noisy.push_back(truth.TransformPose(pose));
    Rigid3d fold = model[i];
    if (i >= model.size() / 2) fold.translation = model[model.size() - 1 - i].translation;
    folded.push_back(truth.TransformPose(fold));
    Rigid3d turn = model[i];
    turn.rotation =
        ExpSO3(Eigen::Vector3d(0.0, (i % 2 == 0 ? 25.0 : -25.0) * kDegree, 0.0)) * turn.rotation;
    turned.push_back(truth.TransformPose(turn));
  }
  const AlignmentLimits limits;
  const PoseAlignment good = AlignPoses(model, noisy);
  EXPECT_NEAR(good.reference_spread, truth.scale * 1.0025, 0.001);
  EXPECT_LT(good.centre_rms / good.reference_spread, 0.02);
  EXPECT_FALSE(AlignmentLimitViolation(good, limits).has_value());

  const PoseAlignment fold = AlignPoses(model, folded);
  std::cout << "folded model: centres " << fold.centre_rms / fold.reference_spread
            << " of the spread, orientations " << fold.rotation_rms_deg << " deg RMS\n";
  const std::optional<std::string> fold_violation = AlignmentLimitViolation(fold, limits);
  ASSERT_TRUE(fold_violation.has_value());
  EXPECT_NE(fold_violation->find("limit 10 %"), std::string::npos) << *fold_violation;

  const PoseAlignment turn = AlignPoses(model, turned);
  EXPECT_LT(turn.centre_rms / turn.reference_spread, 0.1);
  EXPECT_GT(turn.rotation_rms_deg, 20.0);
  ASSERT_TRUE(AlignmentLimitViolation(turn, limits).has_value());
  // Raised limits accept both.
  AlignmentLimits loose;
  loose.max_centre_rms_fraction = 2.0;
  loose.max_rotation_rms_deg = 90.0;
  EXPECT_FALSE(AlignmentLimitViolation(fold, loose).has_value());
  EXPECT_FALSE(AlignmentLimitViolation(turn, loose).has_value());
  loose.max_rotation_rms_deg = 0.0;
  EXPECT_THROW(loose.Check(), InvalidArgumentError);
}

TEST(PoseAlignment, RejectsBadInput) {
  const std::vector<Rigid3d> model = ShortPath(5);
  EXPECT_THROW(AlignPoses(model, ShortPath(4)), InvalidArgumentError);
  EXPECT_THROW(AlignPoses(ShortPath(2), ShortPath(2)), InvalidArgumentError);
  const std::vector<Rigid3d> still(4, Rigid3d());
  EXPECT_THROW(AlignPoses(still, ShortPath(4)), InvalidArgumentError);
  std::vector<Rigid3d> broken = model;
  broken[1].translation.x() = std::nan("");
  EXPECT_THROW(AlignPoses(broken, model), InvalidArgumentError);
  PoseAlignmentOptions options;
  options.weight_iterations = 0;
  EXPECT_THROW(AlignPoses(model, model, options), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::mapper
