// The velocity of a pose on the wire (api::Twist), for a session resumed elsewhere at the pose
// and velocity its client last received (docs/api.md, "Reconnecting").
#pragma once

#include <string_view>

#include "core/geometry/rigid3.h"
#include "evloc/localizer.pb.h"

namespace evloc::wire {

// Largest |linear| (m/s) and |angular| (rad/s) a Twist may carry.
inline constexpr double kMaxTwistLinear = 1000;
inline constexpr double kMaxTwistAngular = 100;

// The twist (linear, angular) of a Twist message. Throws InvalidArgumentError naming `what` for a
// missing part, a non-finite value or a value beyond the bounds above.
Vector6d TwistFromProto(const api::Twist& twist, std::string_view what);
api::Twist TwistToProto(const Vector6d& twist);

}  // namespace evloc::wire
