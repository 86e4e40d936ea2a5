#include "proto/convert/proto_convert.h"

#include <cmath>
#include <initializer_list>
#include <string>

#include "core/common/error.h"

namespace evloc {
namespace {

// The largest camera side a protobuf camera may declare, pixels.
constexpr uint32_t kMaxProtoCameraSide = 65535;

bool AllFinite(std::initializer_list<double> values) {
  for (double value : values) {
    if (!std::isfinite(value)) return false;
  }
  return true;
}

// The checks of RigidFromProto and RigidFromProtoExact: returns the stored quaternion and
// translation as they are.
Rigid3d CheckedRigid(const map_format::Rigid3& pose, std::string_view what) {
  const auto& q = pose.rotation();
  const auto& t = pose.translation();
  if (!AllFinite({q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z()})) {
    throw InvalidArgumentError(std::string(what) + ": the pose has a non-finite value");
  }
  Rigid3d result;
  result.rotation = Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z());
  result.translation = Eigen::Vector3d(t.x(), t.y(), t.z());
  if (std::abs(result.rotation.norm() - 1.0) > kProtoQuaternionNormTolerance) {
    throw InvalidArgumentError(std::string(what) +
                               ": the rotation must be a unit quaternion (norm " +
                               std::to_string(result.rotation.norm()) + ")");
  }
  return result;
}

}  // namespace

Camera CameraFromProto(const map_format::Camera& camera, std::string_view what) {
  Camera result;
  switch (camera.model()) {
    case map_format::CAMERA_MODEL_PINHOLE:
      result.model = CameraModel::kPinhole;
      break;
    case map_format::CAMERA_MODEL_RADIAL_TANGENTIAL:
      result.model = CameraModel::kRadialTangential;
      break;
    case map_format::CAMERA_MODEL_EQUIDISTANT:
      result.model = CameraModel::kEquidistant;
      break;
    default:
      throw InvalidArgumentError(std::string(what) + ".model is not set or unknown (code " +
                                 std::to_string(static_cast<int>(camera.model())) +
                                 "; expected PINHOLE, RADIAL_TANGENTIAL or EQUIDISTANT)");
  }
  if (camera.width() == 0 || camera.height() == 0 || camera.width() > kMaxProtoCameraSide ||
      camera.height() > kMaxProtoCameraSide) {
    throw InvalidArgumentError(std::string(what) + ": width and height must be 1..65535, got " +
                               std::to_string(camera.width()) + "x" +
                               std::to_string(camera.height()));
  }
  result.width = static_cast<int>(camera.width());
  result.height = static_cast<int>(camera.height());
  result.fx = camera.fx();
  result.fy = camera.fy();
  result.cx = camera.cx();
  result.cy = camera.cy();
  result.distortion.assign(camera.distortion().begin(), camera.distortion().end());
  if (result.model == CameraModel::kRadialTangential && result.distortion.size() == 4) {
    result.distortion.push_back(0.0);
  }
  try {
    result.Check();
  } catch (const InvalidArgumentError& error) {
    throw InvalidArgumentError(std::string(what) + ": " + error.what());
  }
  return result;
}

map_format::Camera CameraToProto(const Camera& camera) {
  map_format::Camera result;
  switch (camera.model) {
    case CameraModel::kPinhole:
      result.set_model(map_format::CAMERA_MODEL_PINHOLE);
      break;
    case CameraModel::kRadialTangential:
      result.set_model(map_format::CAMERA_MODEL_RADIAL_TANGENTIAL);
      break;
    case CameraModel::kEquidistant:
      result.set_model(map_format::CAMERA_MODEL_EQUIDISTANT);
      break;
  }
  result.set_width(static_cast<uint32_t>(camera.width));
  result.set_height(static_cast<uint32_t>(camera.height));
  result.set_fx(camera.fx);
  result.set_fy(camera.fy);
  result.set_cx(camera.cx);
  result.set_cy(camera.cy);
  for (double value : camera.distortion) result.add_distortion(value);
  return result;
}

Rigid3d RigidFromProto(const map_format::Rigid3& pose, std::string_view what) {
  const Rigid3d stored = CheckedRigid(pose, what);
  return Rigid3d(stored.rotation.normalized(), stored.translation);
}

Rigid3d RigidFromProtoExact(const map_format::Rigid3& pose, std::string_view what) {
  return CheckedRigid(pose, what);
}

map_format::Rigid3 RigidToProto(const Rigid3d& pose) {
  map_format::Rigid3 result;
  result.mutable_rotation()->set_w(pose.rotation.w());
  result.mutable_rotation()->set_x(pose.rotation.x());
  result.mutable_rotation()->set_y(pose.rotation.y());
  result.mutable_rotation()->set_z(pose.rotation.z());
  result.mutable_translation()->set_x(pose.translation.x());
  result.mutable_translation()->set_y(pose.translation.y());
  result.mutable_translation()->set_z(pose.translation.z());
  return result;
}

GeoAnchor GeoAnchorFromProto(const map_format::GeoAnchor& anchor, std::string_view what) {
  GeoAnchor result;
  result.origin = {anchor.latitude_deg(), anchor.longitude_deg(), anchor.altitude_m()};
  if (anchor.has_enu_from_map()) {
    result.enu_from_map =
        RigidFromProtoExact(anchor.enu_from_map(), std::string(what) + ".enu_from_map");
  }
  result.source = anchor.source();
  result.horizontal_sigma_m = anchor.horizontal_sigma_m();
  result.vertical_sigma_m = anchor.vertical_sigma_m();
  try {
    result.Check();
  } catch (const InvalidArgumentError& error) {
    throw InvalidArgumentError(std::string(what) + ": " + error.what());
  }
  return result;
}

map_format::GeoAnchor GeoAnchorToProto(const GeoAnchor& anchor) {
  map_format::GeoAnchor result;
  result.set_latitude_deg(anchor.origin.latitude_deg);
  result.set_longitude_deg(anchor.origin.longitude_deg);
  result.set_altitude_m(anchor.origin.altitude_m);
  *result.mutable_enu_from_map() = RigidToProto(anchor.enu_from_map);
  result.set_source(anchor.source);
  result.set_horizontal_sigma_m(anchor.horizontal_sigma_m);
  result.set_vertical_sigma_m(anchor.vertical_sigma_m);
  return result;
}

}  // namespace evloc
