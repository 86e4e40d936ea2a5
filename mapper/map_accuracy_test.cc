#include "mapper/map_accuracy.h"

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::mapper {
namespace {

// A row of edge points every 1 cm on the plane z = 2 m, gradients along +y.
Map MakeEdgeMap(double z_offset) {
  Map map;
  for (int i = -40; i <= 40; ++i) {
    map.positions.emplace_back(0.01f * static_cast<float>(i), 0.0f,
                               static_cast<float>(2.0 + z_offset));
    map.gradients.emplace_back(0.0f, 1.0f, 0.0f);
  }
  return map;
}

// A fronto-parallel view of the plane z = 2 m from the origin.
DepthView MakePlaneView() {
  DepthView view;
  view.camera = Camera::Pinhole(64, 48, 50.0, 50.0, 31.5, 23.5);
  view.cam_from_world = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d::Zero());
  view.depth_m = cv::Mat(48, 64, CV_32F, cv::Scalar(2.0f));
  return view;
}

TEST(MapAccuracy, ExactMapHasNoError) {
  const Map reference = MakeEdgeMap(0.0);
  const MapAccuracy accuracy =
      MeasureMapAccuracy(reference, reference, {MakePlaneView()}, MapAccuracyOptions());
  EXPECT_EQ(accuracy.num_points, reference.size());
  EXPECT_GT(accuracy.num_depth_compared, 0u);
  EXPECT_NEAR(accuracy.median_depth_error_m, 0.0, 1e-6);
  EXPECT_NEAR(accuracy.median_edge_distance_m, 0.0, 1e-6);
  EXPECT_DOUBLE_EQ(accuracy.edge_within_fraction, 1.0);
  EXPECT_NEAR(accuracy.median_gradient_angle_deg, 0.0, 1e-3);
  EXPECT_NEAR(accuracy.median_image_gradient_angle_deg, 0.0, 1e-3);
}

TEST(MapAccuracy, MeasuresOffsetsAndGradientAngles) {
  const Map reference = MakeEdgeMap(0.0);
  Map shifted = MakeEdgeMap(0.03);  // 3 cm behind the plane.
  // Points half-way between reference samples lie on the reference edge segment.
  for (Eigen::Vector3f& position : shifted.positions) position.x() += 0.005f;
  for (Eigen::Vector3f& gradient : shifted.gradients) gradient = Eigen::Vector3f(1.0f, 1.0f, 0.0f);
  for (Eigen::Vector3f& gradient : shifted.gradients) gradient.normalize();
  const MapAccuracy accuracy =
      MeasureMapAccuracy(shifted, reference, {MakePlaneView()}, MapAccuracyOptions());
  EXPECT_NEAR(accuracy.median_depth_error_m, 0.03, 1e-5);
  EXPECT_DOUBLE_EQ(accuracy.depth_within_fraction, 0.0);
  EXPECT_NEAR(accuracy.median_edge_distance_m, 0.03, 1e-5);
  EXPECT_NEAR(accuracy.median_gradient_angle_deg, 45.0, 1e-3);
  EXPECT_NEAR(accuracy.median_image_gradient_angle_deg, 45.0, 0.1);
}

TEST(MapAccuracy, RejectsEmptyMapsAndBadOptions) {
  const Map reference = MakeEdgeMap(0.0);
  EXPECT_THROW(MeasureMapAccuracy(Map(), reference, {}, MapAccuracyOptions()),
               InvalidArgumentError);
  MapAccuracyOptions options;
  options.within_m = 0.0;
  EXPECT_THROW(MeasureMapAccuracy(reference, reference, {}, options), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::mapper
