#include "localizer/odometry/oriented_edges.h"

#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"

namespace evloc::odometry {
namespace {

TEST(OrientationBin, SplitsTheCircleFromPlusXTowardsImageDown) {
  EXPECT_EQ(OrientationBin({1, 0}, 8), 0);
  EXPECT_EQ(OrientationBin({1, 1e-9}, 8), 0);
  EXPECT_EQ(OrientationBin({1, -1e-9}, 8), 7);
  EXPECT_EQ(OrientationBin({0, 1}, 8), 2);  // +y is image down
  EXPECT_EQ(OrientationBin({-1, 0}, 8), 4);
  EXPECT_EQ(OrientationBin({0, -1}, 8), 6);
  EXPECT_EQ(OrientationBin({std::cos(0.3), std::sin(0.3)}, 4), 0);
  EXPECT_EQ(OrientationBin({std::cos(1.7), std::sin(1.7)}, 4), 1);
}

// A dark image with one bright vertical bar, 6 px wide: its left edge has a gradient along +x
// (bin 0), its right edge along -x (bin 4).
cv::Mat BarImage(int width, int height, int bar_left, int bar_right) {
  cv::Mat image(height, width, CV_8UC1, cv::Scalar(20));
  image.colRange(bar_left, bar_right + 1).setTo(220);
  return image;
}

TEST(OrientedEdgeFields, ABarsTwoSidesFallIntoOppositeBinsAndNeverAttractEachOther) {
  const int width = 64;
  const int height = 48;
  const UndistortionTable table(Camera::Pinhole(width, height, 60, 60, 31.5, 23.5));
  OrientedEdgeOptions options;
  const std::vector<EdgePixel> edges =
      DetectOrientedEdges(BarImage(width, height, 30, 35), table, options);
  ASSERT_FALSE(edges.empty());
  int left = 0;
  int right = 0;
  for (const EdgePixel& edge : edges) {
    if (edge.sensor_pixel.y() < 2 || edge.sensor_pixel.y() > height - 3) continue;
    // Canny puts the edge on one of the two pixels across the step.
    if (edge.sensor_pixel.x() <= 30) {
      EXPECT_GE(edge.sensor_pixel.x(), 29);
      EXPECT_EQ(edge.bin, 0);
      EXPECT_NEAR(edge.gradient_direction.x(), 1.0, 1e-9);
      ++left;
    } else {
      EXPECT_GE(edge.sensor_pixel.x(), 35);
      EXPECT_LE(edge.sensor_pixel.x(), 36);
      EXPECT_EQ(edge.bin, 4);
      EXPECT_NEAR(edge.gradient_direction.x(), -1.0, 1e-9);
      ++right;
    }
  }
  EXPECT_GE(left, height - 4);
  EXPECT_GE(right, height - 4);

  const OrientedEdgeFields fields(edges, width, height, options);
  ASSERT_EQ(fields.bins(), 8);
  // From x = 40 (right of the bar): bin 0 (and its neighbours 7, 1) sees only the left edge,
  // about 10 px away; bin 4 sees the right edge about 4.5 px away.
  const int y = 24;
  const int from_bin0 = fields.NearestEdge(0, 40, y);
  ASSERT_GE(from_bin0, 0);
  EXPECT_LE(fields.edges()[from_bin0].sensor_pixel.x(), 30);
  // The sub-pixel edge lies half way across the step (29.5); the distance field measures from
  // the pixel it rounds to.
  EXPECT_NEAR(fields.edges()[from_bin0].ideal_pixel.x(), 29.5, 0.01);
  EXPECT_NEAR(fields.distance(0).at<float>(y, 40),
              40 - std::lround(fields.edges()[from_bin0].ideal_pixel.x()), 0.05);
  const int from_bin4 = fields.NearestEdge(4, 40, y);
  ASSERT_GE(from_bin4, 0);
  EXPECT_GE(fields.edges()[from_bin4].sensor_pixel.x(), 35);
  // Bin 1 holds bin 0's edges (neighbour); bin 2 (gradient along +y) holds none of them.
  EXPECT_GE(fields.NearestEdge(1, 40, y), 0);
  EXPECT_EQ(fields.NearestEdge(2, 40, y), -1);
  EXPECT_EQ(fields.NearestEdge(6, 40, y), -1);
  // Beyond max_distance_px there is no nearest edge.
  OrientedEdgeOptions short_reach = options;
  short_reach.max_distance_px = 5;
  const OrientedEdgeFields near_fields(edges, width, height, short_reach);
  EXPECT_EQ(near_fields.NearestEdge(0, 40, y), -1);
  EXPECT_GE(near_fields.NearestEdge(4, 40, y), 0);
  // Outside the image.
  EXPECT_EQ(fields.NearestEdge(0, -1, y), -1);
  EXPECT_EQ(fields.NearestEdge(8, 10, y), -1);
}

TEST(OrientedEdgeFields, DistancesAreEuclideanToTheNearestEdgeOfTheBin) {
  // One bright square: four sides, four bins (of 4), each field measured from its own side.
  const int width = 80;
  const int height = 80;
  cv::Mat image(height, width, CV_8UC1, cv::Scalar(10));
  image(cv::Rect(30, 30, 20, 20)).setTo(240);
  const UndistortionTable table(Camera::Pinhole(width, height, 80, 80, 39.5, 39.5));
  OrientedEdgeOptions options;
  options.orientation_bins = 4;
  options.max_distance_px = 40;
  const OrientedEdgeFields fields(DetectOrientedEdges(image, table, options), width, height,
                                  options);
  // Bin 0 (gradient +x: the square's left side at x ~ 29.5) with neighbours 3 and 1 (the top
  // and bottom sides); bin 2 (gradient -x: the right side) with the same neighbours.
  // At (5, 40), far left of the square, the nearest bin-0 edge is the left side, ~24 px away;
  // the nearest bin-2 edge is a corner of the top or bottom side, farther.
  const float to_left = fields.distance(0).at<float>(40, 5);
  EXPECT_NEAR(to_left, 24.5, 1.0);
  EXPECT_GT(fields.distance(2).at<float>(40, 5), to_left);
  // The mask-5 distance transform is within 2 % of Euclidean along a diagonal.
  const int nearest = fields.NearestEdge(0, 5, 40);
  ASSERT_GE(nearest, 0);
  const Eigen::Vector2d offset = Eigen::Vector2d(5, 40) - fields.edges()[nearest].ideal_pixel;
  EXPECT_NEAR(fields.distance(0).at<float>(40, 5), offset.norm(), 0.02 * offset.norm() + 0.01);
}

TEST(OrientedEdgeFields, RefusesBadInput) {
  const UndistortionTable table(Camera::Pinhole(16, 12, 20, 20, 7.5, 5.5));
  OrientedEdgeOptions options;
  EXPECT_THROW(DetectOrientedEdges(cv::Mat(12, 16, CV_32FC1), table, options),
               InvalidArgumentError);
  EXPECT_THROW(DetectOrientedEdges(cv::Mat(10, 16, CV_8UC1), table, options), InvalidArgumentError);
  options.orientation_bins = 3;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  EdgePixel bad;
  bad.bin = 9;
  EXPECT_THROW(OrientedEdgeFields({bad}, 16, 12, OrientedEdgeOptions()), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::odometry
