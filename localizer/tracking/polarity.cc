#include "localizer/tracking/polarity.h"

#include <cmath>
#include <numbers>

namespace evloc::tracking {

PredictedPolarity ClassifyPolarity(const Eigen::Vector2d& gradient, const Eigen::Vector2d& flow,
                                   const PolarityPredictionOptions& options) {
  const double gradient_norm = gradient.norm();
  const double flow_norm = flow.norm();
  if (!(gradient_norm > 0) || !(flow_norm >= options.min_flow_px) || flow_norm == 0) {
    return PredictedPolarity::kUnsigned;
  }
  // cos of the angle between d and f; the band [90 - w/2, 90 + w/2] is |cos| < sin(w/2).
  const double cosine = gradient.dot(flow) / (gradient_norm * flow_norm);
  const double half_band_rad = 0.5 * options.neutral_band_deg * std::numbers::pi / 180.0;
  if (std::abs(cosine) <= std::sin(half_band_rad)) return PredictedPolarity::kUnsigned;
  return -cosine > 0 ? PredictedPolarity::kOn : PredictedPolarity::kOff;
}

PredictedPolarity PredictPolarity(const Eigen::Vector3d& position_world,
                                  const Eigen::Vector3d& gradient_world,
                                  const PinholeIntrinsics& intrinsics,
                                  const Rigid3d& predicted_cam_from_world,
                                  const Rigid3d& previous_cam_from_world,
                                  const PolarityPredictionOptions& options) {
  const Eigen::Vector3d point_in_cam = predicted_cam_from_world * position_world;
  const double probe_length = options.gradient_probe_depth_fraction * point_in_cam.z();
  Eigen::Vector2d pixel;
  Eigen::Vector2d probe_pixel;
  Eigen::Vector2d previous_pixel;
  if (!intrinsics.Project(point_in_cam, &pixel) ||
      !intrinsics.Project(
          point_in_cam + probe_length * (predicted_cam_from_world.rotation * gradient_world),
          &probe_pixel) ||
      !intrinsics.Project(previous_cam_from_world * position_world, &previous_pixel)) {
    return PredictedPolarity::kUnsigned;
  }
  return ClassifyPolarity(probe_pixel - pixel, pixel - previous_pixel, options);
}

}  // namespace evloc::tracking
