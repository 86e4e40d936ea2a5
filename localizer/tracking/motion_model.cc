#include "localizer/tracking/motion_model.h"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "core/common/error.h"

namespace evloc::tracking {

void ConstantVelocityModel::Reset(const Rigid3d& world_from_cam, int64_t t_ns) {
  last_world_from_cam_ = world_from_cam;
  last_t_ns_ = t_ns;
  velocity_ = Vector6d::Zero();
  velocity_span_ns_ = 0;
  smooth_velocity_ = Vector6d::Zero();
  smooth_velocity_span_ns_ = 0;
  history_.clear();
  history_.emplace_back(t_ns, world_from_cam);
}

void ConstantVelocityModel::Reset(const Rigid3d& world_from_cam, int64_t t_ns,
                                  const Vector6d& velocity) {
  if (!velocity.allFinite()) {
    throw InvalidArgumentError("ConstantVelocityModel::Reset: the velocity is not finite.");
  }
  Reset(world_from_cam, t_ns);
  constexpr int64_t kShortestSeedNs = 1'000'000;
  const int64_t span_ns = std::max(smooth_window_ns_, kShortestSeedNs);
  history_.emplace_front(
      t_ns - span_ns, world_from_cam * ExpSE3(-velocity * (static_cast<double>(span_ns) * 1e-9)));
  velocity_ = velocity;
  velocity_span_ns_ = span_ns;
  smooth_velocity_ = velocity;
  smooth_velocity_span_ns_ = span_ns;
}

void ConstantVelocityModel::Update(const Rigid3d& world_from_cam, int64_t t_ns) {
  if (!last_t_ns_ || t_ns <= *last_t_ns_) {
    throw InvalidArgumentError(
        "ConstantVelocityModel::Update needs a pose later than the last one (call Reset first).");
  }
  history_.emplace_back(t_ns, world_from_cam);
  // Keep the oldest pose within the longer window, and always the previous one.
  while (history_.size() > 2 && t_ns - history_[1].first >= smooth_window_ns_) {
    history_.pop_front();
  }
  std::tie(velocity_, velocity_span_ns_) = TwistOver(window_ns_);
  if (smooth_window_ns_ == window_ns_) {
    smooth_velocity_ = velocity_;
    smooth_velocity_span_ns_ = velocity_span_ns_;
  } else {
    std::tie(smooth_velocity_, smooth_velocity_span_ns_) = TwistOver(smooth_window_ns_);
  }
  last_world_from_cam_ = world_from_cam;
  last_t_ns_ = t_ns;
}

std::pair<Vector6d, int64_t> ConstantVelocityModel::TwistOver(int64_t window_ns) const {
  const auto& [newest_t_ns, newest_world_from_cam] = history_.back();
  size_t oldest = 0;
  for (size_t i = history_.size() - 1; i-- > 0;) {
    if (newest_t_ns - history_[i].first >= window_ns) {
      oldest = i;
      break;
    }
  }
  const auto& [oldest_t_ns, oldest_world_from_cam] = history_[oldest];
  const int64_t span_ns = newest_t_ns - oldest_t_ns;
  return {LogSE3(oldest_world_from_cam.Inverse() * newest_world_from_cam) /
              (static_cast<double>(span_ns) * 1e-9),
          span_ns};
}

Rigid3d ConstantVelocityModel::Predict(int64_t t_ns) const {
  double dt_s = SecondsSinceLast(t_ns);
  if (decay_time_ns_ > 0) {
    // The distance a velocity decaying as exp(-t / tau) covers in dt: tau * (1 - exp(-dt / tau)).
    const double tau_s = static_cast<double>(decay_time_ns_) * 1e-9;
    dt_s = -tau_s * std::expm1(-dt_s / tau_s);
  }
  return Extrapolate(velocity_, dt_s);
}

Rigid3d ConstantVelocityModel::PredictSmooth(int64_t t_ns) const {
  return Extrapolate(smooth_velocity_, SecondsSinceLast(t_ns));
}

double ConstantVelocityModel::SecondsSinceLast(int64_t t_ns) const {
  return last_t_ns_ ? static_cast<double>(t_ns - *last_t_ns_) * 1e-9 : 0.0;
}

Rigid3d ConstantVelocityModel::Extrapolate(const Vector6d& velocity, double dt_s) const {
  if (!last_t_ns_) return last_world_from_cam_;
  return last_world_from_cam_ * ExpSE3(velocity * dt_s);
}

}  // namespace evloc::tracking
