#include "core/geo/geo_anchor.h"

#include <gtest/gtest.h>
#include <GeographicLib/Geodesic.hpp>

#include <cmath>

#include "core/common/error.h"

namespace evloc {
namespace {

// enu_from_cam of a camera at `position` whose optical axis points along `forward` with the
// image's down direction `down` (both in ENU).
Rigid3d CameraLooking(const Eigen::Vector3d& forward, const Eigen::Vector3d& down,
                      const Eigen::Vector3d& position = Eigen::Vector3d::Zero()) {
  Eigen::Matrix3d rotation;
  rotation.col(2) = forward.normalized();
  rotation.col(1) = down.normalized();
  rotation.col(0) = rotation.col(1).cross(rotation.col(2));
  return Rigid3d(Eigen::Quaterniond(rotation), position);
}

GeoAnchor AnchorAt(double latitude, double longitude, double altitude) {
  GeoAnchor anchor;
  anchor.origin = {latitude, longitude, altitude};
  return anchor;
}

TEST(GeoAnchorTest, HeadingIsClockwiseFromNorthAndPitchIsTheElevation) {
  const GeoReference reference(AnchorAt(45.0, 7.0, 100.0));
  const Eigen::Vector3d up(0, 0, 1);
  struct Case {
    Eigen::Vector3d forward;
    double heading, pitch;
  };
  for (const Case& c :
       {Case{{0, 1, 0}, 0.0, 0.0}, Case{{1, 0, 0}, 90.0, 0.0}, Case{{0, -1, 0}, 180.0, 0.0},
        Case{{-1, 0, 0}, 270.0, 0.0}, Case{{1, 1, 0}, 45.0, 0.0},
        Case{{-1, 1, std::sqrt(2.0)}, 315.0, 45.0}, Case{{0, 1, -1}, 0.0, -45.0}}) {
    const Eigen::Vector3d forward = c.forward.normalized();
    const Eigen::Vector3d down = -(up - up.dot(forward) * forward);
    const GeoPose pose = reference.PoseFromMap(CameraLooking(forward, down));
    EXPECT_NEAR(pose.heading_deg, c.heading, 1e-9) << c.forward.transpose();
    EXPECT_NEAR(pose.pitch_deg, c.pitch, 1e-9) << c.forward.transpose();
    EXPECT_FALSE(pose.heading_from_image_up);
  }
}

TEST(GeoAnchorTest, LookingStraightDownTheHeadingIsThatOfTheImageUpDirection) {
  const GeoReference reference(AnchorAt(45.0, 7.0, 100.0));
  // Optical axis down; the image's down direction points west, so its up direction points east.
  const GeoPose pose = reference.PoseFromMap(CameraLooking({0, 0, -1}, {-1, 0, 0}));
  EXPECT_TRUE(pose.heading_from_image_up);
  EXPECT_NEAR(pose.heading_deg, 90.0, 1e-9);
  EXPECT_NEAR(pose.pitch_deg, -90.0, 1e-9);
}

TEST(GeoAnchorTest, TheMapFrameRotationTurnsTheHeading) {
  GeoAnchor anchor = AnchorAt(45.0, 7.0, 100.0);
  // The map frame turned 30 degrees counter-clockwise (seen from above) in ENU: map +y points
  // 30 degrees west of north, and the map origin sits 5 m east, 2 m up.
  anchor.enu_from_map =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 6, Eigen::Vector3d::UnitZ())),
              Eigen::Vector3d(5, 0, 2));
  const GeoReference reference(anchor);
  const GeoPose pose = reference.PoseFromMap(CameraLooking({0, 1, 0}, {0, 0, -1}));
  // 330 degrees at the origin; 5 m east the local north has turned by the meridians' convergence,
  // 5 m / (N cos 45) * sin 45 = 7.8e-7 rad = 4.5e-5 degrees.
  EXPECT_NEAR(pose.heading_deg, 330.0 + 4.48e-5, 1e-7);
  EXPECT_NEAR(pose.enu.x(), 5.0, 1e-12);
  EXPECT_NEAR(pose.enu.z(), 2.0, 1e-12);
  EXPECT_NEAR(pose.position.altitude_m, 102.0, 1e-5);
  const Eigen::Vector3d p_map(12.0, -4.0, 1.5);
  EXPECT_NEAR((reference.MapFromGeodetic(reference.GeodeticFromMap(p_map)) - p_map).norm(), 0.0,
              1e-8);
}

// Far from the origin the meridians converge: the heading is measured against the north at the
// camera, which an independent geodesic azimuth (GeographicLib::Geodesic) gives.
TEST(GeoAnchorTest, HeadingFarFromTheOriginUsesTheLocalNorth) {
  const GeoReference reference(AnchorAt(60.0, 10.0, 0.0));
  const Eigen::Vector3d position(10000.0, 3000.0, 0.0);
  const Eigen::Vector3d forward(0.2, 1.0, 0.0);
  const GeoPose pose = reference.PoseFromMap(CameraLooking(forward, {0, 0, -1}, position));
  const GeodeticPoint ahead =
      reference.enu_frame().ToGeodetic(position + 0.01 * forward.normalized());
  double distance = 0, azimuth_start = 0, azimuth_end = 0;
  GeographicLib::Geodesic::WGS84().Inverse(pose.position.latitude_deg, pose.position.longitude_deg,
                                           ahead.latitude_deg, ahead.longitude_deg, distance,
                                           azimuth_start, azimuth_end);
  EXPECT_NEAR(pose.heading_deg, azimuth_start, 1e-4);
  // And it differs from the heading at the origin by the convergence (about 0.16 degrees here).
  const double heading_at_origin = HeadingDegFromEastNorth(forward.x(), forward.y());
  EXPECT_GT(std::abs(pose.heading_deg - heading_at_origin), 0.1);
}

TEST(GeoAnchorTest, CheckRefusesBadAnchorsNamingTheField) {
  GeoAnchor anchor = AnchorAt(45.0, 7.0, 100.0);
  EXPECT_NO_THROW(anchor.Check());
  GeoAnchor bad = anchor;
  bad.source = "guess";
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
  bad = anchor;
  bad.horizontal_sigma_m = -1.0;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
  bad = anchor;
  bad.enu_from_map.translation.x() = NAN;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
  bad = anchor;
  bad.enu_from_map.translation.x() = 2e5;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
  bad = anchor;
  bad.origin.latitude_deg = 95.0;
  EXPECT_THROW(GeoReference{bad}, InvalidArgumentError);
}

}  // namespace
}  // namespace evloc
