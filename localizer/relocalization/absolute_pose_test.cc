#include "localizer/relocalization/absolute_pose.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>

#include "core/common/error.h"
#include "localizer/relocalization/synthetic_scene_test_util.h"

namespace evloc::relocalization {
namespace {

using testing::DistortedCamera;
using testing::MakeScene;
using testing::Scene;

constexpr double kRadiansToDegrees = 180.0 / M_PI;

double TranslationError(const Rigid3d& a, const Rigid3d& b) {
  return (a.translation - b.translation).norm();
}

double RotationErrorDegrees(const Rigid3d& a, const Rigid3d& b) {
  return AngleBetween(a.rotation, b.rotation) * kRadiansToDegrees;
}

class RelocAbsolutePoseOutliers : public ::testing::TestWithParam<double> {};

TEST_P(RelocAbsolutePoseOutliers, RecoversPoseWithinOneCentimetreAndATenthOfADegree) {
  const Camera camera = DistortedCamera();
  const double outlier_fraction = GetParam();
  for (unsigned seed = 1; seed <= 5; ++seed) {
    const Scene scene = MakeScene(camera, 200, 0.5, outlier_fraction, seed);
    const AbsolutePoseResult result =
        EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, AbsolutePoseOptions());
    ASSERT_TRUE(result.success) << "seed " << seed << ": " << result.reason;
    EXPECT_EQ(result.failure, AbsolutePoseFailure::kNone);
    EXPECT_TRUE(result.reason.empty());
    const double translation_error = TranslationError(result.world_from_cam, scene.world_from_cam);
    const double rotation_error = RotationErrorDegrees(result.world_from_cam, scene.world_from_cam);
    EXPECT_LT(translation_error, 0.01) << "seed " << seed;
    EXPECT_LT(rotation_error, 0.1) << "seed " << seed;
    // The inliers are the true inliers: none missed beyond the Gaussian tail of a 3 px gate on
    // 0.5 px noise, and at most a few random pixels that happen to land near their projection.
    int true_inliers = 0, outliers_taken = 0;
    for (const int i : result.inliers) (scene.is_outlier[i] ? outliers_taken : true_inliers)++;
    const int expected_inliers =
        static_cast<int>(std::count(scene.is_outlier.begin(), scene.is_outlier.end(), false));
    EXPECT_EQ(true_inliers, expected_inliers) << "seed " << seed;
    EXPECT_LE(outliers_taken, 2) << "seed " << seed;
    EXPECT_TRUE(std::is_sorted(result.inliers.begin(), result.inliers.end()));
    // 0.5 px per coordinate gives an RMS 2D error of about 0.71 px.
    EXPECT_GT(result.rms_reprojection_error_px, 0.5);
    EXPECT_LT(result.rms_reprojection_error_px, 0.95);
  }
}

INSTANTIATE_TEST_SUITE_P(OutlierFractions, RelocAbsolutePoseOutliers,
                         ::testing::Values(0.0, 0.3, 0.6));

TEST(RelocAbsolutePose, ReportsTooFewInliersWhenEveryCorrespondenceIsAnOutlier) {
  const Camera camera = DistortedCamera();
  for (unsigned seed = 1; seed <= 5; ++seed) {
    const Scene scene = MakeScene(camera, 200, 0.5, 1.0, seed);
    const AbsolutePoseResult result =
        EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, AbsolutePoseOptions());
    EXPECT_FALSE(result.success) << "seed " << seed;
    // Measured: 0-5 chance inliers of the 20 that 10 % of 200 demands.
    EXPECT_EQ(result.failure, AbsolutePoseFailure::kTooFewInliers) << "seed " << seed;
    EXPECT_NE(result.reason.find("inliers of 200 correspondences within 3 px, at least 20"),
              std::string::npos)
        << result.reason;
  }
}

TEST(RelocAbsolutePose, ReportsTooFewCorrespondencesBelowTheMinimum) {
  const Camera camera = DistortedCamera();
  AbsolutePoseOptions options;
  const Scene scene = MakeScene(camera, options.min_inliers - 1, 0.0, 0.0, 7);
  const AbsolutePoseResult result =
      EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, options);
  EXPECT_FALSE(result.success);
  EXPECT_EQ(result.failure, AbsolutePoseFailure::kTooFewCorrespondences);
  EXPECT_NE(result.reason.find("14 usable correspondences"), std::string::npos) << result.reason;

  // Exactly the minimum of perfect correspondences is enough.
  const Scene enough = MakeScene(camera, options.min_inliers, 0.0, 0.0, 7);
  EXPECT_TRUE(EstimateAbsolutePose(camera, enough.pixels, enough.points_in_world, options).success);
}

TEST(RelocAbsolutePose, RejectsCollinearPoints) {
  const Camera camera = DistortedCamera();
  Scene scene = MakeScene(camera, 100, 0.0, 0.0, 3);
  // Move every point onto one line through the scene, and observe it exactly.
  const Eigen::Vector3d start = scene.points_in_world[0];
  const Eigen::Vector3d direction = (scene.points_in_world[1] - start).normalized();
  const Rigid3d cam_from_world = scene.world_from_cam.Inverse();
  for (int i = 0; i < 100; ++i) {
    scene.points_in_world[i] = start + (0.02 * i - 1.0) * direction;
    ASSERT_TRUE(camera.Project(cam_from_world * scene.points_in_world[i], &scene.pixels[i]));
  }
  const AbsolutePoseResult result =
      EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, AbsolutePoseOptions());
  // Every point fits some pose (the RANSAC accepts all of them), but the rotation about the line
  // is free: the covariance is rank-deficient.
  EXPECT_FALSE(result.success);
  EXPECT_EQ(result.failure, AbsolutePoseFailure::kDegenerate) << result.reason;
  EXPECT_FALSE(result.reason.empty());
}

double Median(std::vector<double> values) {
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

TEST(RelocAbsolutePose, RefinementImprovesTheRansacPose) {
  const Camera camera = DistortedCamera();
  std::vector<double> ransac_errors, refined_errors;
  int improved = 0;
  constexpr int kTrials = 20;
  for (unsigned seed = 100; seed < 100 + kTrials; ++seed) {
    const Scene scene = MakeScene(camera, 200, 1.0, 0.3, seed);
    const AbsolutePoseResult result =
        EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, AbsolutePoseOptions());
    ASSERT_TRUE(result.success) << result.reason;
    const double ransac = TranslationError(result.ransac_world_from_cam, scene.world_from_cam);
    const double refined = TranslationError(result.world_from_cam, scene.world_from_cam);
    ransac_errors.push_back(ransac);
    refined_errors.push_back(refined);
    if (refined < ransac) ++improved;
  }
  EXPECT_LT(Median(refined_errors), 0.8 * Median(ransac_errors));
  EXPECT_GE(improved, kTrials * 3 / 4);
}

TEST(RelocAbsolutePose, CovarianceIsSymmetricPositiveDefiniteShrinksAndPredictsTheError) {
  const Camera camera = DistortedCamera();
  double trace_few = 0, trace_many = 0, nees_sum = 0;
  constexpr int kTrials = 30;
  for (unsigned seed = 200; seed < 200 + kTrials; ++seed) {
    for (const int count : {50, 500}) {
      const Scene scene = MakeScene(camera, count, 0.5, 0.0, seed);
      const AbsolutePoseResult result =
          EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, AbsolutePoseOptions());
      ASSERT_TRUE(result.success) << result.reason;
      const Matrix6d& covariance = result.covariance;
      EXPECT_LT((covariance - covariance.transpose()).norm(), 1e-12 * covariance.norm());
      const Eigen::SelfAdjointEigenSolver<Matrix6d> eigen(covariance);
      EXPECT_GT(eigen.eigenvalues().minCoeff(), 0.0);
      (count == 50 ? trace_few : trace_many) += covariance.trace();
      if (count == 500) {
        // The error in the covariance's own coordinates: xi with truth = estimate * ExpSE3(xi).
        const Vector6d xi = LogSE3(result.world_from_cam.Inverse() * scene.world_from_cam);
        nees_sum += xi.dot(covariance.ldlt().solve(xi));
      }
    }
  }
  // Ten times the points: about a tenth of the variance.
  EXPECT_LT(trace_many, 0.2 * trace_few);
  EXPECT_GT(trace_many, 0.05 * trace_few);
  // The normalised estimation error squared averages 6 (six degrees of freedom) when the
  // covariance is right; 30 trials leave a wide margin.
  const double mean_nees = nees_sum / kTrials;
  EXPECT_GT(mean_nees, 3.0);
  EXPECT_LT(mean_nees, 12.0);
}

TEST(RelocAbsolutePose, ResidualJacobianMatchesCentralDifferences) {
  const Camera camera = DistortedCamera();
  const Scene scene = MakeScene(camera, 20, 0.0, 0.0, 11);
  for (int i = 0; i < 20; ++i) {
    Eigen::Vector2d residual;
    Eigen::Matrix<double, 2, 6> analytic;
    ASSERT_TRUE(ReprojectionResidual(camera, scene.world_from_cam, scene.points_in_world[i],
                                     scene.pixels[i], &residual, &analytic));
    EXPECT_LT(residual.norm(), 1e-9);
    constexpr double kStep = 1e-6;
    Eigen::Matrix<double, 2, 6> numeric;
    for (int k = 0; k < 6; ++k) {
      Vector6d step = Vector6d::Zero();
      step(k) = kStep;
      Eigen::Vector2d plus, minus;
      ASSERT_TRUE(ReprojectionResidual(camera, scene.world_from_cam * ExpSE3(step),
                                       scene.points_in_world[i], scene.pixels[i], &plus));
      ASSERT_TRUE(ReprojectionResidual(camera, scene.world_from_cam * ExpSE3(-step),
                                       scene.points_in_world[i], scene.pixels[i], &minus));
      numeric.col(k) = (plus - minus) / (2 * kStep);
    }
    EXPECT_LT((analytic - numeric).norm(), 1e-5 * analytic.norm()) << "point " << i;
  }
}

TEST(RelocAbsolutePose, ReprojectionResidualFailsBehindTheCamera) {
  const Camera camera = DistortedCamera();
  Eigen::Vector2d residual;
  EXPECT_FALSE(ReprojectionResidual(camera, Rigid3d::Identity(), Eigen::Vector3d(0, 0, -1),
                                    Eigen::Vector2d(320, 240), &residual));
}

TEST(RelocAbsolutePose, ThrowsOnProgrammerErrors) {
  const Camera camera = DistortedCamera();
  const Scene scene = MakeScene(camera, 30, 0.0, 0.0, 5);
  std::vector<Eigen::Vector3d> fewer_points = scene.points_in_world;
  fewer_points.pop_back();
  EXPECT_THROW(EstimateAbsolutePose(camera, scene.pixels, fewer_points, AbsolutePoseOptions()),
               InvalidArgumentError);
  AbsolutePoseOptions bad;
  bad.confidence = 1.0;
  EXPECT_THROW(EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, bad),
               InvalidArgumentError);
  bad = AbsolutePoseOptions();
  bad.min_inliers = 3;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
  Camera broken = camera;
  broken.fx = -1;
  EXPECT_THROW(
      EstimateAbsolutePose(broken, scene.pixels, scene.points_in_world, AbsolutePoseOptions()),
      InvalidArgumentError);
}

TEST(RelocAbsolutePose, IsDeterministic) {
  const Camera camera = DistortedCamera();
  const Scene scene = MakeScene(camera, 300, 0.7, 0.5, 21);
  const AbsolutePoseResult a =
      EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, AbsolutePoseOptions());
  const AbsolutePoseResult b =
      EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, AbsolutePoseOptions());
  ASSERT_TRUE(a.success);
  EXPECT_EQ(a.inliers, b.inliers);
  EXPECT_EQ(a.world_from_cam.translation, b.world_from_cam.translation);
  EXPECT_EQ(a.world_from_cam.rotation.coeffs(), b.world_from_cam.rotation.coeffs());
  EXPECT_EQ(a.covariance, b.covariance);
}

}  // namespace
}  // namespace evloc::relocalization
