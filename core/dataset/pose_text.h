// Pose text: the one parser of a pose written as seven numbers `tx ty tz qx qy qz qw` (TUM order,
// world_from_cam), for command-line flags (--init-pose) and for named-pose files (the mapper's
// `IMAGE_NAME tx ty tz qx qy qz qw` lines); and of a velocity written as six numbers
// `vx vy vz wx wy wz` (--initial-velocity), by the same token rule.
//
// The rule (docs/dataset-format.md, "Pose text"): exactly seven tokens; each token is a finite
// decimal number consumed whole (no "nan", "inf", "1.5m" or empty token); the quaternion
// (qx qy qz qw) has a norm within kPoseQuaternionNormTolerance of 1, and is then normalised.
// A quaternion further from unit norm is a mistake (wrong column order, a missing field, a
// rotation matrix row), never rounding, and is refused instead of silently normalised.
#pragma once

#include <span>
#include <string>
#include <string_view>

#include "core/geometry/rigid3.h"

namespace evloc {

// Largest accepted | |q| - 1 | of a pose text's quaternion: quaternions printed with four or more
// decimals pass.
inline constexpr double kPoseQuaternionNormTolerance = 1e-3;

// Parses seven tokens `tx ty tz qx qy qz qw` by the rule above. Throws InvalidArgumentError whose
// message starts with `what` (a flag name, or "pose") and says what is wrong.
Rigid3d ParsePoseTokens(std::string_view what, std::span<const std::string> tokens);

// Parses "tx ty tz qx qy qz qw" (tokens separated by white space) by the rule above. Throws
// InvalidArgumentError whose message starts with `what`.
Rigid3d ParsePoseText(std::string_view what, std::string_view text);

// Parses "vx vy vz wx wy wz" (a body-frame twist of world_from_cam: m/s, then rad/s, camera
// frame), six tokens by the rule above. Throws InvalidArgumentError whose message starts with
// `what`.
Vector6d ParseTwistText(std::string_view what, std::string_view text);

}  // namespace evloc
