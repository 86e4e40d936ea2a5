// The absolute pose of a calibrated camera from 2D-3D correspondences: observed (distorted)
// pixels are undistorted with evloc's Camera, a P3P RANSAC on normalised coordinates finds the
// consensus, and a Ceres refinement of world_from_cam over the inliers minimises the robustified
// reprojection error through the full camera model, with the covariance of the result
// (docs/relocalization.md). Expected failures are reported in the result, never thrown.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"

namespace evloc::relocalization {

// Options of EstimateAbsolutePose.
struct AbsolutePoseOptions {
  // A correspondence is an inlier when its reprojection error is at most this, pixels.
  double reprojection_threshold_px = 3.0;
  // RANSAC stops when it has found the best model with this probability.
  double confidence = 0.9999;
  // Most RANSAC iterations (minimal samples).
  int max_iterations = 2000;
  // Fewest inliers of an accepted pose; also the fewest correspondences worth trying.
  int min_inliers = 15;
  // Fewest inliers as a fraction of the correspondences for an accepted pose.
  double min_inlier_ratio = 0.1;
  // Refine the RANSAC pose by robust non-linear least squares (Ceres) over the inliers.
  bool refine = true;
  // Scale of the Huber loss on the reprojection error in the refinement, pixels.
  double huber_scale_px = 1.0;
  // Most Levenberg-Marquardt iterations of the refinement.
  int max_refinement_iterations = 30;

  // Throws InvalidArgumentError when a field is outside its domain.
  void Check() const;
};

// Why EstimateAbsolutePose found no pose.
enum class AbsolutePoseFailure {
  // A pose was found.
  kNone,
  // Fewer usable correspondences than min_inliers (or than the 4 of a minimal sample).
  kTooFewCorrespondences,
  // RANSAC's best consensus has fewer inliers than min_inliers or min_inlier_ratio demand.
  kTooFewInliers,
  // The inliers do not determine the pose (RANSAC found no model, or the information matrix of
  // the refined pose is singular).
  kDegenerate,
};

// The outcome of EstimateAbsolutePose.
struct AbsolutePoseResult {
  // True when a verified pose was found; the fields below are meaningful only then, except
  // failure and reason.
  bool success = false;
  // Why no pose was found (kNone on success).
  AbsolutePoseFailure failure = AbsolutePoseFailure::kNone;
  // A sentence saying why no pose was found; empty on success.
  std::string reason;
  // The estimated pose.
  Rigid3d world_from_cam;
  // The RANSAC pose before the refinement (equal to world_from_cam when refine is off).
  Rigid3d ransac_world_from_cam;
  // Covariance of xi in world_from_cam * ExpSE3(xi), xi = (v, omega) in the camera frame:
  // sigma^2 (J^T J)^-1 over the inliers, sigma^2 the residual variance per pixel coordinate.
  Matrix6d covariance = Matrix6d::Identity();
  // Indices (into the input) of the inliers of the final pose, ascending.
  std::vector<int> inliers;
  // Root mean square reprojection error of the inliers, pixels (the norm of the 2D error).
  double rms_reprojection_error_px = 0;
};

// Estimates world_from_cam from pixels observed by `camera` (distorted, evloc's pixel
// convention) and the corresponding points in world coordinates. Deterministic. Throws
// InvalidArgumentError when the vectors differ in length, the camera fails Check(), or the
// options fail Check().
AbsolutePoseResult EstimateAbsolutePose(const Camera& camera,
                                        const std::vector<Eigen::Vector2d>& pixels,
                                        const std::vector<Eigen::Vector3d>& points_in_world,
                                        const AbsolutePoseOptions& options);

// The reprojection residual of one correspondence and its Jacobian with respect to xi in
// world_from_cam * ExpSE3(xi) at xi = 0: projected pixel minus observed pixel. Returns false when
// the point does not project (behind the camera or outside the lens model's valid region).
bool ReprojectionResidual(const Camera& camera, const Rigid3d& world_from_cam,
                          const Eigen::Vector3d& point_in_world, const Eigen::Vector2d& pixel,
                          Eigen::Vector2d* residual,
                          Eigen::Matrix<double, 2, 6>* d_residual_d_xi = nullptr);

}  // namespace evloc::relocalization
