#include "localizer/wire/twist.h"

#include <string>

#include "core/common/error.h"

namespace evloc::wire {
namespace {

Eigen::Vector3d VectorFromProto(const map_format::Vector3& v, double bound, std::string_view what,
                                std::string_view unit) {
  const Eigen::Vector3d value(v.x(), v.y(), v.z());
  if (!value.allFinite()) throw InvalidArgumentError(std::string(what) + " is not finite");
  if (value.norm() > bound) {
    throw InvalidArgumentError(std::string(what) + " is " + std::to_string(value.norm()) + " " +
                               std::string(unit) + "; at most " + std::to_string(bound) +
                               " is accepted");
  }
  return value;
}

void VectorToProto(const Eigen::Vector3d& value, map_format::Vector3* out) {
  out->set_x(value.x());
  out->set_y(value.y());
  out->set_z(value.z());
}

}  // namespace

Vector6d TwistFromProto(const api::Twist& twist, std::string_view what) {
  if (!twist.has_linear() || !twist.has_angular()) {
    throw InvalidArgumentError(std::string(what) +
                               " needs both its linear and its angular part (send zeros for none)");
  }
  Vector6d out;
  out.head<3>() =
      VectorFromProto(twist.linear(), kMaxTwistLinear, std::string(what) + ".linear", "m/s");
  out.tail<3>() =
      VectorFromProto(twist.angular(), kMaxTwistAngular, std::string(what) + ".angular", "rad/s");
  return out;
}

api::Twist TwistToProto(const Vector6d& twist) {
  api::Twist out;
  VectorToProto(twist.head<3>(), out.mutable_linear());
  VectorToProto(twist.tail<3>(), out.mutable_angular());
  return out;
}

}  // namespace evloc::wire
