#include "core/dataset/pose_text.h"

#include <cmath>
#include <sstream>
#include <vector>

#include "core/common/cli.h"
#include "core/common/error.h"

namespace evloc {

Rigid3d ParsePoseTokens(std::string_view what, std::span<const std::string> tokens) {
  if (tokens.size() != 7) {
    throw InvalidArgumentError(std::string(what) +
                               " expects 7 numbers \"tx ty tz qx qy qz qw\", got " +
                               std::to_string(tokens.size()));
  }
  double values[7];
  for (size_t i = 0; i < 7; ++i) values[i] = ParseDoubleFlag(what, tokens[i]);
  const Eigen::Quaterniond rotation(values[6], values[3], values[4], values[5]);
  const double norm = rotation.norm();
  if (!(std::abs(norm - 1.0) <= kPoseQuaternionNormTolerance)) {
    throw InvalidArgumentError(std::string(what) + ": the quaternion (qx qy qz qw) has norm " +
                               std::to_string(norm) +
                               "; a rotation needs a unit quaternion (within " +
                               std::to_string(kPoseQuaternionNormTolerance) + ")");
  }
  return Rigid3d(rotation.normalized(), Eigen::Vector3d(values[0], values[1], values[2]));
}

namespace {

// The tokens of `text`, separated by white space.
std::vector<std::string> Tokens(std::string_view text) {
  std::istringstream stream{std::string(text)};
  std::vector<std::string> tokens;
  std::string token;
  while (stream >> token) tokens.push_back(token);
  return tokens;
}

}  // namespace

Rigid3d ParsePoseText(std::string_view what, std::string_view text) {
  return ParsePoseTokens(what, Tokens(text));
}

Vector6d ParseTwistText(std::string_view what, std::string_view text) {
  const std::vector<std::string> tokens = Tokens(text);
  if (tokens.size() != 6) {
    throw InvalidArgumentError(std::string(what) +
                               " expects 6 numbers \"vx vy vz wx wy wz\", got " +
                               std::to_string(tokens.size()));
  }
  Vector6d twist;
  for (int i = 0; i < 6; ++i) twist[i] = ParseDoubleFlag(what, tokens[i]);
  return twist;
}

}  // namespace evloc
