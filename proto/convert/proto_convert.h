// Conversions between the map-format protobuf messages shared by the map file and the service API
// (evloc/map.proto: Camera, Rigid3, GeoAnchor) and the core types (Camera, Rigid3d, GeoAnchor),
// with the one set of checks every reader applies: the map reader (maps/map_io.cc), the service
// (SessionStart, pose hints) and its clients (PoseUpdates).
#pragma once

#include <string_view>

#include "core/camera/camera.h"
#include "core/geo/geo_anchor.h"
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

// Converts a protobuf geo anchor: an absent enu_from_map is the identity; enu_from_map is kept
// bit for bit (RigidFromProtoExact: the map's content checksum covers it) and the result must pass
// GeoAnchor::Check(). Throws InvalidArgumentError whose message starts with `what`.
GeoAnchor GeoAnchorFromProto(const map_format::GeoAnchor& anchor, std::string_view what);
// Converts a geo anchor to protobuf (every field, enu_from_map bit for bit).
map_format::GeoAnchor GeoAnchorToProto(const GeoAnchor& anchor);

}  // namespace evloc
