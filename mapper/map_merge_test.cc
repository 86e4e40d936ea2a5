#include "mapper/map_merge.h"

#include <gtest/gtest.h>

#include <random>

#include "core/common/error.h"

namespace evloc::mapper {
namespace {

Map MapWithKeyframes(size_t count) {
  Map map;
  map.cameras.push_back(Camera::Pinhole(100, 100, 100.0, 100.0, 49.5, 49.5));
  for (size_t i = 0; i < count; ++i) {
    Keyframe keyframe;
    keyframe.image_name = "k" + std::to_string(i);
    map.keyframes.push_back(keyframe);
  }
  return map;
}

CandidatePoint Point(const Eigen::Vector3d& position, const Eigen::Vector3d& gradient,
                     uint32_t source, std::vector<uint32_t> observers, double sigma = 0.001) {
  CandidatePoint point;
  point.position = position;
  point.gradient = gradient.normalized();
  point.position_sigma = sigma;
  point.inverse_depth_sigma = sigma;
  point.pixel_footprint = 0.001;
  point.source_keyframe = source;
  point.observing_keyframes = std::move(observers);
  return point;
}

TEST(MapMerge, DuplicatesMergeAndVisibilityIsTheUnion) {
  Map map = MapWithKeyframes(3);
  MapMergeOptions options;
  options.voxel_size = 0.01;
  options.outlier_neighbours = 0;
  const std::vector<CandidatePoint> points = {
      Point({0.001, 0.001, 0.001}, {1, 0, 0}, 0, {1}, 0.001),
      Point({0.003, 0.001, 0.001}, {1, 0.1, 0}, 1, {0}, 0.002),
      // Same voxel, opposite gradient: a different edge.
      Point({0.002, 0.002, 0.002}, {-1, 0, 0}, 2, {}),
      // Another voxel.
      Point({0.5, 0.5, 0.5}, {0, 1, 0}, 2, {0})};
  const MergeStatistics statistics = MergePoints(points, options, &map);
  EXPECT_EQ(statistics.input_points, 4u);
  EXPECT_EQ(statistics.merged_points, 3u);
  ASSERT_EQ(map.size(), 3u);
  EXPECT_NO_THROW(map.Check());
  // Inverse-variance weighted position of the first two: weights 1e6 and 2.5e5.
  EXPECT_NEAR(map.positions[0].x(), (0.001 * 4 + 0.003) / 5, 1e-7);
  EXPECT_EQ(map.source_keyframe[0], 0u);
  EXPECT_EQ(map.keyframes[0].visible_points, (std::vector<uint32_t>{0, 2}));
  EXPECT_EQ(map.keyframes[1].visible_points, (std::vector<uint32_t>{0}));
  EXPECT_EQ(map.keyframes[2].visible_points, (std::vector<uint32_t>{1, 2}));
}

TEST(MapMerge, StatisticalOutlierIsRemoved) {
  Map map = MapWithKeyframes(1);
  std::mt19937 random(1);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::vector<CandidatePoint> points;
  for (int i = 0; i < 300; ++i) {
    points.push_back(Point({noise(random), noise(random), 1.0 + noise(random)}, {1, 0, 0}, 0, {}));
  }
  points.push_back(Point({0.5, 0.5, 1.5}, {1, 0, 0}, 0, {}));
  MapMergeOptions options;
  options.voxel_size = 1e-4;
  const MergeStatistics statistics = MergePoints(points, options, &map);
  EXPECT_EQ(statistics.merged_points, 301u);
  EXPECT_LT(statistics.output_points, 301u);
  EXPECT_GT(statistics.output_points, 270u);
  for (const Eigen::Vector3f& position : map.positions) {
    EXPECT_LT(position.x(), 0.2f);
  }
  EXPECT_NO_THROW(map.Check());
  EXPECT_EQ(map.keyframes[0].visible_points.size(), map.size());
}

TEST(MapMerge, AutomaticVoxelIsOnePixelAtTheMedianDepth) {
  Map map = MapWithKeyframes(1);
  std::vector<CandidatePoint> points = {Point({0, 0, 1}, {1, 0, 0}, 0, {}),
                                        Point({1, 0, 1}, {1, 0, 0}, 0, {}),
                                        Point({2, 0, 1}, {1, 0, 0}, 0, {})};
  points[0].pixel_footprint = 0.001;
  points[1].pixel_footprint = 0.002;
  points[2].pixel_footprint = 0.004;
  MapMergeOptions options;
  options.outlier_neighbours = 0;
  EXPECT_DOUBLE_EQ(MergePoints(points, options, &map).voxel_size, 0.002);
}

TEST(MapMerge, RejectsUnknownKeyframe) {
  Map map = MapWithKeyframes(1);
  EXPECT_THROW(MergePoints({Point({0, 0, 1}, {1, 0, 0}, 3, {})}, {}, &map), InvalidArgumentError);
  EXPECT_THROW(MergePoints({Point({0, 0, 1}, {1, 0, 0}, 0, {2})}, {}, &map), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::mapper
