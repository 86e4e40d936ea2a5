#include "mapper/pose_alignment.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <numbers>
#include <sstream>

#include <Eigen/SVD>

#include "core/common/error.h"

namespace evloc::mapper {
namespace {

// The rotation closest to `matrix` in the Frobenius norm (orthogonal polar factor, det +1).
Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& matrix) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(matrix, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d signs = Eigen::Vector3d::Ones();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) signs(2) = -1;
  return svd.matrixU() * signs.asDiagonal() * svd.matrixV().transpose();
}

}  // namespace

void PoseAlignmentOptions::Check() const {
  if (weight_iterations < 1) throw InvalidArgumentError("weight_iterations must be at least 1");
  if (max_iterations < 1) throw InvalidArgumentError("max_iterations must be at least 1");
  if (!(min_centre_variance_m2 > 0) || !(min_rotation_variance_rad2 > 0)) {
    throw InvalidArgumentError("the residual variance floors must be positive");
  }
}

PoseAlignment AlignPoses(const std::vector<Rigid3d>& model, const std::vector<Rigid3d>& reference,
                         const PoseAlignmentOptions& options) {
  options.Check();
  if (model.size() != reference.size()) {
    throw InvalidArgumentError("pose alignment: " + std::to_string(model.size()) +
                               " model poses but " + std::to_string(reference.size()) +
                               " reference poses");
  }
  const size_t count = model.size();
  if (count < 3) {
    throw InvalidArgumentError("pose alignment needs at least 3 poses, got " +
                               std::to_string(count));
  }
  std::vector<Eigen::Matrix3d> model_rotations(count);
  std::vector<Eigen::Matrix3d> reference_rotations(count);
  Eigen::Vector3d model_mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d reference_mean = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < count; ++i) {
    if (!model[i].translation.allFinite() || !reference[i].translation.allFinite() ||
        !model[i].rotation.coeffs().allFinite() || !reference[i].rotation.coeffs().allFinite()) {
      throw InvalidArgumentError("pose alignment: a pose contains NaN or infinity");
    }
    model_rotations[i] = model[i].rotation.normalized().toRotationMatrix();
    reference_rotations[i] = reference[i].rotation.normalized().toRotationMatrix();
    model_mean += model[i].translation;
    reference_mean += reference[i].translation;
  }
  model_mean /= static_cast<double>(count);
  reference_mean /= static_cast<double>(count);
  // Cross-covariance of the centred centres and of the orientations.
  Eigen::Matrix3d centre_covariance = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d orientation_sum = Eigen::Matrix3d::Zero();
  double model_spread = 0.0;
  double reference_spread = 0.0;
  for (size_t i = 0; i < count; ++i) {
    const Eigen::Vector3d a = model[i].translation - model_mean;
    const Eigen::Vector3d b = reference[i].translation - reference_mean;
    centre_covariance += b * a.transpose();
    orientation_sum += reference_rotations[i] * model_rotations[i].transpose();
    model_spread += a.squaredNorm();
    reference_spread += b.squaredNorm();
  }
  if (model_spread <= 1e-18) {
    throw InvalidArgumentError(
        "pose alignment is degenerate: the model camera centres coincide, so the scale is not "
        "determined");
  }

  const auto scale_for = [&](const Eigen::Matrix3d& rotation) {
    return (rotation.transpose() * centre_covariance).trace() / model_spread;
  };
  // Start: the rotation of the orientations alone, the scale of the centres.
  Eigen::Matrix3d rotation = NearestRotation(orientation_sum);
  double scale = scale_for(rotation);
  if (!(scale > 0)) {
    throw InvalidArgumentError(
        "pose alignment: the model's camera centres and orientations disagree with the "
        "reference's (negative scale); check that the reference poses are world_from_cam of the "
        "same images");
  }
  PoseAlignment result;
  result.num_poses = count;
  result.reference_spread = std::sqrt(reference_spread / static_cast<double>(count));
  const auto residuals = [&](double* centre_sum, double* chordal_sum) {
    *centre_sum = 0.0;
    *chordal_sum = 0.0;
    for (size_t i = 0; i < count; ++i) {
      const Eigen::Vector3d a = model[i].translation - model_mean;
      const Eigen::Vector3d b = reference[i].translation - reference_mean;
      *centre_sum += (scale * rotation * a - b).squaredNorm();
      *chordal_sum += (rotation * model_rotations[i] - reference_rotations[i]).squaredNorm();
    }
  };
  for (int weight_iteration = 0; weight_iteration < options.weight_iterations; ++weight_iteration) {
    double centre_sum = 0.0;
    double chordal_sum = 0.0;
    residuals(&centre_sum, &chordal_sum);
    // |R R_i - R'_i|_F^2 = 8 sin^2(angle / 2) ~ 2 angle^2.
    const double centre_variance =
        std::max(centre_sum / static_cast<double>(count), options.min_centre_variance_m2);
    const double chordal_variance = std::max(chordal_sum / static_cast<double>(count),
                                             2.0 * options.min_rotation_variance_rad2);
    const double weight = centre_variance / chordal_variance;
    result.orientation_weight = weight;
    for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
      const Eigen::Matrix3d next_rotation =
          NearestRotation(scale * centre_covariance + weight * orientation_sum);
      const double next_scale = scale_for(next_rotation);
      const bool converged = (next_rotation - rotation).norm() < 1e-13 &&
                             std::abs(next_scale - scale) <= 1e-13 * std::abs(scale);
      rotation = next_rotation;
      scale = next_scale;
      if (converged) break;
    }
    if (!(scale > 0)) {
      throw InvalidArgumentError(
          "pose alignment: the model's camera centres and orientations disagree with the "
          "reference's (negative scale)");
    }
  }

  result.reference_from_model.scale = scale;
  result.reference_from_model.rotation = Eigen::Quaterniond(rotation).normalized();
  result.reference_from_model.translation = reference_mean - scale * (rotation * model_mean);
  double centre_squares = 0.0;
  double angle_squares = 0.0;
  for (size_t i = 0; i < count; ++i) {
    const Rigid3d aligned = result.reference_from_model.TransformPose(model[i]);
    const double distance = (aligned.translation - reference[i].translation).norm();
    const double angle_deg =
        AngleBetween(aligned.rotation, reference[i].rotation) * 180.0 / std::numbers::pi;
    centre_squares += distance * distance;
    angle_squares += angle_deg * angle_deg;
    result.centre_max = std::max(result.centre_max, distance);
    result.rotation_max_deg = std::max(result.rotation_max_deg, angle_deg);
  }
  result.centre_rms = std::sqrt(centre_squares / static_cast<double>(count));
  result.rotation_rms_deg = std::sqrt(angle_squares / static_cast<double>(count));
  return result;
}

void AlignmentLimits::Check() const {
  if (!(max_centre_rms_fraction > 0.0)) {
    throw InvalidArgumentError("the alignment's max_centre_rms_fraction must be positive");
  }
  if (!(max_rotation_rms_deg > 0.0)) {
    throw InvalidArgumentError("the alignment's max_rotation_rms_deg must be positive");
  }
}

std::optional<std::string> AlignmentLimitViolation(const PoseAlignment& alignment,
                                                   const AlignmentLimits& limits) {
  limits.Check();
  const double fraction = alignment.reference_spread > 0.0
                              ? alignment.centre_rms / alignment.reference_spread
                              : std::numeric_limits<double>::infinity();
  const bool centres_off = !(fraction <= limits.max_centre_rms_fraction);
  const bool orientations_off = !(alignment.rotation_rms_deg <= limits.max_rotation_rms_deg);
  if (!centres_off && !orientations_off) return std::nullopt;
  std::ostringstream text;
  text << std::setprecision(3) << "the model does not fit the reference poses: after the Sim(3) "
       << "alignment of " << alignment.num_poses << " cameras the centres are "
       << alignment.centre_rms << " RMS (max " << alignment.centre_max << ") from the reference, "
       << 100.0 * fraction << " % of the reference camera path's spread "
       << alignment.reference_spread << " (limit " << 100.0 * limits.max_centre_rms_fraction
       << " %), and the orientations " << alignment.rotation_rms_deg << " deg RMS (max "
       << alignment.rotation_max_deg << " deg; limit " << limits.max_rotation_rms_deg
       << " deg RMS)";
  return text.str();
}

}  // namespace evloc::mapper
