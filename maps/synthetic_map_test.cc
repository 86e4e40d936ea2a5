#include "maps/synthetic_map.h"

#include <gtest/gtest.h>

namespace evloc {
namespace {

TEST(CorridorMap, IsValidDeterministicAndListsWhatKeyframesSee) {
  CorridorMapOptions options;
  options.num_points = 5000;
  options.num_keyframes = 8;
  const Map map = MakeCorridorMap(options);
  EXPECT_NO_THROW(map.Check());
  EXPECT_EQ(map.size(), 5000u);
  ASSERT_EQ(map.keyframes.size(), 8u);
  EXPECT_EQ(ComputeMapContentChecksum(MakeCorridorMap(options)), ComputeMapContentChecksum(map));
  options.seed = 2;
  EXPECT_NE(ComputeMapContentChecksum(MakeCorridorMap(options)), ComputeMapContentChecksum(map));

  for (size_t k = 0; k < map.keyframes.size(); ++k) {
    const Keyframe& keyframe = map.keyframes[k];
    ASSERT_FALSE(keyframe.visible_points.empty()) << k;
    const Rigid3d world_from_cam = keyframe.cam_from_world.Inverse();
    for (const uint32_t point : keyframe.visible_points) {
      const Eigen::Vector3d in_cam = keyframe.cam_from_world * map.positions[point].cast<double>();
      ASSERT_GT(in_cam.z(), 0.0);
      ASSERT_LE(in_cam.z(), options.keyframe_visibility_depth_m);
      Eigen::Vector2d pixel;
      ASSERT_TRUE(options.camera.Project(in_cam, &pixel));
      ASSERT_TRUE(options.camera.IsInside(pixel));
    }
    EXPECT_NEAR(world_from_cam.translation.x(), (k + 0.5) * options.length_m / 8, 1e-12);
  }
  // Points lie on the faces and their gradients are tangent to them.
  for (size_t i = 0; i < map.size(); ++i) {
    const Eigen::Vector3f& p = map.positions[i];
    const bool on_wall = std::abs(std::abs(p.y()) - 1.0f) < 1e-6f;
    const bool on_floor_or_ceiling = std::abs(std::abs(p.z()) - 1.25f) < 1e-6f;
    ASSERT_TRUE(on_wall || on_floor_or_ceiling) << i;
    ASSERT_NEAR(on_wall ? map.gradients[i].y() : map.gradients[i].z(), 0.0f, 1e-6f) << i;
  }
  // Most points have a source keyframe (those in view of at least one).
  const MapInfo info = SummarizeMap(map);
  EXPECT_GT(info.num_points_with_source_keyframe, map.size() / 2);
}

}  // namespace
}  // namespace evloc
