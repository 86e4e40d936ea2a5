// Conversions between the map-format protobuf messages shared by the map file and the service API
// (evloc/map.proto: Camera, Rigid3) and the core types (Camera, Rigid3d), with the one set of
// checks every reader applies: the map reader (maps/map_io.cc), the service (SessionStart, pose
// hints) and its clients (PoseUpdates).
#pragma once

#include <string_view>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "evloc/map.pb.h"

namespace evloc {

// Largest |norm - 1| of a protobuf quaternion that the readers accept.
inline constexpr double kProtoQuaternionNormTolerance = 1e-3;

// Converts a protobuf camera. The model must be set (PINHOLE, RADIAL_TANGENTIAL or EQUIDISTANT),
// width and height must be 1..65535; a RADIAL_TANGENTIAL camera with 4 coefficients (k1 k2 p1 p2,
// as many calibration tools write them) gets k3 = 0; the result must pass Camera::Check().
// Throws InvalidArgumentError whose message starts with `what` (e.g. "SessionStart.camera").
Camera CameraFromProto(const map_format::Camera& camera, std::string_view what);
// Converts a camera to protobuf (every field, the distortion as stored).
map_format::Camera CameraToProto(const Camera& camera);

// Converts a protobuf pose: every value must be finite and the quaternion's norm within
// kProtoQuaternionNormTolerance of 1; the rotation is normalised. Throws InvalidArgumentError
// whose message starts with `what`.
Rigid3d RigidFromProto(const map_format::Rigid3& pose, std::string_view what);
// Converts a protobuf pose with the checks of RigidFromProto but keeps the stored values bit for
// bit (not normalised), for stored poses that must round-trip exactly (map keyframes, which the
// map's content checksum covers).
Rigid3d RigidFromProtoExact(const map_format::Rigid3& pose, std::string_view what);
// Converts a pose to protobuf (bit for bit).
map_format::Rigid3 RigidToProto(const Rigid3d& pose);

}  // namespace evloc
