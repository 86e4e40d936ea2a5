#include "localizer/relocalization/absolute_pose.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <sstream>
#include <string>

#include <ceres/ceres.h>
#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/common/error.h"

namespace evloc::relocalization {
namespace {

// Smallest RANSAC sample of OpenCV's P3P solvers (three points, and a fourth to choose among
// the up to four solutions).
constexpr int kMinimalSample = 4;

// The 7 parameters of a pose block: translation of world_from_cam, then its quaternion (x, y,
// z, w).
constexpr int kPoseParameters = 7;

Rigid3d PoseFromParameters(const double* parameters) {
  return Rigid3d(Eigen::Quaterniond(parameters[6], parameters[3], parameters[4], parameters[5]),
                 Eigen::Vector3d(parameters[0], parameters[1], parameters[2]));
}

void PoseToParameters(const Rigid3d& pose, double* parameters) {
  parameters[0] = pose.translation.x();
  parameters[1] = pose.translation.y();
  parameters[2] = pose.translation.z();
  parameters[3] = pose.rotation.x();
  parameters[4] = pose.rotation.y();
  parameters[5] = pose.rotation.z();
  parameters[6] = pose.rotation.w();
}

// The pose block's manifold: x [+] xi = x * ExpSE3(xi), the tracker's right perturbation, so
// that Ceres' tangent-space covariance is evloc's pose covariance. The cost function returns
// its Jacobian with respect to xi in the first six columns of the 2 x 7 "ambient" Jacobian (and
// zeros in the seventh); PlusJacobian is the matching [I; 0], so Ceres' product of the two is
// exactly d residual / d xi.
class RightPerturbationManifold : public ceres::Manifold {
 public:
  int AmbientSize() const override { return kPoseParameters; }
  int TangentSize() const override { return 6; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    const Vector6d xi = Eigen::Map<const Vector6d>(delta);
    PoseToParameters(PoseFromParameters(x) * ExpSE3(xi), x_plus_delta);
    return true;
  }
  bool PlusJacobian(const double* /*x*/, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, kPoseParameters, 6, Eigen::RowMajor>> j(jacobian);
    j.setZero();
    j.topRows<6>().setIdentity();
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    Eigen::Map<Vector6d> difference(y_minus_x);
    difference = LogSE3(PoseFromParameters(x).Inverse() * PoseFromParameters(y));
    return true;
  }
  bool MinusJacobian(const double* /*x*/, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 6, kPoseParameters, Eigen::RowMajor>> j(jacobian);
    j.setZero();
    j.leftCols<6>().setIdentity();
    return true;
  }
};

// One reprojection residual (2 pixels) on the pose block, with the analytic Jacobian of
// ReprojectionResidual.
class ReprojectionCost : public ceres::SizedCostFunction<2, kPoseParameters> {
 public:
  ReprojectionCost(const Camera& camera, const Eigen::Vector3d& point_in_world,
                   const Eigen::Vector2d& pixel)
      : camera_(camera), point_in_world_(point_in_world), pixel_(pixel) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    Eigen::Vector2d residual;
    Eigen::Matrix<double, 2, 6> d_residual_d_xi;
    if (!ReprojectionResidual(camera_, PoseFromParameters(parameters[0]), point_in_world_, pixel_,
                              &residual, &d_residual_d_xi)) {
      return false;
    }
    residuals[0] = residual.x();
    residuals[1] = residual.y();
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 2, kPoseParameters, Eigen::RowMajor>> j(jacobians[0]);
      j.leftCols<6>() = d_residual_d_xi;
      j.col(6).setZero();
    }
    return true;
  }

 private:
  const Camera& camera_;
  const Eigen::Vector3d point_in_world_;
  const Eigen::Vector2d pixel_;
};

// A number in the shortest form that reads back the same ("3", "2.5").
std::string FormatNumber(double value) {
  std::ostringstream stream;
  stream << value;
  return stream.str();
}

AbsolutePoseResult Failure(AbsolutePoseFailure failure, std::string reason) {
  AbsolutePoseResult result;
  result.failure = failure;
  result.reason = std::move(reason);
  return result;
}

// The correspondences among `candidates` whose reprojection error at `world_from_cam` is at
// most the threshold, and the sum of their squared errors.
std::vector<int> SelectInliers(const Camera& camera, const Rigid3d& world_from_cam,
                               const std::vector<Eigen::Vector2d>& pixels,
                               const std::vector<Eigen::Vector3d>& points_in_world,
                               const std::vector<int>& candidates, double threshold_px,
                               double* squared_error_sum) {
  std::vector<int> inliers;
  *squared_error_sum = 0;
  for (const int i : candidates) {
    Eigen::Vector2d residual;
    if (!ReprojectionResidual(camera, world_from_cam, points_in_world[i], pixels[i], &residual)) {
      continue;
    }
    if (residual.squaredNorm() <= threshold_px * threshold_px) {
      inliers.push_back(i);
      *squared_error_sum += residual.squaredNorm();
    }
  }
  return inliers;
}

// The Huber-robustified reprojection residuals of the inliers on one pose block.
class PoseProblem {
 public:
  PoseProblem(const Camera& camera, const Rigid3d& world_from_cam,
              const std::vector<Eigen::Vector2d>& pixels,
              const std::vector<Eigen::Vector3d>& points_in_world, const std::vector<int>& inliers,
              const AbsolutePoseOptions& options) {
    PoseToParameters(world_from_cam, pose_);
    for (const int i : inliers) {
      problem_.AddResidualBlock(new ReprojectionCost(camera, points_in_world[i], pixels[i]),
                                new ceres::HuberLoss(options.huber_scale_px), pose_);
    }
    problem_.SetManifold(pose_, new RightPerturbationManifold);
  }
  // The pose parameters (translation, quaternion x y z w).
  double* pose() { return pose_; }
  // The problem.
  ceres::Problem* problem() { return &problem_; }

 private:
  double pose_[kPoseParameters];
  ceres::Problem problem_;
};

// Minimises the Huber-robustified reprojection error of the inliers over world_from_cam.
Rigid3d Refine(const Camera& camera, const Rigid3d& initial,
               const std::vector<Eigen::Vector2d>& pixels,
               const std::vector<Eigen::Vector3d>& points_in_world, const std::vector<int>& inliers,
               const AbsolutePoseOptions& options) {
  PoseProblem problem(camera, initial, pixels, points_in_world, inliers, options);
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.max_num_iterations = options.max_refinement_iterations;
  solver_options.num_threads = 1;
  solver_options.logging_type = ceres::SILENT;
  solver_options.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, problem.problem(), &summary);
  return PoseFromParameters(problem.pose());
}

// sigma^2 (J^T J)^-1 at `world_from_cam` over the inliers, with the Huber loss applied as in the
// refinement; false when the information matrix is singular.
bool PoseCovariance(const Camera& camera, const Rigid3d& world_from_cam,
                    const std::vector<Eigen::Vector2d>& pixels,
                    const std::vector<Eigen::Vector3d>& points_in_world,
                    const std::vector<int>& inliers, double residual_variance,
                    const AbsolutePoseOptions& options, Matrix6d* covariance) {
  PoseProblem problem(camera, world_from_cam, pixels, points_in_world, inliers, options);
  const double* pose = problem.pose();
  ceres::Covariance::Options covariance_options;
  covariance_options.algorithm_type = ceres::DENSE_SVD;
  covariance_options.num_threads = 1;
  // A pseudo-inverse that drops the directions with a reciprocal condition number below
  // min_reciprocal_condition_number (1e-14): Ceres then computes silently (with rank 0 it would
  // log an error), and a dropped direction shows as a zero eigenvalue below.
  covariance_options.null_space_rank = -1;
  ceres::Covariance estimator(covariance_options);
  const std::vector<std::pair<const double*, const double*>> blocks = {{pose, pose}};
  if (!estimator.Compute(blocks, problem.problem())) return false;
  Eigen::Matrix<double, 6, 6, Eigen::RowMajor> tangent;
  if (!estimator.GetCovarianceBlockInTangentSpace(pose, pose, tangent.data())) return false;
  *covariance = residual_variance * tangent;
  *covariance = 0.5 * (*covariance + covariance->transpose());
  if (!covariance->allFinite()) return false;
  const Eigen::SelfAdjointEigenSolver<Matrix6d> eigen(*covariance);
  constexpr double kMinEigenvalueRatio = 1e-12;
  return eigen.eigenvalues().minCoeff() > kMinEigenvalueRatio * eigen.eigenvalues().maxCoeff();
}

}  // namespace

void AbsolutePoseOptions::Check() const {
  const auto fail = [](const std::string& what) {
    throw InvalidArgumentError("AbsolutePoseOptions: " + what);
  };
  if (!(reprojection_threshold_px > 0) || !std::isfinite(reprojection_threshold_px)) {
    fail("reprojection_threshold_px must be positive and finite");
  }
  if (!(confidence > 0 && confidence < 1)) fail("confidence must lie in (0, 1)");
  if (max_iterations < 1) fail("max_iterations must be at least 1");
  if (min_inliers < kMinimalSample) fail("min_inliers must be at least 4");
  if (!(min_inlier_ratio >= 0 && min_inlier_ratio <= 1)) {
    fail("min_inlier_ratio must lie in [0, 1]");
  }
  if (!(huber_scale_px > 0) || !std::isfinite(huber_scale_px)) {
    fail("huber_scale_px must be positive and finite");
  }
  if (max_refinement_iterations < 1) fail("max_refinement_iterations must be at least 1");
}

bool ReprojectionResidual(const Camera& camera, const Rigid3d& world_from_cam,
                          const Eigen::Vector3d& point_in_world, const Eigen::Vector2d& pixel,
                          Eigen::Vector2d* residual, Eigen::Matrix<double, 2, 6>* d_residual_d_xi) {
  // p_cam = R^T (p_world - t). With world_from_cam * ExpSE3(xi), to first order in xi = (v,
  // omega): p_cam(xi) = p_cam - v + p_cam x omega, so d p_cam / d (v, omega) = [-I, Hat(p_cam)].
  const Eigen::Vector3d point_in_cam =
      world_from_cam.rotation.conjugate() * (point_in_world - world_from_cam.translation);
  Eigen::Vector2d projected;
  Eigen::Matrix<double, 2, 3> d_pixel_d_point;
  if (!camera.Project(point_in_cam, &projected, d_residual_d_xi ? &d_pixel_d_point : nullptr)) {
    return false;
  }
  *residual = projected - pixel;
  if (d_residual_d_xi != nullptr) {
    d_residual_d_xi->leftCols<3>() = -d_pixel_d_point;
    d_residual_d_xi->rightCols<3>() = d_pixel_d_point * Hat(point_in_cam);
  }
  return true;
}

AbsolutePoseResult EstimateAbsolutePose(const Camera& camera,
                                        const std::vector<Eigen::Vector2d>& pixels,
                                        const std::vector<Eigen::Vector3d>& points_in_world,
                                        const AbsolutePoseOptions& options) {
  options.Check();
  camera.Check();
  if (pixels.size() != points_in_world.size()) {
    throw InvalidArgumentError("EstimateAbsolutePose: " + std::to_string(pixels.size()) +
                               " pixels but " + std::to_string(points_in_world.size()) + " points");
  }
  const int total = static_cast<int>(pixels.size());

  // Undistorted normalised coordinates of every usable correspondence.
  std::vector<int> usable;
  std::vector<cv::Point2d> normalized;
  std::vector<cv::Point3d> object_points;
  for (int i = 0; i < total; ++i) {
    Eigen::Vector3d ray;
    if (!pixels[i].allFinite() || !points_in_world[i].allFinite() ||
        !camera.Unproject(pixels[i], &ray)) {
      continue;
    }
    usable.push_back(i);
    normalized.emplace_back(ray.x(), ray.y());
    object_points.emplace_back(points_in_world[i].x(), points_in_world[i].y(),
                               points_in_world[i].z());
  }
  const int needed = std::max(kMinimalSample, options.min_inliers);
  if (static_cast<int>(usable.size()) < needed) {
    return Failure(AbsolutePoseFailure::kTooFewCorrespondences,
                   std::to_string(usable.size()) + " usable correspondences of " +
                       std::to_string(total) + ", at least " + std::to_string(needed) +
                       " are needed");
  }

  // P3P RANSAC on normalised coordinates: the pixel threshold becomes an angle-like threshold
  // through the mean focal length (the final inliers are chosen in pixels below).
  const double focal = 0.5 * (camera.fx + camera.fy);
  cv::Mat rotation_vector, translation;
  std::vector<int> ransac_inliers;
  bool found = false;
  try {
    found = cv::solvePnPRansac(object_points, normalized, cv::Mat::eye(3, 3, CV_64F), cv::Mat(),
                               rotation_vector, translation, false, options.max_iterations,
                               static_cast<float>(options.reprojection_threshold_px / focal),
                               options.confidence, ransac_inliers, cv::SOLVEPNP_AP3P);
  } catch (const cv::Exception&) {
    found = false;  // OpenCV throws on some degenerate configurations; treated as no model.
  }
  if (!found || rotation_vector.empty() || translation.empty()) {
    return Failure(AbsolutePoseFailure::kDegenerate, "RANSAC found no pose consistent with " +
                                                         std::to_string(usable.size()) +
                                                         " correspondences");
  }
  cv::Mat rotation_cv;
  cv::Rodrigues(rotation_vector, rotation_cv);
  Eigen::Matrix3d rotation;
  Eigen::Vector3d cam_translation;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) rotation(r, c) = rotation_cv.at<double>(r, c);
    cam_translation(r) = translation.at<double>(r);
  }
  const Rigid3d ransac_world_from_cam =
      Rigid3d(Eigen::Quaterniond(rotation), cam_translation).Inverse();
  if (!ransac_world_from_cam.IsFinite()) {
    return Failure(AbsolutePoseFailure::kDegenerate, "RANSAC returned a non-finite pose");
  }

  // Inliers in pixels through the full camera model; then refine, re-select, and refine again
  // when the inlier set changed.
  const auto enough = [&](int count) {
    return count >= options.min_inliers && count >= options.min_inlier_ratio * total;
  };
  const auto too_few = [&](int count) {
    return Failure(AbsolutePoseFailure::kTooFewInliers,
                   std::to_string(count) + " inliers of " + std::to_string(total) +
                       " correspondences within " +
                       FormatNumber(options.reprojection_threshold_px) + " px, at least " +
                       std::to_string(std::max<int>(
                           options.min_inliers,
                           static_cast<int>(std::ceil(options.min_inlier_ratio * total)))) +
                       " are needed");
  };
  double squared_error_sum = 0;
  Rigid3d world_from_cam = ransac_world_from_cam;
  std::vector<int> inliers = SelectInliers(camera, world_from_cam, pixels, points_in_world, usable,
                                           options.reprojection_threshold_px, &squared_error_sum);
  if (!enough(static_cast<int>(inliers.size()))) return too_few(static_cast<int>(inliers.size()));
  constexpr int kRefinementRounds = 2;
  for (int round = 0; options.refine && round < kRefinementRounds; ++round) {
    world_from_cam = Refine(camera, world_from_cam, pixels, points_in_world, inliers, options);
    if (!world_from_cam.IsFinite()) {
      return Failure(AbsolutePoseFailure::kDegenerate, "the refinement diverged");
    }
    std::vector<int> reselected =
        SelectInliers(camera, world_from_cam, pixels, points_in_world, usable,
                      options.reprojection_threshold_px, &squared_error_sum);
    const bool unchanged = reselected == inliers;
    inliers = std::move(reselected);
    if (!enough(static_cast<int>(inliers.size()))) {
      return too_few(static_cast<int>(inliers.size()));
    }
    if (unchanged) break;
  }

  AbsolutePoseResult result;
  const int count = static_cast<int>(inliers.size());
  const double residual_variance = squared_error_sum / std::max(1, 2 * count - 6);
  if (!PoseCovariance(camera, world_from_cam, pixels, points_in_world, inliers, residual_variance,
                      options, &result.covariance)) {
    return Failure(AbsolutePoseFailure::kDegenerate,
                   "the " + std::to_string(count) +
                       " inliers do not constrain all six degrees "
                       "of freedom of the pose");
  }
  result.success = true;
  result.world_from_cam = world_from_cam;
  result.ransac_world_from_cam = ransac_world_from_cam;
  result.inliers = std::move(inliers);
  result.rms_reprojection_error_px = std::sqrt(squared_error_sum / count);
  return result;
}

}  // namespace evloc::relocalization
