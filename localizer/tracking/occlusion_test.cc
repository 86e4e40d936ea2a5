#include "localizer/tracking/occlusion.h"

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::tracking {
namespace {

TEST(NearestEdgeField, FindsTheNearestEdgePixel) {
  cv::Mat edges = cv::Mat::zeros(30, 40, CV_8UC1);
  edges.at<uint8_t>(10, 5) = 255;   // (x 5, y 10)
  edges.at<uint8_t>(20, 30) = 255;  // (x 30, y 20)
  NearestEdgeField annf;
  annf.Build(edges);
  EXPECT_EQ(annf.num_edge_pixels(), 2);
  int index;
  float distance;
  ASSERT_TRUE(annf.Nearest(8, 10, &index, &distance));
  EXPECT_EQ(index, 10 * 40 + 5);
  EXPECT_NEAR(distance, 3.0, 0.05);
  ASSERT_TRUE(annf.Nearest(30, 20, &index, &distance));
  EXPECT_EQ(index, 20 * 40 + 30);
  EXPECT_EQ(distance, 0.0f);
  ASSERT_TRUE(annf.Nearest(27, 16, &index, &distance));
  EXPECT_EQ(index, 20 * 40 + 30);
  EXPECT_NEAR(distance, 5.0, 0.1);
  EXPECT_FALSE(annf.Nearest(40, 0, &index, &distance));
  // An image without edges has no nearest edge.
  annf.Build(cv::Mat::zeros(30, 40, CV_8UC1));
  EXPECT_TRUE(annf.empty());
  EXPECT_FALSE(annf.Nearest(8, 10, &index, &distance));
}

// Two points claim the edge pixel (x 20, y 15); the nearer must win whatever the order. A
// z-buffer that never compares (reallocated per point, as in the reference code) keeps both.
TEST(EdgeZBuffer, KeepsTheNearerOfTwoPointsClaimingOneEdgePixel) {
  cv::Mat edges = cv::Mat::zeros(30, 40, CV_8UC1);
  edges.at<uint8_t>(15, 20) = 255;
  edges.at<uint8_t>(5, 35) = 255;
  NearestEdgeField annf;
  annf.Build(edges);
  EdgeZBuffer zbuffer;
  std::vector<uint8_t> keep;
  const std::vector<Eigen::Vector2d> pixels = {
      {21.2, 15.4},  // near (20, 15), depth 3
      {19.0, 16.0},  // near (20, 15), depth 2: occludes the first
      {34.6, 5.2},   // alone at (35, 5)
      {5.0, 25.0},   // more than 5 px from every edge
  };
  zbuffer.Cull(pixels, {3.0, 2.0, 4.0, 1.0}, annf, 5.0, &keep);
  EXPECT_EQ(keep, (std::vector<uint8_t>{0, 1, 1, 0}));
  // Same points, nearer one first.
  zbuffer.Cull(pixels, {2.0, 3.0, 4.0, 1.0}, annf, 5.0, &keep);
  EXPECT_EQ(keep, (std::vector<uint8_t>{1, 0, 1, 0}));
  // The buffer is reset between calls: a lone point keeps its edge pixel.
  zbuffer.Cull({{21.0, 15.0}}, {9.0}, annf, 5.0, &keep);
  EXPECT_EQ(keep, (std::vector<uint8_t>{1}));
  // Equal depths: the lower index wins.
  zbuffer.Cull({{21.0, 15.0}, {19.0, 15.0}}, {2.0, 2.0}, annf, 5.0, &keep);
  EXPECT_EQ(keep, (std::vector<uint8_t>{1, 0}));
  EXPECT_THROW(zbuffer.Cull({{1.0, 1.0}}, {}, annf, 5.0, &keep), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::tracking
