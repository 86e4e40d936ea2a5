#include "core/geo/geo_anchor.h"

#include <cmath>
#include <numbers>

#include "core/common/error.h"

namespace evloc {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

}  // namespace

void GeoAnchor::Check() const {
  CheckGeodeticPoint(origin, "geo anchor origin");
  if (!enu_from_map.IsFinite()) {
    throw InvalidArgumentError("geo anchor: enu_from_map is not finite");
  }
  if (std::abs(enu_from_map.rotation.norm() - 1.0) > 1e-6) {
    throw InvalidArgumentError("geo anchor: the quaternion of enu_from_map is not of unit norm");
  }
  if (enu_from_map.translation.norm() > kMaxAnchorTranslationM) {
    throw InvalidArgumentError(
        "geo anchor: enu_from_map moves the map " +
        std::to_string(enu_from_map.translation.norm()) + " m from the ENU origin (at most " +
        std::to_string(kMaxAnchorTranslationM) + " m); put the origin near the map");
  }
  if (source != kGeoAnchorSourceGiven && source != kGeoAnchorSourceSurvey &&
      source != kGeoAnchorSourceExif) {
    throw InvalidArgumentError("geo anchor: source '" + source +
                               "' is not one of given, survey, exif");
  }
  for (const auto& [name, value] : {std::pair{"horizontal_sigma_m", horizontal_sigma_m},
                                    {"vertical_sigma_m", vertical_sigma_m}}) {
    if (!std::isfinite(value) || value < 0.0) {
      throw InvalidArgumentError(std::string("geo anchor: ") + name + " " + std::to_string(value) +
                                 " is not a finite value >= 0");
    }
  }
}

double HeadingDegFromEastNorth(double east, double north) {
  double heading = std::atan2(east, north) * kDegPerRad;
  if (heading < 0.0) heading += 360.0;
  if (heading >= 360.0) heading -= 360.0;
  return heading;
}

GeoReference::GeoReference(const GeoAnchor& anchor)
    : anchor_((anchor.Check(), anchor)), frame_(anchor.origin) {}

GeodeticPoint GeoReference::GeodeticFromMap(const Eigen::Vector3d& p_map) const {
  return frame_.ToGeodetic(anchor_.enu_from_map * p_map);
}

Eigen::Vector3d GeoReference::MapFromGeodetic(const GeodeticPoint& point) const {
  return anchor_.enu_from_map.Inverse() * frame_.FromGeodetic(point);
}

GeoPose GeoReference::PoseFromMap(const Rigid3d& map_from_cam) const {
  GeoPose pose;
  const Rigid3d enu_from_cam = anchor_.enu_from_map * map_from_cam;
  pose.enu = enu_from_cam.translation;
  pose.position = frame_.ToGeodetic(pose.enu);
  // The camera's axes in the ENU frame at its own position.
  const Eigen::Matrix3d local_from_cam =
      frame_.OriginFromLocalRotation(pose.enu).transpose() * enu_from_cam.RotationMatrix();
  const Eigen::Vector3d optical_axis = local_from_cam.col(2);
  const double horizontal = optical_axis.head<2>().norm();
  pose.pitch_deg = std::atan2(optical_axis.z(), horizontal) * kDegPerRad;
  if (horizontal > kVerticalAxisTolerance) {
    pose.heading_deg = HeadingDegFromEastNorth(optical_axis.x(), optical_axis.y());
  } else {
    const Eigen::Vector3d image_up = -local_from_cam.col(1);
    pose.heading_deg = HeadingDegFromEastNorth(image_up.x(), image_up.y());
    pose.heading_from_image_up = true;
  }
  return pose;
}

}  // namespace evloc
