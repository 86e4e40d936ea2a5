#include "localizer/tracking/polarity.h"

#include <cmath>
#include <numbers>

namespace evloc::tracking {

namespace {

PredictedPolarity Classify(const Eigen::Vector2d& gradient, const Eigen::Vector2d& flow,
                           double min_flow_px, double band_sine) {
  const double gradient_norm = gradient.norm();
  const double flow_norm = flow.norm();
  if (!(gradient_norm > 0) || !(flow_norm >= min_flow_px) || flow_norm == 0) {
    return PredictedPolarity::kUnsigned;
  }
  // cos of the angle between d and f; the band [90 - w/2, 90 + w/2] is |cos| <= sin(w/2).
  const double cosine = gradient.dot(flow) / (gradient_norm * flow_norm);
  if (std::abs(cosine) <= band_sine) return PredictedPolarity::kUnsigned;
  return -cosine > 0 ? PredictedPolarity::kOn : PredictedPolarity::kOff;
}

double BandSine(const PolarityPredictionOptions& options) {
  return std::sin(0.5 * options.neutral_band_deg * std::numbers::pi / 180.0);
}

}  // namespace

PredictedPolarity ClassifyPolarity(const Eigen::Vector2d& gradient, const Eigen::Vector2d& flow,
                                   const PolarityPredictionOptions& options) {
  return Classify(gradient, flow, options.min_flow_px, BandSine(options));
}

PolarityPredictor::PolarityPredictor(const PinholeIntrinsics& intrinsics,
                                     const Rigid3d& predicted_cam_from_world,
                                     const Rigid3d& previous_cam_from_world,
                                     const PolarityPredictionOptions& options)
    : intrinsics_(intrinsics),
      predicted_rotation_(predicted_cam_from_world.RotationMatrix()),
      predicted_translation_(predicted_cam_from_world.translation),
      previous_rotation_(previous_cam_from_world.RotationMatrix()),
      previous_translation_(previous_cam_from_world.translation),
      options_(options),
      band_sine_(BandSine(options)) {}

PredictedPolarity PolarityPredictor::Predict(const Eigen::Vector3d& position_world,
                                             const Eigen::Vector3d& gradient_world) const {
  const Eigen::Vector3d point_in_cam =
      predicted_rotation_ * position_world + predicted_translation_;
  const double probe_length = options_.gradient_probe_depth_fraction * point_in_cam.z();
  Eigen::Vector2d pixel;
  Eigen::Vector2d probe_pixel;
  Eigen::Vector2d previous_pixel;
  if (!intrinsics_.Project(point_in_cam, &pixel) ||
      !intrinsics_.Project(point_in_cam + probe_length * (predicted_rotation_ * gradient_world),
                           &probe_pixel) ||
      !intrinsics_.Project(previous_rotation_ * position_world + previous_translation_,
                           &previous_pixel)) {
    return PredictedPolarity::kUnsigned;
  }
  return Classify(probe_pixel - pixel, pixel - previous_pixel, options_.min_flow_px, band_sine_);
}

PredictedPolarity PredictPolarity(const Eigen::Vector3d& position_world,
                                  const Eigen::Vector3d& gradient_world,
                                  const PinholeIntrinsics& intrinsics,
                                  const Rigid3d& predicted_cam_from_world,
                                  const Rigid3d& previous_cam_from_world,
                                  const PolarityPredictionOptions& options) {
  return PolarityPredictor(intrinsics, predicted_cam_from_world, previous_cam_from_world, options)
      .Predict(position_world, gradient_world);
}

}  // namespace evloc::tracking
