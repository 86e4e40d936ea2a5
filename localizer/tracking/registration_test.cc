#include "localizer/tracking/registration.h"

#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>

#include "core/common/error.h"

#include "localizer/tracking/potential_field.h"
#include "localizer/tracking/testing/synthetic_scene.h"

namespace evloc::tracking {
namespace {

// A smooth field sampled on a grid, wrapped as a DenseField.
DenseField SmoothDenseField(int width, int height) {
  cv::Mat values(height, width, CV_32FC1);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      values.at<float>(y, x) =
          static_cast<float>(0.5 + 0.3 * std::sin(x / 7.0) * std::cos(y / 5.0));
    }
  }
  return DenseField(values);
}

// The field of projected map points: truncated distance to their rounded pixels, smoothed.
DenseField ProjectedEdgeField(const Map& map, const PinholeIntrinsics& intrinsics, int width,
                              int height, const Rigid3d& cam_from_world) {
  cv::Mat edges = cv::Mat::zeros(height, width, CV_8UC1);
  for (const Eigen::Vector3f& position : map.positions) {
    Eigen::Vector2d pixel;
    if (!intrinsics.Project(cam_from_world * position.cast<double>(), &pixel)) continue;
    const int x = static_cast<int>(std::lround(pixel.x()));
    const int y = static_cast<int>(std::lround(pixel.y()));
    if (x >= 0 && y >= 0 && x < width && y < height) edges.at<uint8_t>(y, x) = 255;
  }
  return DenseField(TruncatedDistanceField(edges, 10.0, false));
}

TEST(Registration, AnalyticJacobianMatchesNumericalDifferences) {
  DenseField field = SmoothDenseField(320, 240);
  const PinholeIntrinsics intrinsics{250.0, 260.0, 160.3, 119.7};
  const Rigid3d cam_from_world(ExpSO3(Eigen::Vector3d(0.1, -0.2, 0.05)),
                               Eigen::Vector3d(0.1, -0.05, 0.3));
  std::mt19937 random(7);
  std::uniform_real_distribution<double> lateral(-0.6, 0.6);
  std::uniform_real_distribution<double> depth(1.0, 4.0);
  int checked = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d position(lateral(random), lateral(random), depth(random));
    // Skip points within 1e-3 px of a cell boundary, where the bilinear derivative jumps.
    Eigen::Vector2d pixel;
    ASSERT_TRUE(intrinsics.Project(cam_from_world * position, &pixel));
    const Eigen::Vector2d fraction = pixel - pixel.array().floor().matrix();
    if (fraction.minCoeff() < 1e-3 || fraction.maxCoeff() > 1 - 1e-3) continue;
    double residual;
    RowVector6d analytic;
    if (!EvaluatePointResidual(field, intrinsics, cam_from_world, position, 2.0, &residual,
                               &analytic)) {
      continue;
    }
    RowVector6d numeric;
    const double step = 1e-6;
    for (int k = 0; k < 6; ++k) {
      Vector6d delta = Vector6d::Zero();
      delta(k) = step;
      double plus, minus;
      ASSERT_TRUE(EvaluatePointResidual(field, intrinsics, ExpSE3(delta) * cam_from_world, position,
                                        2.0, &plus, nullptr));
      ASSERT_TRUE(EvaluatePointResidual(field, intrinsics, ExpSE3(-delta) * cam_from_world,
                                        position, 2.0, &minus, nullptr));
      numeric(k) = (plus - minus) / (2 * step);
    }
    EXPECT_LT((analytic - numeric).norm(), 1e-5 * std::max(1.0, numeric.norm()))
        << "analytic " << analytic << "\nnumeric  " << numeric;
    ++checked;
  }
  EXPECT_GT(checked, 100);
}

TEST(Registration, ProjectionJacobianMatchesNumericalDifferences) {
  const PinholeIntrinsics intrinsics{250.0, 260.0, 160.3, 119.7};
  const Eigen::Vector3d point(0.3, -0.2, 1.7);
  Eigen::Vector2d pixel;
  Eigen::Matrix<double, 2, 3> analytic;
  ASSERT_TRUE(intrinsics.Project(point, &pixel, &analytic));
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d offset = Eigen::Vector3d::Zero();
    offset(k) = 1e-6;
    Eigen::Vector2d plus, minus;
    ASSERT_TRUE(intrinsics.Project(point + offset, &plus));
    ASSERT_TRUE(intrinsics.Project(point - offset, &minus));
    EXPECT_LT((analytic.col(k) - (plus - minus) / 2e-6).norm(), 1e-4);
  }
}

TEST(Registration, RobustWeightsAndCosts) {
  EXPECT_DOUBLE_EQ(RobustWeight(RobustLoss::kHuber, 0.2, 0.1), 1.0);
  EXPECT_DOUBLE_EQ(RobustWeight(RobustLoss::kHuber, 0.2, 0.8), 0.25);
  EXPECT_DOUBLE_EQ(RobustWeight(RobustLoss::kCauchy, 0.2, 0.2), 0.5);
  // The Huber cost is continuous at the threshold and the weight is rho'(r) / r.
  EXPECT_NEAR(RobustCost(RobustLoss::kHuber, 0.2, 0.2 - 1e-12),
              RobustCost(RobustLoss::kHuber, 0.2, 0.2 + 1e-12), 1e-9);
  for (const RobustLoss loss : {RobustLoss::kHuber, RobustLoss::kCauchy}) {
    const double r = 0.5;
    const double derivative =
        (RobustCost(loss, 0.2, r + 1e-7) - RobustCost(loss, 0.2, r - 1e-7)) / 2e-7;
    EXPECT_NEAR(derivative / r, RobustWeight(loss, 0.2, r), 1e-6);
  }
}

class RegistrationConvergence : public ::testing::TestWithParam<RobustLoss> {};

TEST_P(RegistrationConvergence, ConvergesFromTwoCentimetresAndOneDegree) {
  const Camera camera = Camera::Pinhole(320, 240, 260.0, 260.0, 159.5, 119.5);
  const PinholeIntrinsics intrinsics = PinholeIntrinsics::FromCamera(camera);
  const Map map = testing::MakeRectangleMap(testing::DefaultRectangles(), 0.005);
  const Rigid3d true_cam_from_world = testing::SmoothMotion(200'000'000).Inverse();
  DenseField field =
      ProjectedEdgeField(map, intrinsics, camera.width, camera.height, true_cam_from_world);
  std::vector<RegistrationPoint> points;
  for (const Eigen::Vector3f& position : map.positions) {
    points.push_back({position.cast<double>(), &field});
  }
  RegistrationOptions options;
  options.loss = GetParam();
  options.max_iterations = 20;
  // Run to the minimum: the default early stop (min_relative_decrease) is checked below.
  options.min_relative_decrease = 0;
  RegistrationOptions early_stop = options;
  early_stop.min_relative_decrease = RegistrationOptions().min_relative_decrease;
  const double degree = M_PI / 180.0;
  const Vector6d perturbations[] = {
      (Vector6d() << 0.02, 0, 0, 0, 0, 1 * degree).finished(),
      (Vector6d() << 0, -0.02, 0, 1 * degree, 0, 0).finished(),
      (Vector6d() << 0.012, 0.012, -0.01, 0, -1 * degree, 0).finished(),
  };
  for (const Vector6d& perturbation : perturbations) {
    const Rigid3d start = ExpSE3(perturbation) * true_cam_from_world;
    const RegistrationResult result = RegisterPoints(points, intrinsics, start, options);
    // The minimum of this field (edges rounded to pixels) lies ~2 mm from the truth: every start
    // must reach the same minimum as a start at the truth.
    const RegistrationResult from_truth =
        RegisterPoints(points, intrinsics, true_cam_from_world, options);
    EXPECT_TRUE(result.converged);
    EXPECT_LT(result.iterations, 12);
    EXPECT_LT((result.cam_from_world.translation - from_truth.cam_from_world.translation).norm(),
              1e-4);
    EXPECT_NEAR(result.cost, from_truth.cost, 1e-6 * from_truth.cost);
    const Rigid3d error = result.cam_from_world * true_cam_from_world.Inverse();
    // Camera-centre error and orientation error.
    const double centre_error =
        (result.cam_from_world.Inverse().translation - true_cam_from_world.Inverse().translation)
            .norm();
    EXPECT_LT(centre_error, 0.003) << perturbation.transpose();
    EXPECT_LT(LogSO3(error.rotation).norm(), 0.1 * degree) << perturbation.transpose();
    EXPECT_GT(result.points_used, 1000);
    EXPECT_TRUE(result.well_conditioned);
    // The covariance is symmetric positive definite and small for this many points.
    EXPECT_LT((result.covariance - result.covariance.transpose()).norm(), 1e-12);
    EXPECT_GT(Eigen::SelfAdjointEigenSolver<Matrix6d>(result.covariance).eigenvalues().minCoeff(),
              0);
    EXPECT_LT(std::sqrt(result.covariance(0, 0)), 0.01);
    // The default early stop ends within a millimetre and 0.05 degrees of that minimum, in fewer
    // trials.
    const RegistrationResult early = RegisterPoints(points, intrinsics, start, early_stop);
    EXPECT_TRUE(early.converged);
    EXPECT_LE(early.iterations, result.iterations);
    EXPECT_LT((early.cam_from_world.Inverse().translation -
               from_truth.cam_from_world.Inverse().translation)
                  .norm(),
              1e-3)
        << perturbation.transpose();
    EXPECT_LT(AngleBetween(early.cam_from_world.rotation, from_truth.cam_from_world.rotation),
              0.05 * degree);
  }
}

INSTANTIATE_TEST_SUITE_P(Losses, RegistrationConvergence,
                         ::testing::Values(RobustLoss::kHuber, RobustLoss::kCauchy));

// Vertical lines on two planes, 0.2 m apart at z = 2 m and, between them, at z = 4 m (two depths
// tell a sideways translation from a turn), over |y| <= half_height (5 mm steps).
Map VerticalLinesMap(double half_height) {
  Map map;
  for (int line = -3; line <= 3; ++line) {
    for (double y = -half_height; y <= half_height + 1e-9; y += 0.005) {
      map.positions.emplace_back(static_cast<float>(0.2 * line), static_cast<float>(y), 2.0f);
      map.positions.emplace_back(static_cast<float>(0.2 * line + 0.1), static_cast<float>(y), 4.0f);
    }
  }
  return map;
}

// Points on vertical lines registered against a field of longer vertical lines: the points fix
// the pose across the lines and leave it free along them (y).
class RegistrationPrior : public ::testing::Test {
 protected:
  RegistrationPrior()
      : field_(ProjectedEdgeField(VerticalLinesMap(1.5), intrinsics_, 320, 240, Rigid3d())) {
    for (const Eigen::Vector3f& position : VerticalLinesMap(0.3).positions) {
      points_.push_back({position.cast<double>(), &field_});
    }
    options_.max_iterations = 20;
    options_.min_relative_decrease = 0;
  }

  // A prior at `cam_from_world` with standard deviation `sigma_m` in translation and
  // `sigma_rad` in rotation, for residuals that vary by 0.1.
  static PosePrior Prior(const Rigid3d& cam_from_world, double sigma_m, double sigma_rad) {
    PosePrior prior;
    prior.cam_from_world = cam_from_world;
    prior.information.diagonal() << Eigen::Vector3d::Constant(0.01 / (sigma_m * sigma_m)),
        Eigen::Vector3d::Constant(0.01 / (sigma_rad * sigma_rad));
    return prior;
  }

  const PinholeIntrinsics intrinsics_{260.0, 260.0, 159.5, 119.5};
  DenseField field_;
  std::vector<RegistrationPoint> points_;
  RegistrationOptions options_;
};

TEST_F(RegistrationPrior, HoldsWhatThePointsLeaveFreeAndYieldsWhereTheyConstrain) {
  // The camera truly at the origin; the prior 1 cm off along the lines (y) and 1 cm across (x).
  const Rigid3d truth;
  const Rigid3d prior_pose = ExpSE3((Vector6d() << 0.01, 0.01, 0, 0, 0, 0).finished()) * truth;
  const PosePrior prior = Prior(prior_pose, 0.005, 0.01);
  // Both solves start at the truth.
  const RegistrationResult with_prior =
      RegisterPoints(points_, intrinsics_, truth, options_, &prior);
  const RegistrationResult without = RegisterPoints(points_, intrinsics_, truth, options_);
  // Along the lines the points say nothing: the prior moves y to its own; without it y stays.
  EXPECT_NEAR(with_prior.cam_from_world.translation.y(), 0.01, 1e-4);
  EXPECT_NEAR(without.cam_from_world.translation.y(), 0.0, 1e-4);
  // Across the lines hundreds of points outweigh a 5 mm prior: back within 2 mm of the truth.
  EXPECT_LT(std::abs(with_prior.cam_from_world.translation.x()), 0.002);
  EXPECT_LT(std::abs(without.cam_from_world.translation.x()), 0.002);
  // The points alone do not constrain the pose; the covariance along y is the prior's order.
  EXPECT_FALSE(with_prior.well_conditioned);
  EXPECT_LT(std::sqrt(with_prior.covariance(1, 1)), 0.05);
  EXPECT_GT(with_prior.residual_variance, 0);
}

TEST_F(RegistrationPrior, AWeakPriorChangesLittleAndAStrongOneWins) {
  const Rigid3d truth = ExpSE3((Vector6d() << 0.015, 0, 0.02, 0, 0, 0).finished());
  DenseField field = ProjectedEdgeField(VerticalLinesMap(1.5), intrinsics_, 320, 240, truth);
  for (RegistrationPoint& point : points_) point.field = &field;
  const Rigid3d start;
  const Rigid3d prior_pose = ExpSE3((Vector6d() << 0.02, 0, 0, 0, 0, 0).finished());
  const RegistrationResult without = RegisterPoints(points_, intrinsics_, start, options_);
  ASSERT_LT(std::abs(without.cam_from_world.translation.x() - truth.translation.x()), 0.003);
  const PosePrior weak = Prior(prior_pose, 10.0, 10.0);
  const RegistrationResult weak_result =
      RegisterPoints(points_, intrinsics_, start, options_, &weak);
  EXPECT_LT((weak_result.cam_from_world.translation - without.cam_from_world.translation).norm(),
            2e-4);
  const PosePrior strong = Prior(prior_pose, 1e-5, 1e-5);
  const RegistrationResult strong_result =
      RegisterPoints(points_, intrinsics_, start, options_, &strong);
  EXPECT_LT((strong_result.cam_from_world.translation - prior_pose.translation).norm(), 1e-4);
  // The cost includes the prior's term.
  EXPECT_GT(strong_result.cost, without.cost);
}

TEST_F(RegistrationPrior, NonFiniteInformationIsRejected) {
  PosePrior prior = Prior(Rigid3d(), 0.01, 0.01);
  prior.information(2, 2) = std::numeric_limits<double>::infinity();
  EXPECT_THROW(RegisterPoints(points_, intrinsics_, Rigid3d(), options_, &prior),
               InvalidArgumentError);
}

TEST(Registration, PointsWithoutFieldAreRejected) {
  std::vector<RegistrationPoint> points(1);
  EXPECT_THROW(RegisterPoints(points, PinholeIntrinsics{}, Rigid3d(), RegistrationOptions{}),
               InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::tracking
