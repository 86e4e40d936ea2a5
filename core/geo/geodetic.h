// WGS84 geodetic coordinates, Earth-centred Earth-fixed (ECEF) and local East-North-Up (ENU)
// frames, on GeographicLib (docs/geo.md). Degrees appear only here, at the geodetic boundary:
// latitude and longitude are what every GNSS receiver, EXIF tag and map shows.
#pragma once

#include <Eigen/Core>
#include <string>

namespace evloc {

// A WGS84 position: latitude and longitude in degrees, height above the ellipsoid in metres (not
// above mean sea level: a GNSS receiver's "altitude MSL" differs by the geoid undulation).
struct GeodeticPoint {
  // Latitude, degrees, in [-90, 90], positive north.
  double latitude_deg = 0.0;
  // Longitude, degrees, in [-180, 180], positive east.
  double longitude_deg = 0.0;
  // Height above the WGS84 ellipsoid, metres.
  double altitude_m = 0.0;
};

// Heights evloc accepts, metres above the ellipsoid: from the Dead Sea shore and the geoid's
// lowest point (about -430 m with its -106 m undulation) to aircraft altitudes.
inline constexpr double kMinAltitudeM = -11000.0;
inline constexpr double kMaxAltitudeM = 100000.0;

// Throws InvalidArgumentError naming `what` unless the point is finite, the latitude in
// [-90, 90], the longitude in [-180, 180] and the altitude in [kMinAltitudeM, kMaxAltitudeM].
void CheckGeodeticPoint(const GeodeticPoint& point, const std::string& what);

// The longitude wrapped into [-180, 180) degrees.
double WrapLongitudeDeg(double longitude_deg);

// ECEF coordinates of a WGS84 point, metres (GeographicLib::Geocentric::WGS84()).
Eigen::Vector3d EcefFromGeodetic(const GeodeticPoint& point);
// The WGS84 point of ECEF coordinates (longitude in [-180, 180]).
GeodeticPoint GeodeticFromEcef(const Eigen::Vector3d& ecef);

// The rotation ecef_from_enu of the local ENU frame at `point`: its columns are the east, north
// and up unit vectors in ECEF.
Eigen::Matrix3d EcefFromEnuRotation(const GeodeticPoint& point);

// Distance between two WGS84 points, metres: the geodesic on the ellipsoid between their
// horizontal positions (GeographicLib::Geodesic) and the difference of their altitudes.
struct GeodeticDistance {
  // Length of the geodesic between the two latitude/longitude positions, metres.
  double horizontal_m = 0.0;
  // b.altitude_m - a.altitude_m, metres.
  double vertical_m = 0.0;
};
GeodeticDistance DistanceBetween(const GeodeticPoint& a, const GeodeticPoint& b);

// A local East-North-Up frame: origin at a WGS84 point, x east, y north, z up along the
// ellipsoid normal (GeographicLib::LocalCartesian).
class EnuFrame {
 public:
  // Throws InvalidArgumentError when `origin` fails CheckGeodeticPoint.
  explicit EnuFrame(const GeodeticPoint& origin);

  // The origin.
  const GeodeticPoint& origin() const { return origin_; }
  // ENU coordinates of a WGS84 point, metres.
  Eigen::Vector3d FromGeodetic(const GeodeticPoint& point) const;
  // The WGS84 point of ENU coordinates.
  GeodeticPoint ToGeodetic(const Eigen::Vector3d& enu) const;
  // The rotation origin_enu_from_local_enu between this frame's axes and the ENU axes at the
  // point `enu` (east, north, up there): directions at a distance from the origin turn with the
  // meridians and the normal.
  Eigen::Matrix3d OriginFromLocalRotation(const Eigen::Vector3d& enu) const;

 private:
  GeodeticPoint origin_;
  Eigen::Vector3d origin_ecef_;
  Eigen::Matrix3d ecef_from_enu_;
};

}  // namespace evloc
