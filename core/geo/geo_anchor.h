// Where a map is on the Earth (docs/geo.md): the GeoAnchor (the core mirror of the protobuf
// message evloc.GeoAnchor of proto/evloc/map.proto) and the geodetic pose of a camera whose pose
// is known in the map frame: latitude, longitude, altitude, heading and pitch.
#pragma once

#include <Eigen/Core>
#include <string>

#include "core/geo/geodetic.h"
#include "core/geometry/rigid3.h"

namespace evloc {

// The sources an anchor may come from (GeoAnchor::source).
inline constexpr const char* kGeoAnchorSourceGiven = "given";
inline constexpr const char* kGeoAnchorSourceSurvey = "survey";
inline constexpr const char* kGeoAnchorSourceExif = "exif";

// The geo-reference of a map: the WGS84 origin of a local East-North-Up frame and the map frame
// in that frame.
struct GeoAnchor {
  // WGS84 position of the ENU origin.
  GeodeticPoint origin;
  // The map frame in the ENU frame: p_enu = enu_from_map * p_map.
  Rigid3d enu_from_map;
  // Where the anchor came from: kGeoAnchorSourceGiven, kGeoAnchorSourceSurvey or
  // kGeoAnchorSourceExif.
  std::string source = kGeoAnchorSourceGiven;
  // One-sigma uncertainty of the anchor's horizontal position, metres; 0 when unknown.
  double horizontal_sigma_m = 0.0;
  // One-sigma uncertainty of the anchor's vertical position, metres; 0 when unknown.
  double vertical_sigma_m = 0.0;

  // Throws InvalidArgumentError naming the field unless the origin passes CheckGeodeticPoint,
  // enu_from_map is finite with a unit quaternion (within 1e-6) and a translation within
  // kMaxAnchorTranslationM, the source is one of the three, and the sigmas are finite and >= 0.
  void Check() const;
};

// Largest |enu_from_map.translation| an anchor may have, metres: a map frame farther than this
// from its ENU origin would lose float precision and the flat ENU frame its meaning.
inline constexpr double kMaxAnchorTranslationM = 100000.0;

// A camera pose in WGS84 terms.
struct GeoPose {
  // The camera centre in WGS84.
  GeodeticPoint position;
  // The camera centre in the anchor's ENU frame, metres.
  Eigen::Vector3d enu = Eigen::Vector3d::Zero();
  // Heading, degrees clockwise from true north in [0, 360): the direction of the camera's optical
  // axis (+z) projected on the horizontal plane at the camera's own position (east, north, up
  // there, not at the anchor). When the optical axis is within kVerticalAxisTolerance of the
  // vertical (looking straight down or up) its projection has no direction, and the heading is
  // that of the image's up direction (the camera's -y axis) instead: heading_from_image_up says so.
  double heading_deg = 0.0;
  // Elevation of the optical axis above the horizontal plane, degrees in [-90, 90] (-90: looking
  // straight down).
  double pitch_deg = 0.0;
  // True when heading_deg is the heading of the image's up direction (a vertical optical axis).
  bool heading_from_image_up = false;
};

// The horizontal length below which the optical axis counts as vertical in GeoPose (sine of the
// angle to the vertical: 1e-6 is 0.2 arc seconds).
inline constexpr double kVerticalAxisTolerance = 1e-6;

// Converts map-frame poses of one anchor to WGS84.
class GeoReference {
 public:
  // Checks `anchor` (GeoAnchor::Check).
  explicit GeoReference(const GeoAnchor& anchor);

  const GeoAnchor& anchor() const { return anchor_; }
  const EnuFrame& enu_frame() const { return frame_; }

  // The WGS84 point of a map-frame point.
  GeodeticPoint GeodeticFromMap(const Eigen::Vector3d& p_map) const;
  // The map-frame point of a WGS84 point.
  Eigen::Vector3d MapFromGeodetic(const GeodeticPoint& point) const;
  // The geodetic pose of a camera at map_from_cam.
  GeoPose PoseFromMap(const Rigid3d& map_from_cam) const;

 private:
  GeoAnchor anchor_;
  EnuFrame frame_;
};

// The heading of a horizontal direction (east, north), degrees clockwise from north in [0, 360).
double HeadingDegFromEastNorth(double east, double north);

}  // namespace evloc
