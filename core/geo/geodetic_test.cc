#include "core/geo/geodetic.h"

#include <gtest/gtest.h>
#include <GeographicLib/LocalCartesian.hpp>

#include <cmath>

#include "core/common/error.h"

namespace evloc {
namespace {

// The examples of GeographicLib's CartConvert(1) manual page (man/CartConvert.pod), printed there
// to 2 decimals (the reverse example's height too, its latitude to 3 decimals).
TEST(GeodeticTest, EcefMatchesTheCartConvertManualExample) {
  const Eigen::Vector3d ecef = EcefFromGeodetic({33.3, 44.4, 6000.0});
  EXPECT_NEAR(ecef.x(), 3816209.60, 0.005);
  EXPECT_NEAR(ecef.y(), 3737108.55, 0.005);
  EXPECT_NEAR(ecef.z(), 3485109.57, 0.005);
}

TEST(GeodeticTest, EnuMatchesTheCartConvertManualLocalExample) {
  const EnuFrame frame({33.0, 44.0, 20.0});
  const Eigen::Vector3d enu = frame.FromGeodetic({33.3, 44.4, 6000.0});
  EXPECT_NEAR(enu.x(), 37288.97, 0.005);
  EXPECT_NEAR(enu.y(), 33374.29, 0.005);
  // The manual prints 5783.64 where GeographicLib 2.1.2's own LocalCartesian gives 5783.6466
  // (truncated there, not rounded): 1 cm here, and 1 um against LocalCartesian below.
  EXPECT_NEAR(enu.z(), 5783.64, 0.01);
  // And back.
  const GeodeticPoint back = frame.ToGeodetic(enu);
  EXPECT_NEAR(back.latitude_deg, 33.3, 1e-11);
  EXPECT_NEAR(back.longitude_deg, 44.4, 1e-11);
  EXPECT_NEAR(back.altitude_m, 6000.0, 1e-6);
}

TEST(GeodeticTest, ReverseMatchesTheCartConvertManualExample) {
  // echo 30000 30000 0 | CartConvert -r  =>  6.483 45 -6335709.73
  const GeodeticPoint point = GeodeticFromEcef({30000.0, 30000.0, 0.0});
  EXPECT_NEAR(point.latitude_deg, 6.483, 0.0005);
  EXPECT_NEAR(point.longitude_deg, 45.0, 1e-12);
  EXPECT_NEAR(point.altitude_m, -6335709.73, 0.005);
}

TEST(GeodeticTest, EnuFrameAgreesWithLocalCartesian) {
  const GeographicLib::LocalCartesian reference(48.85, 2.35, 35.0);
  const EnuFrame frame({48.85, 2.35, 35.0});
  for (const GeodeticPoint& point :
       {GeodeticPoint{48.86, 2.36, 40.0}, GeodeticPoint{48.0, 3.0, -20.0},
        GeodeticPoint{50.9, 1.8, 0.0}}) {
    double x = 0, y = 0, z = 0;
    reference.Forward(point.latitude_deg, point.longitude_deg, point.altitude_m, x, y, z);
    const Eigen::Vector3d enu = frame.FromGeodetic(point);
    EXPECT_NEAR(enu.x(), x, 1e-6);
    EXPECT_NEAR(enu.y(), y, 1e-6);
    EXPECT_NEAR(enu.z(), z, 1e-6);
  }
}

// Independent checks: a meridian degree is 111,132.95 m at 45 degrees (WGS84 meridian radius of
// curvature M = a(1-e^2)/(1-e^2 sin^2)^1.5), so 1 km north is 1000/M radians of latitude.
TEST(GeodeticTest, OneKilometreNorthMovesTheLatitudeByTheMeridianArc) {
  const double a = 6378137.0, f = 1 / 298.257223563, e2 = f * (2 - f);
  const double latitude = 45.0 * M_PI / 180.0;
  const double meridian_radius =
      a * (1 - e2) / std::pow(1 - e2 * std::sin(latitude) * std::sin(latitude), 1.5);
  const EnuFrame frame({45.0, 7.0, 0.0});
  const GeodeticPoint north = frame.ToGeodetic({0.0, 1000.0, 0.0});
  EXPECT_NEAR(north.latitude_deg - 45.0, 1000.0 / meridian_radius * 180.0 / M_PI, 1e-8);
  EXPECT_NEAR(north.longitude_deg, 7.0, 1e-12);
  // A flat 1 km leaves the curved Earth: the height grows by about d^2 / 2R (7.8 cm).
  EXPECT_NEAR(north.altitude_m, 1000.0 * 1000.0 / (2 * meridian_radius), 0.002);
  const GeodeticDistance distance = DistanceBetween(frame.origin(), north);
  EXPECT_NEAR(distance.horizontal_m, 1000.0, 0.001);
}

TEST(GeodeticTest, AltitudeIsAlongTheNormal) {
  const EnuFrame frame({-33.9, 151.2, 10.0});
  const GeodeticPoint up = frame.ToGeodetic({0.0, 0.0, 123.5});
  EXPECT_NEAR(up.latitude_deg, -33.9, 1e-12);
  EXPECT_NEAR(up.longitude_deg, 151.2, 1e-12);
  EXPECT_NEAR(up.altitude_m, 133.5, 1e-8);
}

TEST(GeodeticTest, AcrossTheAntimeridianTheLongitudeWraps) {
  const EnuFrame frame({-16.5, 179.9995, 0.0});
  // 100 m east at 16.5 S is 0.00094 degrees of longitude: over the antimeridian.
  const GeodeticPoint east = frame.ToGeodetic({100.0, 0.0, 0.0});
  EXPECT_LT(east.longitude_deg, -179.999);
  EXPECT_GE(east.longitude_deg, -180.0);
  const Eigen::Vector3d back = frame.FromGeodetic(east);
  EXPECT_NEAR(back.x(), 100.0, 1e-6);
  EXPECT_NEAR(back.y(), 0.0, 1e-6);
  EXPECT_NEAR(DistanceBetween(frame.origin(), east).horizontal_m, 100.0, 0.01);
  EXPECT_DOUBLE_EQ(WrapLongitudeDeg(180.5), -179.5);
  EXPECT_DOUBLE_EQ(WrapLongitudeDeg(-180.0), -180.0);
  EXPECT_DOUBLE_EQ(WrapLongitudeDeg(540.0), -180.0);
}

TEST(GeodeticTest, AtThePolesTheFrameIsDefined) {
  for (const double pole : {90.0, -90.0}) {
    const EnuFrame frame({pole, 0.0, 0.0});
    const Eigen::Vector3d ecef = EcefFromGeodetic(frame.origin());
    EXPECT_NEAR(ecef.head<2>().norm(), 0.0, 1e-6);
    EXPECT_NEAR(std::abs(ecef.z()), 6356752.314245, 1e-5);  // the WGS84 polar radius b
    // 10 m "north" of the pole is 10 m away on the other side; the round trip holds.
    const Eigen::Vector3d offset(3.0, 10.0, 2.0);
    const Eigen::Vector3d back = frame.FromGeodetic(frame.ToGeodetic(offset));
    EXPECT_NEAR((back - offset).norm(), 0.0, 1e-6);
    const GeodeticPoint moved = frame.ToGeodetic(offset);
    EXPECT_NEAR(DistanceBetween(frame.origin(), moved).horizontal_m, std::hypot(3.0, 10.0), 1e-3);
    EXPECT_NEAR(moved.altitude_m, 2.0, 1e-3);
  }
}

TEST(GeodeticTest, EnuAxesAreEastNorthUpInEcef) {
  const Eigen::Matrix3d ecef_from_enu = EcefFromEnuRotation({0.0, 90.0, 0.0});
  // At latitude 0, longitude 90: east is -X, north is +Z, up is +Y.
  EXPECT_NEAR((ecef_from_enu.col(0) - Eigen::Vector3d(-1, 0, 0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((ecef_from_enu.col(1) - Eigen::Vector3d(0, 0, 1)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((ecef_from_enu.col(2) - Eigen::Vector3d(0, 1, 0)).norm(), 0.0, 1e-12);
}

TEST(GeodeticTest, OutOfRangeValuesAreRefusedWithTheField) {
  EXPECT_NO_THROW(CheckGeodeticPoint({90.0, -180.0, 0.0}, "p"));
  const auto message = [](const GeodeticPoint& point) {
    try {
      CheckGeodeticPoint(point, "fix");
    } catch (const InvalidArgumentError& error) {
      return std::string(error.what());
    }
    return std::string();
  };
  EXPECT_NE(message({90.5, 0.0, 0.0}).find("fix: latitude 90.5"), std::string::npos);
  EXPECT_NE(message({0.0, 180.25, 0.0}).find("longitude"), std::string::npos);
  EXPECT_NE(message({0.0, 0.0, NAN}).find("altitude"), std::string::npos);
  EXPECT_NE(message({0.0, 0.0, 1e6}).find("altitude"), std::string::npos);
  EXPECT_NE(message({INFINITY, 0.0, 0.0}).find("latitude"), std::string::npos);
  EXPECT_THROW(EnuFrame({-91.0, 0.0, 0.0}), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc
