// The constant-velocity motion prior on SE(3) (docs/tracking.md, "Registration"): the body-frame
// twist over the recent estimates, extrapolated to the next step time.
#pragma once

#include <algorithm>
#include <cstdint>
#include <deque>
#include <optional>
#include <utility>

#include "core/geometry/rigid3.h"

namespace evloc::tracking {

// Predicts world_from_cam at a later time from the recent poses. The velocity is the twist
// between the newest pose and the oldest one within `window_ns` of it (at least the previous
// pose): a single step of a few milliseconds turns millimetre pose noise into a velocity noise
// of decimetres per second, which the window divides by the number of steps it spans.
class ConstantVelocityModel {
 public:
  // `window_ns` = 0 takes the velocity from the last two poses only. `smooth_window_ns` is the
  // window of smooth_velocity() (at least `window_ns` is used). `decay_time_ns` > 0 damps
  // Predict(): the velocity is taken to decay exponentially with that time constant (a
  // first-order Gauss-Markov velocity), so the prediction moves by
  // velocity * tau * (1 - exp(-dt / tau)) instead of velocity * dt; 0 = constant velocity.
  explicit ConstantVelocityModel(int64_t window_ns = 0, int64_t smooth_window_ns = 0,
                                 int64_t decay_time_ns = 0)
      : window_ns_(window_ns),
        smooth_window_ns_(std::max(window_ns, smooth_window_ns)),
        decay_time_ns_(std::max<int64_t>(decay_time_ns, 0)) {}

  // Forgets the history and sets the pose at t_ns; the velocity becomes zero.
  void Reset(const Rigid3d& world_from_cam, int64_t t_ns);
  // Forgets the history and sets the pose at t_ns moving with `velocity` (a body-frame twist per
  // second, as velocity()), e.g. a session resumed elsewhere with the velocity its client
  // measured: the history starts with the pose one smooth window (at least 1 ms) earlier on that
  // motion, so both velocities equal `velocity` over a full window at once and the newer
  // estimates replace it as they arrive. Throws InvalidArgumentError for a non-finite velocity.
  void Reset(const Rigid3d& world_from_cam, int64_t t_ns, const Vector6d& velocity);
  // Adds the estimate at t_ns (after the last one) and updates the velocity. Throws
  // InvalidArgumentError when t_ns is not after the last time or no pose was set.
  void Update(const Rigid3d& world_from_cam, int64_t t_ns);
  // Keeps the last pose but sets the velocity to zero and forgets the history (after a failure).
  void StopMotion() { Reset(last_world_from_cam_, last_t_ns_.value_or(0)); }

  // True once Reset was called.
  bool initialized() const { return last_t_ns_.has_value(); }
  // The last pose.
  const Rigid3d& last_world_from_cam() const { return last_world_from_cam_; }
  // The time of the last pose (0 before Reset).
  int64_t last_t_ns() const { return last_t_ns_.value_or(0); }
  // The body-frame twist per second, (v, omega): world_from_cam(t + dt) =
  // world_from_cam(t) * ExpSE3(velocity * dt).
  const Vector6d& velocity() const { return velocity_; }
  // The time span the velocity was measured over, ns (0 after Reset).
  int64_t velocity_span_ns() const { return velocity_span_ns_; }
  // The same twist measured over the longer smooth window: pose noise averages out further, at
  // the price of lagging behind an acceleration (for short extrapolations, Tracker's step-time
  // stamping). Equal to velocity() while the history is shorter than the short window.
  const Vector6d& smooth_velocity() const { return smooth_velocity_; }
  // The time span smooth_velocity() was measured over, ns (0 after Reset).
  int64_t smooth_velocity_span_ns() const { return smooth_velocity_span_ns_; }
  // The smooth window, ns.
  int64_t smooth_window_ns() const { return smooth_window_ns_; }

  // The pose predicted at t_ns (the last pose when not initialized or at the same time), damped
  // by the decay time when there is one.
  Rigid3d Predict(int64_t t_ns) const;
  // The same along smooth_velocity(), undamped (the motion prior's centre).
  Rigid3d PredictSmooth(int64_t t_ns) const;

 private:
  // The twist from the oldest pose of `history_` that is at least `window_ns` older than the
  // newest (at least the previous pose; the oldest when none is), and that span.
  std::pair<Vector6d, int64_t> TwistOver(int64_t window_ns) const;
  // The last pose moved on by `velocity` for `dt_s` seconds.
  Rigid3d Extrapolate(const Vector6d& velocity, double dt_s) const;
  // The time from the last pose to t_ns, seconds (0 when not initialized).
  double SecondsSinceLast(int64_t t_ns) const;

  int64_t window_ns_ = 0;
  int64_t smooth_window_ns_ = 0;
  int64_t decay_time_ns_ = 0;
  Rigid3d last_world_from_cam_;
  std::optional<int64_t> last_t_ns_;
  Vector6d velocity_ = Vector6d::Zero();
  int64_t velocity_span_ns_ = 0;
  Vector6d smooth_velocity_ = Vector6d::Zero();
  int64_t smooth_velocity_span_ns_ = 0;
  // The poses since the last Reset within the smooth window of the newest (newest last).
  std::deque<std::pair<int64_t, Rigid3d>> history_;
};

}  // namespace evloc::tracking
