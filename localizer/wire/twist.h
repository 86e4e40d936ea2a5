// The velocity of a pose on the wire (api::Twist), for a session resumed elsewhere at the pose
// and velocity its client last received (docs/api.md, "Reconnecting").
#pragma once

#include <cstdint>
#include <string_view>

#include "core/geometry/rigid3.h"
#include "evloc/localizer.pb.h"

namespace evloc::wire {

// The window over which a client measures the velocity it sends from a trajectory (evloc-load and
// evloc-replay --initial-velocity truth): the tracker's constant-velocity window
// (TrackerOptions::velocity_window_s, 20 ms), so that the session starts as it would measure it.
inline constexpr int64_t kClientVelocityWindowNs = 20'000'000;

// Largest |linear| (m/s) and |angular| (rad/s) a Twist may carry.
inline constexpr double kMaxTwistLinear = 1000;
inline constexpr double kMaxTwistAngular = 100;

// The twist (linear, angular) of a Twist message. Throws InvalidArgumentError naming `what` for a
// missing part, a non-finite value or a value beyond the bounds above.
Vector6d TwistFromProto(const api::Twist& twist, std::string_view what);
api::Twist TwistToProto(const Vector6d& twist);

}  // namespace evloc::wire
