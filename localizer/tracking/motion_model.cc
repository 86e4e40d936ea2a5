#include "localizer/tracking/motion_model.h"

#include "core/common/error.h"

namespace evloc::tracking {

void ConstantVelocityModel::Reset(const Rigid3d& world_from_cam, int64_t t_ns) {
  last_world_from_cam_ = world_from_cam;
  last_t_ns_ = t_ns;
  velocity_ = Vector6d::Zero();
  velocity_span_ns_ = 0;
  history_.clear();
  history_.emplace_back(t_ns, world_from_cam);
}

void ConstantVelocityModel::Update(const Rigid3d& world_from_cam, int64_t t_ns) {
  if (!last_t_ns_ || t_ns <= *last_t_ns_) {
    throw InvalidArgumentError(
        "ConstantVelocityModel::Update needs a pose later than the last one (call Reset first).");
  }
  history_.emplace_back(t_ns, world_from_cam);
  // Keep the oldest pose within the window, and always the previous one.
  while (history_.size() > 2 && t_ns - history_[1].first >= window_ns_) history_.pop_front();
  const auto& [oldest_t_ns, oldest_world_from_cam] = history_.front();
  velocity_span_ns_ = t_ns - oldest_t_ns;
  velocity_ = LogSE3(oldest_world_from_cam.Inverse() * world_from_cam) /
              (static_cast<double>(velocity_span_ns_) * 1e-9);
  last_world_from_cam_ = world_from_cam;
  last_t_ns_ = t_ns;
}

Rigid3d ConstantVelocityModel::Predict(int64_t t_ns) const {
  if (!last_t_ns_) return last_world_from_cam_;
  const double dt_s = static_cast<double>(t_ns - *last_t_ns_) * 1e-9;
  return last_world_from_cam_ * ExpSE3(velocity_ * dt_s);
}

}  // namespace evloc::tracking
