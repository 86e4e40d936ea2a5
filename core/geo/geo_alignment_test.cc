#include "core/geo/geo_alignment.h"

#include <gtest/gtest.h>

#include <random>

#include "core/common/error.h"

namespace evloc {
namespace {

// Map points spread over a 120 m x 80 m site, up to 15 m high, with their WGS84 positions
// through `truth` (exact; noise and outliers are added by the tests).
std::vector<GeoCorrespondence> Survey(const GeoAnchor& truth, int count, uint64_t seed) {
  const GeoReference reference(truth);
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> x(-60, 60), y(-40, 40), z(0, 15);
  std::vector<GeoCorrespondence> points;
  for (int i = 0; i < count; ++i) {
    GeoCorrespondence point;
    point.p_map = {x(random), y(random), z(random)};
    point.geodetic = reference.GeodeticFromMap(point.p_map);
    point.label = "point " + std::to_string(i);
    points.push_back(point);
  }
  return points;
}

GeoAnchor TrueAnchor() {
  GeoAnchor anchor;
  anchor.origin = {47.3769, 8.5417, 408.0};
  anchor.enu_from_map = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.05, -0.02, 1).normalized())),
      Eigen::Vector3d(30.0, -12.0, 1.5));
  return anchor;
}

// Largest distance, over the map points, between where the estimated and the true anchor put
// them, metres.
double WorstDisagreement(const GeoAnchor& estimate, const GeoAnchor& truth,
                         const std::vector<GeoCorrespondence>& points) {
  const GeoReference a(estimate), b(truth);
  double worst = 0.0;
  for (const GeoCorrespondence& point : points) {
    const Eigen::Vector3d in_b = b.enu_frame().FromGeodetic(a.GeodeticFromMap(point.p_map));
    worst = std::max(worst, (in_b - truth.enu_from_map * point.p_map).norm());
  }
  return worst;
}

TEST(GeoAlignmentTest, ExactPointsGiveTheAnchorBack) {
  const GeoAnchor truth = TrueAnchor();
  const auto points = Survey(truth, 12, 1);
  const GeoAlignment alignment = AlignMapToGeodetic(points, {}, kGeoAnchorSourceSurvey);
  EXPECT_EQ(alignment.num_inliers, 12u);
  EXPECT_LT(alignment.rms_m, 1e-6);
  EXPECT_NEAR(alignment.scale, 1.0, 1e-9);
  EXPECT_LT(WorstDisagreement(alignment.anchor, truth, points), 1e-6);
  EXPECT_EQ(alignment.anchor.source, "survey");
}

// Consumer GNSS: 3 m per axis horizontally, 5 m vertically, and a fifth of the fixes off by
// 40-80 m (multipath); RANSAC keeps the good ones and the fit is within the noise's standard
// error at the site.
TEST(GeoAlignmentTest, NoisyFixesWithOutliersAreAlignedRobustly) {
  const GeoAnchor truth = TrueAnchor();
  auto points = Survey(truth, 60, 2);
  const EnuFrame frame(truth.origin);
  std::mt19937_64 random(3);
  std::normal_distribution<double> horizontal(0.0, 3.0), vertical(0.0, 5.0);
  std::uniform_real_distribution<double> outlier(40.0, 80.0), angle(0.0, 2 * M_PI);
  std::vector<bool> is_outlier(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    Eigen::Vector3d enu = frame.FromGeodetic(points[i].geodetic);
    enu += Eigen::Vector3d(horizontal(random), horizontal(random), vertical(random));
    if (i % 5 == 0) {
      const double a = angle(random), d = outlier(random);
      enu += Eigen::Vector3d(d * std::cos(a), d * std::sin(a), 0.0);
      is_outlier[i] = true;
    }
    points[i].geodetic = frame.ToGeodetic(enu);
  }
  GeoAlignmentOptions options;
  options.inlier_threshold_m = 15.0;  // 3 sigma of the 3D residual with 5 m vertical noise
  const GeoAlignment alignment = AlignMapToGeodetic(points, options, kGeoAnchorSourceExif);
  for (size_t i = 0; i < points.size(); ++i) {
    if (is_outlier[i]) {
      EXPECT_FALSE(alignment.inliers[i]) << i;
    }
  }
  EXPECT_GE(alignment.num_inliers, 45u);
  EXPECT_NEAR(alignment.horizontal_rms_m, 3.0 * std::sqrt(2.0), 1.5);
  EXPECT_NEAR(alignment.vertical_rms_m, 5.0, 1.5);
  // 48 fixes: the centroid's standard error is 3 / sqrt(48) = 0.43 m horizontally and 0.72 m
  // vertically; the vertical noise tilts the fit by about 5 / (34.6 * sqrt(48)) = 0.021 rad (34.6
  // m: the spread of x), 1.25 m at the site's edge (60 m): 1.45 m one-sigma there, 4.5 m at 3.
  EXPECT_LT(WorstDisagreement(alignment.anchor, truth, points), 4.5);
  EXPECT_GT(alignment.anchor.horizontal_sigma_m, 0.3);
  EXPECT_LT(alignment.anchor.horizontal_sigma_m, 1.0);
}

TEST(GeoAlignmentTest, CollinearPointsAreRefused) {
  GeoAnchor truth = TrueAnchor();
  auto points = Survey(truth, 5, 4);
  const GeoReference reference(truth);
  for (size_t i = 0; i < points.size(); ++i) {
    points[i].p_map = Eigen::Vector3d(10.0 * i, 0.0, 0.0);
    points[i].geodetic = reference.GeodeticFromMap(points[i].p_map);
  }
  try {
    AlignMapToGeodetic(points, {}, kGeoAnchorSourceSurvey);
    FAIL() << "collinear points were aligned";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("collinear"), std::string::npos) << error.what();
  }
}

TEST(GeoAlignmentTest, AMapAtAnotherScaleIsRefused) {
  const GeoAnchor truth = TrueAnchor();
  auto points = Survey(truth, 10, 5);
  for (GeoCorrespondence& point : points) point.p_map *= 0.5;  // an unscaled COLMAP model
  GeoAlignmentOptions options;
  options.inlier_threshold_m = 200.0;
  try {
    AlignMapToGeodetic(points, options, kGeoAnchorSourceSurvey);
    FAIL() << "a half-scale map was aligned";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("scale"), std::string::npos) << error.what();
  }
}

TEST(GeoAlignmentTest, TooFewOrDisagreeingPointsAreRefused) {
  const GeoAnchor truth = TrueAnchor();
  auto points = Survey(truth, 2, 6);
  EXPECT_THROW(AlignMapToGeodetic(points, {}, kGeoAnchorSourceSurvey), InvalidArgumentError);
  points = Survey(truth, 6, 7);
  // Every fix somewhere else: no 3 agree within 1 m.
  std::mt19937_64 random(8);
  std::uniform_real_distribution<double> scatter(-500, 500);
  const EnuFrame frame(truth.origin);
  for (GeoCorrespondence& point : points) {
    point.geodetic = frame.ToGeodetic(Eigen::Vector3d(scatter(random), scatter(random), 0));
  }
  GeoAlignmentOptions options;
  options.inlier_threshold_m = 1.0;
  options.min_inliers = 4;
  EXPECT_THROW(AlignMapToGeodetic(points, options, kGeoAnchorSourceSurvey), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc
