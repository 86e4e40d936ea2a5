#include "localizer/tracking/polarity.h"

#include <cmath>

#include <gtest/gtest.h>

namespace evloc::tracking {
namespace {

// A vertical edge at depth 2 m in front of a camera at the origin: bright for world x < 0, dark
// for x > 0, so the 3D gradient (towards brighter) is -x. The camera translates along x between
// the previous and the predicted pose; the test renders the brightness of a pixel swept by the
// edge at both poses and compares the sign of its change with the predicted polarity.
struct EdgeExample {
  PinholeIntrinsics intrinsics{300.0, 300.0, 160.0, 120.0};
  Eigen::Vector3d position{0.0, 0.0, 2.0};
  Eigen::Vector3d gradient{-1.0, 0.0, 0.0};

  // Brightness at image column u when the edge projects at column edge_u.
  static double Brightness(double u, double edge_u) { return u < edge_u ? 1.0 : 0.1; }

  double EdgeColumn(const Rigid3d& cam_from_world) const {
    Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
    EXPECT_TRUE(intrinsics.Project(cam_from_world * position, &pixel));
    return pixel.x();
  }
};

TEST(Polarity, PredictionMatchesBrightnessConstancyOfAMovingEdge) {
  const EdgeExample example;
  for (const double camera_motion_m : {-0.02, 0.02}) {
    const Rigid3d previous_world_from_cam;
    const Rigid3d predicted_world_from_cam(Eigen::Quaterniond::Identity(),
                                           Eigen::Vector3d(camera_motion_m, 0, 0));
    const Rigid3d previous = previous_world_from_cam.Inverse();
    const Rigid3d predicted = predicted_world_from_cam.Inverse();
    const double edge_before = example.EdgeColumn(previous);
    const double edge_after = example.EdgeColumn(predicted);
    ASSERT_GT(std::abs(edge_after - edge_before), 1.0);
    // A pixel the edge sweeps over.
    const double swept_pixel = 0.5 * (edge_before + edge_after);
    const double change = EdgeExample::Brightness(swept_pixel, edge_after) -
                          EdgeExample::Brightness(swept_pixel, edge_before);
    ASSERT_NE(change, 0.0);
    const PredictedPolarity expected =
        change > 0 ? PredictedPolarity::kOn : PredictedPolarity::kOff;
    EXPECT_EQ(PredictPolarity(example.position, example.gradient, example.intrinsics, predicted,
                              previous, PolarityPredictionOptions{}),
              expected)
        << "camera motion " << camera_motion_m;
  }
  // Camera moving -x: the edge moves right, the bright side covers the pixel: ON.
  const Rigid3d predicted =
      Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-0.02, 0, 0)).Inverse();
  EXPECT_EQ(PredictPolarity(example.position, example.gradient, example.intrinsics, predicted,
                            Rigid3d(), PolarityPredictionOptions{}),
            PredictedPolarity::kOn);
}

TEST(Polarity, NeutralBandAroundNinetyDegrees) {
  const PolarityPredictionOptions options;  // 30 degrees in total: 75..105 is neutral.
  const Eigen::Vector2d gradient(1.0, 0.0);
  auto flow_at = [](double degrees) {
    const double radians = degrees * M_PI / 180.0;
    return Eigen::Vector2d(std::cos(radians), std::sin(radians));
  };
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(0), options), PredictedPolarity::kOff);
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(70), options), PredictedPolarity::kOff);
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(80), options), PredictedPolarity::kUnsigned);
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(90), options), PredictedPolarity::kUnsigned);
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(100), options), PredictedPolarity::kUnsigned);
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(110), options), PredictedPolarity::kOn);
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(180), options), PredictedPolarity::kOn);
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(-110), options), PredictedPolarity::kOn);
  // The magnitudes do not matter (the reference code divided by the sum of norms).
  EXPECT_EQ(ClassifyPolarity(5.0 * gradient, 0.2 * flow_at(110), options), PredictedPolarity::kOn);
  // A flow below min_flow_px gives no prediction.
  EXPECT_EQ(ClassifyPolarity(gradient, 0.01 * flow_at(180), options), PredictedPolarity::kUnsigned);
  // Without a band, only exactly 90 degrees is neutral.
  PolarityPredictionOptions no_band;
  no_band.neutral_band_deg = 0;
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(89), no_band), PredictedPolarity::kOff);
  EXPECT_EQ(ClassifyPolarity(gradient, flow_at(91), no_band), PredictedPolarity::kOn);
}

}  // namespace
}  // namespace evloc::tracking
