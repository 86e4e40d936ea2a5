// The constant-velocity motion prior on SE(3) (method.md §4.2): the body-frame twist between the
// last two estimates, extrapolated to the next step time.
#pragma once

#include <cstdint>
#include <optional>

#include "core/geometry/rigid3.h"

namespace evloc::tracking {

// Predicts world_from_cam at a later time from the last two poses.
class ConstantVelocityModel {
 public:
  // Forgets the history and sets the pose at t_ns; the velocity becomes zero.
  void Reset(const Rigid3d& world_from_cam, int64_t t_ns);
  // Adds the estimate at t_ns (after the last one); the velocity becomes the twist between the
  // previous and this pose divided by the elapsed time. Throws InvalidArgumentError when t_ns is
  // not after the last time or no pose was set.
  void Update(const Rigid3d& world_from_cam, int64_t t_ns);
  // Keeps the last pose but sets the velocity to zero (after a failure).
  void StopMotion() { velocity_ = Vector6d::Zero(); }

  // True once Reset was called.
  bool initialized() const { return last_t_ns_.has_value(); }
  // The last pose.
  const Rigid3d& last_world_from_cam() const { return last_world_from_cam_; }
  // The time of the last pose (0 before Reset).
  int64_t last_t_ns() const { return last_t_ns_.value_or(0); }
  // The body-frame twist per second, (v, omega): world_from_cam(t + dt) =
  // world_from_cam(t) * ExpSE3(velocity * dt).
  const Vector6d& velocity() const { return velocity_; }

  // The pose predicted at t_ns (the last pose when not initialized or at the same time).
  Rigid3d Predict(int64_t t_ns) const;

 private:
  Rigid3d last_world_from_cam_;
  std::optional<int64_t> last_t_ns_;
  Vector6d velocity_ = Vector6d::Zero();
};

}  // namespace evloc::tracking
