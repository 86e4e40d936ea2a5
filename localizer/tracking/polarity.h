// Polarity prediction for signed time surfaces (docs/tracking.md, "Polarity-aware registration").
// Brightness constancy gives dI/dt = -grad I . f, so a point whose image gradient d (towards
// brighter) and flow f satisfy -d . f > 0 fires ON events, and OFF events when -d . f < 0. Near 90
// degrees the prediction is not trusted.
#pragma once

#include <Eigen/Core>

#include "core/geometry/rigid3.h"
#include "localizer/tracking/registration.h"

namespace evloc::tracking {

// The surface a point registers against.
enum class PredictedPolarity : int {
  // The angle between gradient and flow is in the neutral band, or the flow is too small: the
  // unsigned surface (all events).
  kUnsigned = 0,
  // ON events expected.
  kOn = 1,
  // OFF events expected.
  kOff = 2,
};

// Options of the prediction.
struct PolarityPredictionOptions {
  // Total width of the neutral band around 90 degrees, degrees.
  double neutral_band_deg = 30.0;
  // Length of the gradient probe P + s g as a fraction of the depth of P.
  double gradient_probe_depth_fraction = 0.01;
  // Flows shorter than this (pixels) give kUnsigned.
  double min_flow_px = 0.05;
};

// Classifies a 2D gradient direction `gradient` (towards brighter, any length) and an image flow
// `flow` (pixels): kOn when -d.f > 0 outside the neutral band, kOff when -d.f < 0, else kUnsigned.
PredictedPolarity ClassifyPolarity(const Eigen::Vector2d& gradient, const Eigen::Vector2d& flow,
                                   const PolarityPredictionOptions& options);

// Predicts the polarity of map point P with unit 3D gradient g: d = pi(P + s g) - pi(P) at the
// predicted pose, f = pi_predicted(P) - pi_previous(P). kUnsigned when a projection fails.
PredictedPolarity PredictPolarity(const Eigen::Vector3d& position_world,
                                  const Eigen::Vector3d& gradient_world,
                                  const PinholeIntrinsics& intrinsics,
                                  const Rigid3d& predicted_cam_from_world,
                                  const Rigid3d& previous_cam_from_world,
                                  const PolarityPredictionOptions& options);

// PredictPolarity for many points at one pair of poses: the rotation matrices and the band
// threshold are computed once (the tracker predicts ~2000 points per step).
class PolarityPredictor {
 public:
  // Predictions at `predicted_cam_from_world` with the flow from `previous_cam_from_world`.
  PolarityPredictor(const PinholeIntrinsics& intrinsics, const Rigid3d& predicted_cam_from_world,
                    const Rigid3d& previous_cam_from_world,
                    const PolarityPredictionOptions& options);

  // Same result as PredictPolarity with the constructor's arguments.
  PredictedPolarity Predict(const Eigen::Vector3d& position_world,
                            const Eigen::Vector3d& gradient_world) const;

 private:
  PinholeIntrinsics intrinsics_;
  Eigen::Matrix3d predicted_rotation_;
  Eigen::Vector3d predicted_translation_;
  Eigen::Matrix3d previous_rotation_;
  Eigen::Vector3d previous_translation_;
  PolarityPredictionOptions options_;
  // sin(neutral_band / 2): |cos angle(d, f)| at or below it is in the band.
  double band_sine_ = 0;
};

}  // namespace evloc::tracking
