#include "localizer/tracking/registration.h"

#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "core/common/error.h"

namespace evloc::tracking {
namespace {

// The variance reported along directions the points do not constrain.
constexpr double kUnconstrainedVariance = 1e6;

// Normal equations and cost of all points at one pose.
struct Linearization {
  Matrix6d information = Matrix6d::Zero();
  Vector6d gradient = Vector6d::Zero();
  double cost = 0;
  double weighted_squared_residuals = 0;
  double sum_residuals = 0;
  int points_used = 0;
};

Linearization Linearize(const std::vector<RegistrationPoint>& points,
                        const PinholeIntrinsics& intrinsics, const Rigid3d& cam_from_world,
                        const RegistrationOptions& options) {
  Linearization result;
  // Points outside the image cost as much as a point far from every edge (residual 1), so that
  // costs at different poses compare the same point set.
  const double outside_cost = RobustCost(options.loss, options.robust_scale, 1.0);
  // Accumulate J^T J in the upper triangle only; 21 products per point instead of 36.
  Matrix6d information = Matrix6d::Zero();
  for (const RegistrationPoint& point : points) {
    double residual;
    RowVector6d jacobian;
    if (!EvaluatePointResidual(*point.field, intrinsics, cam_from_world, point.position_world,
                               options.image_margin_px, &residual, &jacobian)) {
      result.cost += outside_cost;
      continue;
    }
    const double weight = RobustWeight(options.loss, options.robust_scale, residual);
    information.selfadjointView<Eigen::Upper>().rankUpdate(jacobian.transpose(), weight);
    result.gradient += (weight * residual) * jacobian.transpose();
    result.cost += RobustCost(options.loss, options.robust_scale, residual);
    result.weighted_squared_residuals += weight * residual * residual;
    result.sum_residuals += residual;
    ++result.points_used;
  }
  result.information = information.selfadjointView<Eigen::Upper>();
  return result;
}

// sigma^2 H^-1, with unconstrained directions given a large variance.
Matrix6d Covariance(const Linearization& linearization, bool* well_conditioned) {
  const int redundancy = linearization.points_used - 6;
  const double variance =
      redundancy > 0 ? linearization.weighted_squared_residuals / redundancy : 1.0;
  const Eigen::SelfAdjointEigenSolver<Matrix6d> solver(linearization.information);
  const Vector6d eigenvalues = solver.eigenvalues();
  const double largest = eigenvalues.cwiseAbs().maxCoeff();
  Vector6d inverse_eigenvalues;
  *well_conditioned = largest > 0;
  for (int i = 0; i < 6; ++i) {
    if (largest > 0 && eigenvalues(i) > 1e-12 * largest) {
      inverse_eigenvalues(i) = variance / eigenvalues(i);
    } else {
      inverse_eigenvalues(i) = kUnconstrainedVariance;
      *well_conditioned = false;
    }
  }
  return solver.eigenvectors() * inverse_eigenvalues.asDiagonal() *
         solver.eigenvectors().transpose();
}

}  // namespace

bool EvaluatePointResidual(PotentialField& field, const PinholeIntrinsics& intrinsics,
                           const Rigid3d& cam_from_world, const Eigen::Vector3d& position_world,
                           double margin_px, double* residual, RowVector6d* jacobian) {
  const Eigen::Vector3d point_in_cam = cam_from_world * position_world;
  Eigen::Vector2d pixel;
  Eigen::Matrix<double, 2, 3> d_pixel_d_point;
  if (!intrinsics.Project(point_in_cam, &pixel, jacobian ? &d_pixel_d_point : nullptr)) {
    return false;
  }
  if (pixel.x() < margin_px || pixel.y() < margin_px || pixel.x() > field.width() - 1 - margin_px ||
      pixel.y() > field.height() - 1 - margin_px) {
    return false;
  }
  Eigen::Vector2d field_gradient;
  if (!field.Sample(pixel.x(), pixel.y(), residual, jacobian ? &field_gradient : nullptr)) {
    return false;
  }
  if (jacobian != nullptr) {
    // d p_cam / d delta for p_cam(delta) = ExpSE3(delta) * p_cam ~ p_cam + v + omega x p_cam.
    const Eigen::RowVector3d d_residual_d_point = field_gradient.transpose() * d_pixel_d_point;
    jacobian->head<3>() = d_residual_d_point;
    jacobian->tail<3>() = d_residual_d_point * (-Hat(point_in_cam));
  }
  return true;
}

double RobustWeight(RobustLoss loss, double scale, double residual) {
  const double magnitude = std::abs(residual);
  switch (loss) {
    case RobustLoss::kHuber:
      return magnitude <= scale ? 1.0 : scale / magnitude;
    case RobustLoss::kCauchy: {
      const double ratio = residual / scale;
      return 1.0 / (1.0 + ratio * ratio);
    }
  }
  return 1.0;
}

double RobustCost(RobustLoss loss, double scale, double residual) {
  const double magnitude = std::abs(residual);
  switch (loss) {
    case RobustLoss::kHuber:
      return magnitude <= scale ? 0.5 * residual * residual : scale * (magnitude - 0.5 * scale);
    case RobustLoss::kCauchy: {
      const double ratio = residual / scale;
      return 0.5 * scale * scale * std::log1p(ratio * ratio);
    }
  }
  return 0.5 * residual * residual;
}

RegistrationResult RegisterPoints(const std::vector<RegistrationPoint>& points,
                                  const PinholeIntrinsics& intrinsics,
                                  const Rigid3d& initial_cam_from_world,
                                  const RegistrationOptions& options) {
  for (const RegistrationPoint& point : points) {
    if (point.field == nullptr) {
      throw InvalidArgumentError("RegisterPoints: every point needs a field.");
    }
  }
  RegistrationResult result;
  result.cam_from_world = initial_cam_from_world;
  Linearization current = Linearize(points, intrinsics, initial_cam_from_world, options);
  double damping = options.initial_damping;
  double growth = 2.0;
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    if (current.points_used < 6) break;
    Matrix6d damped = current.information;
    damped.diagonal() += damping * current.information.diagonal() +
                         Vector6d::Constant(1e-9 * current.information.trace());
    const Vector6d increment = damped.ldlt().solve(-current.gradient);
    if (!increment.allFinite()) break;
    ++result.iterations;
    const Rigid3d candidate = ExpSE3(increment) * result.cam_from_world;
    Linearization trial = Linearize(points, intrinsics, candidate, options);
    const bool small = increment.head<3>().norm() < options.min_increment &&
                       increment.tail<3>().norm() < options.min_increment;
    // Gain ratio: actual over predicted decrease of the (robust) cost (Nielsen's LM update).
    const double predicted_decrease =
        -(increment.dot(current.gradient) + 0.5 * increment.dot(current.information * increment));
    const double gain =
        predicted_decrease > 0 ? (current.cost - trial.cost) / predicted_decrease : -1;
    if (trial.cost < current.cost) {
      result.cam_from_world = candidate;
      current = trial;
      const double factor = 2 * gain - 1;
      damping *= std::max(1.0 / 3.0, 1.0 - factor * factor * factor);
      damping = std::max(damping, 1e-8);
      growth = 2.0;
    } else {
      damping *= growth;
      growth *= 2.0;
    }
    if (small) {
      result.converged = true;
      break;
    }
  }
  result.cost = current.cost;
  result.information = current.information;
  result.points_used = current.points_used;
  result.mean_residual = current.points_used > 0 ? current.sum_residuals / current.points_used : 1;
  result.covariance = Covariance(current, &result.well_conditioned);
  return result;
}

}  // namespace evloc::tracking
