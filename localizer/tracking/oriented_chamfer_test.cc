// The oriented chamfer field of the global search's pre-score (docs/relocalization.md, "Events").
#include "localizer/tracking/oriented_chamfer.h"

#include <opencv2/imgproc.hpp>

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::tracking {
namespace {

// Mean oriented (or, with bin < 0, plain) distance of points at pixels `points` whose edge normal
// is (normal_x, normal_y).
double MeanDistance(const OrientedChamferField& field, const cv::Mat& plain,
                    const std::vector<cv::Point>& points, double normal_x, double normal_y,
                    bool oriented) {
  double sum = 0;
  for (const cv::Point& p : points) {
    sum += oriented ? field.Distance(p.x, p.y, field.Bin(normal_x, normal_y))
                    : plain.ptr<float>(p.y)[p.x];
  }
  return sum / static_cast<double>(points.size());
}

TEST(OrientedChamfer, DistanceCountsOnlyEdgesOfTheSameOrientation) {
  cv::Mat edges(200, 200, CV_8UC1, cv::Scalar(0));
  cv::line(edges, {20, 100}, {180, 100}, cv::Scalar(255));  // horizontal: normal along y
  cv::line(edges, {50, 20}, {50, 180}, cv::Scalar(255));    // vertical: normal along x
  OrientedChamferField field;
  OrientedChamferOptions options;
  options.truncation_px = 100;
  field.Build(edges, options);
  EXPECT_GT(field.oriented_pixels(), 250);
  // (120, 110): 10 px below the horizontal line, 70 px right of the vertical one.
  EXPECT_NEAR(field.Distance(120, 110, field.Bin(0, 1)), 10, 0.5);
  EXPECT_NEAR(field.Distance(120, 110, field.Bin(1, 0)), 70, 1.0);
  // An edge normal and its opposite are one orientation.
  EXPECT_EQ(field.Bin(0, 1), field.Bin(0, -1));
  EXPECT_EQ(field.Bin(1, 0), field.Bin(-1, 0));
  EXPECT_NE(field.Bin(1, 0), field.Bin(0, 1));
  // Far from any edge of the orientation: the truncation.
  OrientedChamferOptions short_range = options;
  short_range.truncation_px = 24;
  field.Build(edges, short_range);
  EXPECT_FLOAT_EQ(field.Distance(120, 110, field.Bin(1, 0)), 24.0f);
}

// A vertical edge drawn in dashes (the edge of the model, seen with gaps, as events of an edge
// moving along itself) beside dense horizontal texture: the plain chamfer prefers to put the
// model's points (a vertical edge) on the texture, the oriented one on the edge.
TEST(OrientedChamfer, PrefersTheTrueEdgeWhereThePlainChamferPrefersDenseTexture) {
  cv::Mat edges(240, 320, CV_8UC1, cv::Scalar(0));
  for (int y = 20; y < 220; y += 2) cv::line(edges, {20, y}, {140, y}, cv::Scalar(255));
  for (int y = 20; y < 220; y += 10) cv::line(edges, {240, y}, {240, y + 5}, cv::Scalar(255));
  std::vector<cv::Point> on_texture;
  std::vector<cv::Point> on_edge;
  for (int y = 40; y < 200; ++y) {
    on_texture.emplace_back(80, y);
    on_edge.emplace_back(240, y);
  }
  cv::Mat not_edges;
  cv::bitwise_not(edges, not_edges);
  cv::Mat plain;
  cv::distanceTransform(not_edges, plain, cv::DIST_L2, cv::DIST_MASK_5);
  OrientedChamferField field;
  field.Build(edges, OrientedChamferOptions());
  // The model's edge is vertical: its normal is along x.
  const double plain_texture = MeanDistance(field, plain, on_texture, 1, 0, false);
  const double plain_edge = MeanDistance(field, plain, on_edge, 1, 0, false);
  const double oriented_texture = MeanDistance(field, plain, on_texture, 1, 0, true);
  const double oriented_edge = MeanDistance(field, plain, on_edge, 1, 0, true);
  EXPECT_LT(plain_texture, plain_edge);
  EXPECT_LT(oriented_edge, oriented_texture);
  EXPECT_LT(oriented_edge, 2.0);
  EXPECT_GT(oriented_texture, 10.0);
}

TEST(OrientedChamfer, RejectsInvalidInputAndOptions) {
  OrientedChamferField field;
  EXPECT_THROW(field.Build(cv::Mat(), OrientedChamferOptions()), InvalidArgumentError);
  EXPECT_THROW(field.Build(cv::Mat(10, 10, CV_32FC1), OrientedChamferOptions()),
               InvalidArgumentError);
  OrientedChamferOptions options;
  options.bins = 1;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = OrientedChamferOptions();
  options.tolerance_bins = 4;  // 9 bins of 8
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = OrientedChamferOptions();
  options.min_coherence = 1;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = OrientedChamferOptions();
  options.mean_window_px = -1;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::tracking
