#include "core/geo/geo_alignment.h"

#include <gtest/gtest.h>

#include <algorithm>
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

namespace evloc {
namespace {

// The experiment of docs/accuracy.md ("Anchors from noisy GNSS"): photos along a survey path
// tagged with GNSS positions of 3 m one-sigma noise per axis (consumer GNSS), the anchor aligned
// to them (AlignMapToGeodetic with the defaults evloc-mapper uses), and the shift of the reported
// WGS84 positions over the site (how far the anchor moves a map point from where the true anchor
// puts it), over 100 noise draws per survey. Printed as a table; the car park's 95th percentile
// is asserted against the standard error of its 200 fixes.
struct Survey3m {
  const char* name;
  int photos;
  double half_x_m, half_y_m;  // the survey loop's half extents
};

struct ShiftFigures {
  int refused = 0;
  std::vector<double> horizontal, vertical;
};

double Percentile(std::vector<double> values, double fraction) {
  if (values.empty()) return NAN;
  std::sort(values.begin(), values.end());
  return values[static_cast<size_t>(fraction * static_cast<double>(values.size() - 1))];
}

ShiftFigures MeasureShift(const Survey3m& survey, int draws) {
  ShiftFigures figures;
  const GeoAnchor truth = TrueAnchor();
  const GeoReference true_reference(truth);
  for (int draw = 0; draw < draws; ++draw) {
    std::mt19937_64 random(1000 + draw);
    std::normal_distribution<double> noise(0.0, 3.0);
    std::vector<GeoCorrespondence> photos;
    for (int i = 0; i < survey.photos; ++i) {
      const double angle = 2 * M_PI * i / survey.photos;
      GeoCorrespondence photo;
      photo.p_map = {survey.half_x_m * std::cos(angle), survey.half_y_m * std::sin(angle), 1.6};
      const Eigen::Vector3d enu = truth.enu_from_map * photo.p_map +
                                  Eigen::Vector3d(noise(random), noise(random), noise(random));
      photo.geodetic = true_reference.enu_frame().ToGeodetic(enu);
      photo.label = "photo " + std::to_string(i);
      photos.push_back(photo);
    }
    GeoAlignment alignment;
    try {
      alignment = AlignMapToGeodetic(photos, {}, kGeoAnchorSourceExif);
    } catch (const InvalidArgumentError&) {
      ++figures.refused;
      continue;
    }
    const GeoReference estimate(alignment.anchor);
    // The shift at the site's points: a grid over the survey's extent at 0 and 3 m height.
    for (double fx : {-1.0, 0.0, 1.0}) {
      for (double fy : {-1.0, 0.0, 1.0}) {
        for (double z : {0.0, 3.0}) {
          const Eigen::Vector3d p(fx * survey.half_x_m, fy * survey.half_y_m, z);
          const Eigen::Vector3d shift =
              true_reference.enu_frame().FromGeodetic(estimate.GeodeticFromMap(p)) -
              truth.enu_from_map * p;
          figures.horizontal.push_back(shift.head<2>().norm());
          figures.vertical.push_back(std::abs(shift.z()));
        }
      }
    }
  }
  return figures;
}

TEST(GeoAlignmentExperiment, ShiftOfReportedPositionsFromThreeMetreGnssTags) {
  const Survey3m surveys[] = {{"room (4 photos, 1 m loop)", 4, 0.5, 0.5},
                              {"courtyard (12 photos, 40 x 30 m)", 12, 20, 15},
                              {"car park (200 photos, 200 x 200 m)", 200, 100, 100}};
  std::printf(
      "| survey | refused of 100 | horizontal shift median / 95 %% / max (m) | vertical "
      "shift median / 95 %% / max (m) |\n|---|---|---|---|\n");
  ShiftFigures car_park;
  for (const Survey3m& survey : surveys) {
    const ShiftFigures figures = MeasureShift(survey, 100);
    const auto& h = figures.horizontal;
    const auto& v = figures.vertical;
    std::printf("| %s | %d | %.2f / %.2f / %.2f | %.2f / %.2f / %.2f |\n", survey.name,
                figures.refused, Percentile(h, 0.5), Percentile(h, 0.95),
                h.empty() ? NAN : *std::max_element(h.begin(), h.end()), Percentile(v, 0.5),
                Percentile(v, 0.95), v.empty() ? NAN : *std::max_element(v.begin(), v.end()));
    car_park = figures;
  }
  // 200 fixes: the centroid's standard error is 0.21 m per axis, the tilt 3 / (70.7 sqrt(200))
  // = 3 mrad, 0.3 m at the corners (141 m): the 95th percentile of the shift stays below 1 m.
  EXPECT_EQ(car_park.refused, 0);
  EXPECT_LT(Percentile(car_park.horizontal, 0.95), 1.0);
  EXPECT_LT(Percentile(car_park.vertical, 0.95), 1.0);
}

}  // namespace
}  // namespace evloc
