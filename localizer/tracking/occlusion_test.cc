#include "localizer/tracking/occlusion.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

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
  int index;
  float distance;
  ASSERT_TRUE(annf.Nearest(8, 10, 5.0, &index, &distance));
  EXPECT_EQ(index, 10 * 40 + 5);
  EXPECT_NEAR(distance, 3.0, 0.05);
  ASSERT_TRUE(annf.Nearest(30, 20, 5.0, &index, &distance));
  EXPECT_EQ(index, 20 * 40 + 30);
  EXPECT_EQ(distance, 0.0f);
  ASSERT_TRUE(annf.Nearest(27, 16, 5.0, &index, &distance));
  EXPECT_EQ(index, 20 * 40 + 30);
  EXPECT_NEAR(distance, 5.0, 0.1);
  // Beyond the search radius there is no nearest edge.
  EXPECT_FALSE(annf.Nearest(27, 16, 4.9, &index, &distance));
  EXPECT_FALSE(annf.Nearest(40, 0, 5.0, &index, &distance));
  // An image without edges has no nearest edge.
  annf.Build(cv::Mat::zeros(30, 40, CV_8UC1));
  EXPECT_FALSE(annf.Nearest(8, 10, 5.0, &index, &distance));
}

// RoundToPixel rounds half away from zero exactly as std::lround, at and around the halves, and
// refuses non-finite and far-off coordinates; Nearest of a real pixel searches from it.
TEST(NearestEdgeField, RoundsPixelsAsLroundWithoutTheLibraryCall) {
  std::vector<double> values = {0.0, -0.0, 0.5, -0.5, 1.5, -1.5, 2.5, -2.5, 1e8, -1e8, 3.0, -3.0};
  for (const double half : {0.5, 1.5, 2.5, 319.5, -0.5, -1.5, -239.5}) {
    values.push_back(std::nextafter(half, 1e9));
    values.push_back(std::nextafter(half, -1e9));
  }
  std::mt19937 random(3);
  std::uniform_real_distribution<double> uniform(-1000.0, 1000.0);
  for (int i = 0; i < 10000; ++i) values.push_back(uniform(random));
  for (const double value : values) {
    int x = 0;
    int y = 0;
    ASSERT_TRUE(NearestEdgeField::RoundToPixel(Eigen::Vector2d(value, -value), &x, &y));
    EXPECT_EQ(x, std::lround(value)) << value;
    EXPECT_EQ(y, std::lround(-value)) << value;
  }
  int x = 7;
  int y = 7;
  EXPECT_FALSE(NearestEdgeField::RoundToPixel(Eigen::Vector2d(NAN, 1.0), &x, &y));
  EXPECT_FALSE(NearestEdgeField::RoundToPixel(Eigen::Vector2d(1.0, INFINITY), &x, &y));
  EXPECT_FALSE(NearestEdgeField::RoundToPixel(Eigen::Vector2d(2e8, 1.0), &x, &y));
  EXPECT_EQ(x, 7);

  cv::Mat edges = cv::Mat::zeros(30, 40, CV_8UC1);
  edges.at<uint8_t>(10, 5) = 255;
  NearestEdgeField annf;
  annf.Build(edges);
  int index;
  float distance;
  ASSERT_TRUE(annf.Nearest(Eigen::Vector2d(7.5, 9.6), 5.0, &index, &distance));  // (8, 10)
  EXPECT_EQ(index, 10 * 40 + 5);
  EXPECT_NEAR(distance, 3.0, 1e-6);
  EXPECT_FALSE(annf.Nearest(Eigen::Vector2d(NAN, 10.0), 5.0, &index, &distance));
}

// The window search agrees with a brute-force search over every edge pixel, for a mask and for
// the active pixels of a time surface (the same pixels as the surface's active mask).
TEST(NearestEdgeField, WindowSearchEqualsBruteForceOnMaskAndTimeSurface) {
  const UndistortionTable table(Camera::Pinhole(50, 40, 40, 40, 24.5, 19.5));
  TimeSurface surface(table);
  std::mt19937 random(11);
  std::uniform_int_distribution<int> column(0, 49), row(0, 39);
  EventBuffer events;
  for (int i = 0; i < 60; ++i) {
    events.push_back({int64_t{i} * 2'000'000, static_cast<uint16_t>(column(random)),
                      static_cast<uint16_t>(row(random)), static_cast<int8_t>(i % 2 ? 1 : -1)});
  }
  surface.Insert(events, 0, events.size());
  const SurfaceDecay decay{30e6, 0.1};
  const int64_t t_ns = 120'000'000;
  const cv::Mat mask = surface.ActiveMask(SurfaceChannel::kAll, t_ns, decay);
  ASSERT_GT(cv::countNonZero(mask), 10);
  ASSERT_LT(cv::countNonZero(mask), 60);  // Some events have decayed.
  NearestEdgeField from_mask;
  from_mask.Build(mask);
  NearestEdgeField from_surface;
  from_surface.Build(surface, SurfaceChannel::kAll, t_ns, decay);
  for (int y = 0; y < 40; ++y) {
    for (int x = 0; x < 50; ++x) {
      ASSERT_EQ(from_surface.IsEdge(x, y), mask.at<uint8_t>(y, x) != 0) << x << " " << y;
      double best = 1e9;
      for (int yy = 0; yy < 40; ++yy) {
        for (int xx = 0; xx < 50; ++xx) {
          if (mask.at<uint8_t>(yy, xx) != 0) best = std::min(best, std::hypot(xx - x, yy - y));
        }
      }
      for (const NearestEdgeField* field : {&from_mask, &from_surface}) {
        int index;
        float distance;
        const bool found = field->Nearest(x, y, 5.0, &index, &distance);
        ASSERT_EQ(found, best <= 5.0) << x << " " << y;
        if (!found) continue;
        EXPECT_NEAR(distance, best, 1e-5);
        EXPECT_NE(mask.at<uint8_t>(index / 50, index % 50), 0);
        EXPECT_NEAR(std::hypot(index % 50 - x, index / 50 - y), best, 1e-5);
      }
    }
  }
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
