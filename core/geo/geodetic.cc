#include "core/geo/geodetic.h"

#include <GeographicLib/Geocentric.hpp>
#include <GeographicLib/Geodesic.hpp>
#include <cmath>
#include <sstream>

#include "core/common/error.h"

namespace evloc {
namespace {

const GeographicLib::Geocentric& Wgs84() { return GeographicLib::Geocentric::WGS84(); }

}  // namespace

void CheckGeodeticPoint(const GeodeticPoint& point, const std::string& what) {
  std::ostringstream problem;
  problem.precision(17);
  if (!std::isfinite(point.latitude_deg) || point.latitude_deg < -90.0 ||
      point.latitude_deg > 90.0) {
    problem << "latitude " << point.latitude_deg << " is outside [-90, 90] degrees";
  } else if (!std::isfinite(point.longitude_deg) || point.longitude_deg < -180.0 ||
             point.longitude_deg > 180.0) {
    problem << "longitude " << point.longitude_deg << " is outside [-180, 180] degrees";
  } else if (!std::isfinite(point.altitude_m) || point.altitude_m < kMinAltitudeM ||
             point.altitude_m > kMaxAltitudeM) {
    problem << "altitude " << point.altitude_m << " m is outside [" << kMinAltitudeM << ", "
            << kMaxAltitudeM << "] m above the WGS84 ellipsoid";
  } else {
    return;
  }
  throw InvalidArgumentError(what + ": " + problem.str());
}

double WrapLongitudeDeg(double longitude_deg) {
  double wrapped = std::fmod(longitude_deg + 180.0, 360.0);
  if (wrapped < 0.0) wrapped += 360.0;
  return wrapped - 180.0;
}

Eigen::Vector3d EcefFromGeodetic(const GeodeticPoint& point) {
  Eigen::Vector3d ecef;
  Wgs84().Forward(point.latitude_deg, point.longitude_deg, point.altitude_m, ecef.x(), ecef.y(),
                  ecef.z());
  return ecef;
}

GeodeticPoint GeodeticFromEcef(const Eigen::Vector3d& ecef) {
  GeodeticPoint point;
  Wgs84().Reverse(ecef.x(), ecef.y(), ecef.z(), point.latitude_deg, point.longitude_deg,
                  point.altitude_m);
  return point;
}

Eigen::Matrix3d EcefFromEnuRotation(const GeodeticPoint& point) {
  std::vector<double> row_major(9);
  double x = 0.0, y = 0.0, z = 0.0;
  Wgs84().Forward(point.latitude_deg, point.longitude_deg, point.altitude_m, x, y, z, row_major);
  Eigen::Matrix3d rotation;
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col) rotation(row, col) = row_major[3 * row + col];
  }
  return rotation;
}

GeodeticDistance DistanceBetween(const GeodeticPoint& a, const GeodeticPoint& b) {
  GeodeticDistance distance;
  GeographicLib::Geodesic::WGS84().Inverse(a.latitude_deg, a.longitude_deg, b.latitude_deg,
                                           b.longitude_deg, distance.horizontal_m);
  distance.vertical_m = b.altitude_m - a.altitude_m;
  return distance;
}

EnuFrame::EnuFrame(const GeodeticPoint& origin) : origin_(origin) {
  CheckGeodeticPoint(origin, "ENU frame origin");
  origin_ecef_ = EcefFromGeodetic(origin);
  ecef_from_enu_ = EcefFromEnuRotation(origin);
}

Eigen::Vector3d EnuFrame::FromGeodetic(const GeodeticPoint& point) const {
  return ecef_from_enu_.transpose() * (EcefFromGeodetic(point) - origin_ecef_);
}

GeodeticPoint EnuFrame::ToGeodetic(const Eigen::Vector3d& enu) const {
  return GeodeticFromEcef(origin_ecef_ + ecef_from_enu_ * enu);
}

Eigen::Matrix3d EnuFrame::OriginFromLocalRotation(const Eigen::Vector3d& enu) const {
  return ecef_from_enu_.transpose() * EcefFromEnuRotation(ToGeodetic(enu));
}

}  // namespace evloc
