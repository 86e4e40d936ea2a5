#include "localizer/tracking/motion_model.h"

#include "core/common/error.h"

namespace evloc::tracking {

void ConstantVelocityModel::Reset(const Rigid3d& world_from_cam, int64_t t_ns) {
  last_world_from_cam_ = world_from_cam;
  last_t_ns_ = t_ns;
  velocity_ = Vector6d::Zero();
}

void ConstantVelocityModel::Update(const Rigid3d& world_from_cam, int64_t t_ns) {
  if (!last_t_ns_ || t_ns <= *last_t_ns_) {
    throw InvalidArgumentError(
        "ConstantVelocityModel::Update needs a pose later than the last one (call Reset first).");
  }
  const double dt_s = static_cast<double>(t_ns - *last_t_ns_) * 1e-9;
  velocity_ = LogSE3(last_world_from_cam_.Inverse() * world_from_cam) / dt_s;
  last_world_from_cam_ = world_from_cam;
  last_t_ns_ = t_ns;
}

Rigid3d ConstantVelocityModel::Predict(int64_t t_ns) const {
  if (!last_t_ns_) return last_world_from_cam_;
  const double dt_s = static_cast<double>(t_ns - *last_t_ns_) * 1e-9;
  return last_world_from_cam_ * ExpSE3(velocity_ * dt_s);
}

}  // namespace evloc::tracking
