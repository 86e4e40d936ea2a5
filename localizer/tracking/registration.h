// 3D-2D registration of map points to a potential field (docs/tracking.md, "Registration"):
// residual r_k = F(pi(W(p_k; theta))), robust loss, forward-compositional Levenberg-Marquardt on
// SE(3) with analytic Jacobians, and the covariance from the Gauss-Newton information matrix.
//
// Increments are left perturbations of cam_from_world in the camera frame:
// cam_from_world <- ExpSE3(delta) * cam_from_world, delta = (v, omega). The equivalent
// perturbation of world_from_cam is on the right: world_from_cam * ExpSE3(-delta), so the
// covariance of delta is also the covariance of xi in world_from_cam * ExpSE3(xi).
#pragma once

#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "localizer/tracking/potential_field.h"
#include "localizer/tracking/tracker_options.h"

namespace evloc::tracking {

using RowVector6d = Eigen::Matrix<double, 1, 6>;

// The intrinsics of the ideal pinhole camera the fields live in.
struct PinholeIntrinsics {
  // Focal length along x, pixels.
  double fx = 1;
  // Focal length along y, pixels.
  double fy = 1;
  // Principal point x, pixels.
  double cx = 0;
  // Principal point y, pixels.
  double cy = 0;

  // The intrinsics of `camera`, ignoring any distortion.
  static PinholeIntrinsics FromCamera(const Camera& camera) {
    return {camera.fx, camera.fy, camera.cx, camera.cy};
  }

  // Projects a point in camera coordinates; false when z <= 0. Optionally the 2x3 Jacobian.
  bool Project(const Eigen::Vector3d& point_in_cam, Eigen::Vector2d* pixel,
               Eigen::Matrix<double, 2, 3>* d_pixel_d_point = nullptr) const {
    const double z = point_in_cam.z();
    if (!(z > Camera::kMinDepth)) return false;
    const double inverse_z = 1.0 / z;
    const double x = point_in_cam.x() * inverse_z;
    const double y = point_in_cam.y() * inverse_z;
    *pixel << fx * x + cx, fy * y + cy;
    if (d_pixel_d_point != nullptr) {
      *d_pixel_d_point << fx * inverse_z, 0, -fx * x * inverse_z, 0, fy * inverse_z,
          -fy * y * inverse_z;
    }
    return true;
  }
};

// The variance reported along directions the points do not constrain (and, by the tracker, for
// every direction of a pose that is no estimate).
inline constexpr double kUnconstrainedVariance = 1e6;

// One point to register: its world position and the field it is registered against.
struct RegistrationPoint {
  // Position in the world, metres.
  Eigen::Vector3d position_world = Eigen::Vector3d::Zero();
  // The field sampled for this point (not owned); points may use different fields.
  PotentialField* field = nullptr;
};

// The residual of one point at `cam_from_world` and, when `jacobian` is not null, its derivative
// with respect to the left increment delta = (v, omega) at zero:
// dr/d delta = grad F(u) * d pi/d p * [I, -Hat(p_cam)]. Returns false when the point is behind
// the camera or its projection is not inside the field shrunk by `margin_px`.
bool EvaluatePointResidual(PotentialField& field, const PinholeIntrinsics& intrinsics,
                           const Rigid3d& cam_from_world, const Eigen::Vector3d& position_world,
                           double margin_px, double* residual, RowVector6d* jacobian);

// Weight w(r) of iteratively reweighted least squares for the robust loss, and the loss rho(r)
// scaled so that rho(r) ~ r^2 / 2 near zero. Inline: the solver calls both for every point.
inline double RobustWeight(RobustLoss loss, double scale, double residual) {
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

// The robust loss value (see RobustWeight).
inline double RobustCost(RobustLoss loss, double scale, double residual) {
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

// The outcome of a registration.
struct RegistrationResult {
  // The estimate.
  Rigid3d cam_from_world;
  // Covariance of the increment (v, omega) at the estimate: sigma^2 * H^-1, with H the robustly
  // weighted Gauss-Newton information matrix and sigma^2 the weighted residual variance.
  Matrix6d covariance = Matrix6d::Identity();
  // The information matrix H at the estimate (unscaled).
  Matrix6d information = Matrix6d::Zero();
  // Robust cost at the estimate (points outside the image count as residual 1).
  double cost = 0;
  // Mean field value over the points used at the estimate.
  double mean_residual = 1;
  // Number of points inside the image at the estimate.
  int points_used = 0;
  // Number of LM trials (linearisations) run.
  int iterations = 0;
  // True when the solve stopped on a small increment, a negligible (predicted) decrease of the
  // cost or an increment that moves the points by a negligible fraction of a pixel, rather than on
  // max_iterations.
  bool converged = false;
  // True when the points' own H had full rank at the estimate (otherwise the covariance is
  // large, 1e6, along what neither the points nor a prior constrain).
  bool well_conditioned = false;
  // The weighted residual variance of the points at the estimate (sigma^2 above; 1 when there are
  // no more points than the pose has parameters).
  double residual_variance = 1;
};

// A Gaussian prior on the pose, e.g. the motion model's prediction: the cost gains
// 0.5 * e^T * information * e with e = LogSE3(cam_from_world * prior.cam_from_world^-1), the left
// increment from the prior to the pose in the camera frame, (v, omega). `information` is in the
// units of the points' cost (half squared field values per squared metre or radian): a prior of
// standard deviation s per axis against points whose residuals vary by sigma has sigma^2 / s^2.
struct PosePrior {
  Rigid3d cam_from_world;
  Matrix6d information = Matrix6d::Zero();
};

// Registers `points` starting from `initial_cam_from_world` with Levenberg-Marquardt, with the
// prior's term in the cost when `prior` is not null (then the covariance is the posterior's:
// sigma^2 (H + prior information)^-1). Throws InvalidArgumentError when a point has no field or
// the prior's information is not finite.
RegistrationResult RegisterPoints(const std::vector<RegistrationPoint>& points,
                                  const PinholeIntrinsics& intrinsics,
                                  const Rigid3d& initial_cam_from_world,
                                  const RegistrationOptions& options,
                                  const PosePrior* prior = nullptr);

}  // namespace evloc::tracking
