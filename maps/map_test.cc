#include "maps/map.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "core/common/error.h"

namespace evloc {
namespace {

// A small valid map: 4 points, 2 keyframes, 1 camera.
Map MakeSmallMap() {
  Map map;
  map.AddPoint({0, 0, 1}, {1, 0, 0}, 0.1f, 0.5f, 0);
  map.AddPoint({1, 0, 2}, {0, 1, 0}, 0.2f, 0.0f, 1);
  map.AddPoint({0, 1, 3}, {0, 0, 1}, 0.0f, 0.3f, kNoKeyframe);
  map.AddPoint({-1, -2, 4}, Eigen::Vector3f(1, 1, 0).normalized(), 0.0f, 0.0f, 0);
  map.cameras.push_back(Camera::Pinhole(640, 480, 500, 500, 320, 240));
  Keyframe first;
  first.t_ns = 1000;
  first.visible_points = {0, 1, 3};
  Keyframe second;
  second.t_ns = 5000;
  second.cam_from_world =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY())),
              Eigen::Vector3d(0.1, 0.2, 0.3));
  second.visible_points = {1, 2};
  map.keyframes = {first, second};
  return map;
}

// Expects map.Check() to throw InvalidArgumentError whose message contains `fragment`.
void ExpectCheckFails(const Map& map, const std::string& fragment) {
  try {
    map.Check();
    ADD_FAILURE() << "Check() accepted a map that should fail with '" << fragment << "'";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos)
        << "message: " << error.what() << "\nexpected to contain: " << fragment;
  }
}

TEST(Map, CheckAcceptsAValidMap) {
  const Map map = MakeSmallMap();
  EXPECT_EQ(map.size(), 4u);
  EXPECT_NO_THROW(map.Check());
  EXPECT_NO_THROW(Map().Check());
}

TEST(Map, CheckNamesTheFirstBadElement) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  Map map = MakeSmallMap();
  map.gradients.pop_back();
  ExpectCheckFails(map, "4 positions but 3 gradients");

  map = MakeSmallMap();
  map.source_keyframe.push_back(0);
  ExpectCheckFails(map, "5 source keyframes");

  map = MakeSmallMap();
  map.positions[2].y() = nan;
  ExpectCheckFails(map, "map point 2 has a non-finite position");

  map = MakeSmallMap();
  map.gradients[1] = {0, 2, 0};
  ExpectCheckFails(map, "map point 1 has gradient");

  map = MakeSmallMap();
  map.gradients[3] = {0, 0, 0};
  ExpectCheckFails(map, "map point 3 has gradient");

  map = MakeSmallMap();
  map.gradients[0] = {1.0005f, 0, 0};  // within the tolerance
  EXPECT_NO_THROW(map.Check());

  map = MakeSmallMap();
  map.inverse_depth_sigma[3] = -0.1f;
  ExpectCheckFails(map, "map point 3 has inverse-depth sigma");

  map = MakeSmallMap();
  map.gradient_magnitude[0] = std::numeric_limits<float>::infinity();
  ExpectCheckFails(map, "map point 0 has gradient magnitude");

  map = MakeSmallMap();
  map.source_keyframe[2] = 2;
  ExpectCheckFails(map, "map point 2 has source keyframe 2 but the map has 2 keyframes");

  map = MakeSmallMap();
  map.keyframes[1].camera_index = 1;
  ExpectCheckFails(map, "map keyframe 1 uses camera 1 but the map has 1 cameras");

  map = MakeSmallMap();
  map.keyframes[0].visible_points.push_back(4);
  ExpectCheckFails(map, "map keyframe 0 lists visible point 4 (entry 3)");

  map = MakeSmallMap();
  map.keyframes[0].visible_points = {0, 3, 1};
  ExpectCheckFails(map, "map keyframe 0 visible points are not strictly increasing at entry 2");

  map = MakeSmallMap();
  map.keyframes[1].visible_points = {1, 1};
  ExpectCheckFails(map, "not strictly increasing at entry 1");

  map = MakeSmallMap();
  map.keyframes[0].cam_from_world.translation.x() = std::numeric_limits<double>::infinity();
  ExpectCheckFails(map, "map keyframe 0 has a non-finite pose");

  map = MakeSmallMap();
  map.keyframes[1].cam_from_world.rotation.coeffs() *= 2.0;
  ExpectCheckFails(map, "map keyframe 1 has a rotation quaternion of norm 2");

  map = MakeSmallMap();
  map.cameras[0].fx = -1;
  ExpectCheckFails(map, "map camera 0: ");
}

TEST(Map, ContentChecksumFollowsContentNotProvenance) {
  const Map map = MakeSmallMap();
  const uint32_t checksum = ComputeMapContentChecksum(map);
  Map other = map;
  other.provenance.tool = "another tool";
  other.provenance.created_utc = "2030-01-01T00:00:00Z";
  EXPECT_EQ(ComputeMapContentChecksum(other), checksum);

  other = map;
  other.positions[3].z() = std::nextafter(other.positions[3].z(), 10.0f);
  EXPECT_NE(ComputeMapContentChecksum(other), checksum);
  other = map;
  other.keyframes[1].visible_points = {1};
  EXPECT_NE(ComputeMapContentChecksum(other), checksum);
  other = map;
  other.keyframes[0].image_name = "a.png";
  EXPECT_NE(ComputeMapContentChecksum(other), checksum);
  other = map;
  other.cameras[0].cy += 1e-9;
  EXPECT_NE(ComputeMapContentChecksum(other), checksum);
}

TEST(Map, SummaryCountsAndBounds) {
  Map map = MakeSmallMap();
  map.provenance.tool = "test";
  const MapInfo info = SummarizeMap(map);
  EXPECT_EQ(info.num_points, 4u);
  EXPECT_EQ(info.num_keyframes, 2u);
  EXPECT_EQ(info.num_cameras, 1u);
  EXPECT_EQ(info.num_visibility_entries, 5u);
  EXPECT_EQ(info.num_points_with_inverse_depth_sigma, 2u);
  EXPECT_EQ(info.num_points_with_gradient_magnitude, 2u);
  EXPECT_EQ(info.num_points_with_source_keyframe, 3u);
  EXPECT_FLOAT_EQ(info.median_inverse_depth_sigma, 0.2f);
  EXPECT_EQ(info.bounding_box_min, Eigen::Vector3f(-1, -2, 1));
  EXPECT_EQ(info.bounding_box_max, Eigen::Vector3f(1, 1, 4));
  EXPECT_EQ(info.Extent(), Eigen::Vector3f(2, 3, 3));
  EXPECT_EQ(info.first_keyframe_t_ns, 1000);
  EXPECT_EQ(info.last_keyframe_t_ns, 5000);
  EXPECT_EQ(info.content_crc32c, ComputeMapContentChecksum(map));
  ASSERT_EQ(info.camera_descriptions.size(), 1u);
  EXPECT_EQ(info.camera_descriptions[0], "pinhole 640x480 fx=500 fy=500 cx=320 cy=240");
  const std::string text = FormatMapInfo(info);
  EXPECT_NE(text.find("points:           4"), std::string::npos) << text;
  EXPECT_NE(text.find("keyframes:        2"), std::string::npos) << text;
  EXPECT_NE(text.find("tool:         test"), std::string::npos) << text;
}

}  // namespace
}  // namespace evloc
