#include "tools/sim/depth_sensor.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "tools/sim/motion.h"
#include "tools/sim/renderer.h"
#include "tools/sim/scene.h"

namespace evloc::sim {
namespace {

// A small pinhole depth camera for constructed depth maps.
Camera SmallCamera() { return Camera::Pinhole(120, 90, 100.0, 100.0, 59.5, 44.5); }

// The model's defaults on `camera`, without noise.
DepthSensorOptions NoiselessOptions(const Camera& camera) {
  DepthSensorOptions options;
  options.camera = camera;
  options.noise_at_1m_m = 0.0;
  return options;
}

cv::Mat Constant(const Camera& camera, float value) {
  return cv::Mat(camera.height, camera.width, CV_32FC1, cv::Scalar(value));
}

// The mean and standard deviation of measured - exact over the measured pixels.
void ErrorStatistics(const cv::Mat& measured, const cv::Mat& exact, double* mean, double* sigma,
                     int* count) {
  double sum = 0;
  double sum_squared = 0;
  int n = 0;
  for (int y = 0; y < measured.rows; ++y) {
    for (int x = 0; x < measured.cols; ++x) {
      if (measured.at<float>(y, x) <= 0) continue;
      const double error = measured.at<float>(y, x) - exact.at<float>(y, x);
      sum += error;
      sum_squared += error * error;
      ++n;
    }
  }
  *count = n;
  *mean = sum / n;
  *sigma = std::sqrt(sum_squared / n - *mean * *mean);
}

TEST(DepthSensorModel, NoiseGrowsWithTheSquareOfTheDepth) {
  const Camera camera = SmallCamera();
  DepthSensorOptions options;
  options.camera = camera;
  options.noise_at_1m_m = 0.002;
  std::mt19937_64 rng(7);
  for (const double z : {1.0, 2.0, 4.0}) {
    const cv::Mat exact = Constant(camera, static_cast<float>(z));
    const cv::Mat measured = ApplyDepthSensorModel(exact, Constant(camera, 0.5f),
                                                   Constant(camera, 0.0f), camera, options, &rng);
    double mean = 0;
    double sigma = 0;
    int count = 0;
    ErrorStatistics(measured, exact, &mean, &sigma, &count);
    EXPECT_EQ(count, camera.width * camera.height) << "a fronto-parallel wall has no holes";
    const double expected = 0.002 * z * z;  // 2, 8, 32 mm
    EXPECT_NEAR(sigma, expected, 0.05 * expected + 0.0003) << "z = " << z;
    EXPECT_LT(std::abs(mean), 4 * expected / std::sqrt(count) + 0.0005) << "z = " << z;
  }
}

TEST(DepthSensorModel, DepthIsQuantisedToMillimetres) {
  const Camera camera = SmallCamera();
  DepthSensorOptions options = NoiselessOptions(camera);
  std::mt19937_64 rng(1);
  cv::Mat exact = Constant(camera, 0);
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      exact.at<float>(y, x) = static_cast<float>(1.5 + 0.0001 * x + 0.00003 * y);  // smooth
    }
  }
  const cv::Mat measured = ApplyDepthSensorModel(exact, Constant(camera, 0.5f),
                                                 Constant(camera, 0.0f), camera, options, &rng);
  int distinct_from_exact = 0;
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const double value = measured.at<float>(y, x);
      ASSERT_GT(value, 0);
      EXPECT_NEAR(value * 1000.0, std::round(value * 1000.0), 1e-3) << x << "," << y;
      EXPECT_LE(std::abs(value - exact.at<float>(y, x)), 0.0005 + 1e-6);
      distinct_from_exact += std::abs(value - exact.at<float>(y, x)) > 1e-5;
    }
  }
  EXPECT_GT(distinct_from_exact, camera.width * camera.height / 2);
  // With noise the values stay on the millimetre grid.
  options.noise_at_1m_m = 0.003;
  const cv::Mat noisy = ApplyDepthSensorModel(exact, Constant(camera, 0.5f), Constant(camera, 0.0f),
                                              camera, options, &rng);
  for (int y = 0; y < camera.height; y += 7) {
    for (int x = 0; x < camera.width; x += 5) {
      const double value = noisy.at<float>(y, x);
      EXPECT_NEAR(value * 1000.0, std::round(value * 1000.0), 1e-3);
    }
  }
}

TEST(DepthSensorModel, HolesOnTheFarSideOfADepthDiscontinuity) {
  const Camera camera = SmallCamera();
  DepthSensorOptions options = NoiselessOptions(camera);
  options.discontinuity_hole_px = 2;
  std::mt19937_64 rng(1);
  // A panel at 1 m covers the columns x < 60; the wall behind at 2 m the rest.
  cv::Mat exact = Constant(camera, 2.0f);
  exact(cv::Rect(0, 0, 60, camera.height)).setTo(1.0f);
  DepthModelCounts counts;
  const cv::Mat measured = ApplyDepthSensorModel(
      exact, Constant(camera, 0.5f), Constant(camera, 0.0f), camera, options, &rng, &counts);
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const bool hole = measured.at<float>(y, x) == 0.0f;
      // The near side keeps its depth; the far side loses the two columns beside the edge.
      EXPECT_EQ(hole, x == 60 || x == 61) << x << "," << y;
    }
  }
  EXPECT_EQ(counts.discontinuity, 2 * camera.height);
  EXPECT_EQ(counts.measured, camera.width * camera.height - 2 * camera.height);
  // A smooth slope is no discontinuity.
  cv::Mat slope = Constant(camera, 0);
  for (int x = 0; x < camera.width; ++x) slope.col(x).setTo(1.0f + 0.01f * x);
  DepthModelCounts slope_counts;
  ApplyDepthSensorModel(slope, Constant(camera, 0.5f), Constant(camera, 0.0f), camera, options,
                        &rng, &slope_counts);
  EXPECT_EQ(slope_counts.discontinuity, 0);
}

TEST(DepthSensorModel, HolesOnDarkSurfacesAndAtGrazingAngles) {
  const Camera camera = SmallCamera();
  DepthSensorOptions options = NoiselessOptions(camera);
  std::mt19937_64 rng(1);
  cv::Mat albedo = Constant(camera, 0.5f);
  albedo(cv::Rect(20, 20, 30, 30)).setTo(0.03f);  // a black patch on a grey wall
  DepthModelCounts counts;
  const cv::Mat measured = ApplyDepthSensorModel(
      Constant(camera, 1.5f), albedo, Constant(camera, 0.0f), camera, options, &rng, &counts);
  EXPECT_EQ(counts.dark, 30 * 30);
  for (int y = 20; y < 50; ++y) {
    for (int x = 20; x < 50; ++x) EXPECT_EQ(measured.at<float>(y, x), 0.0f);
  }
  EXPECT_GT(measured.at<float>(10, 10), 0.0f);
  // The same grey seen at a grazing angle returns too little light: a floor plane z = h / (v - cy)
  // * f seen from 0.2 m above it; far rows meet it at grazing angles.
  cv::Mat floor = Constant(camera, 0);
  for (int y = 0; y < camera.height; ++y) {
    const double v = y - camera.cy;
    if (v > 0.5) floor.row(y).setTo(static_cast<float>(0.2 * camera.fy / v));
  }
  options.max_range_m = 100;
  options.discontinuity_fraction = 0.9;  // the rows of a far floor are far apart in depth
  DepthModelCounts floor_counts;
  const cv::Mat floor_measured = ApplyDepthSensorModel(
      floor, Constant(camera, 0.5f), Constant(camera, 0.0f), camera, options, &rng, &floor_counts);
  // cos(incidence) = 0.2 / distance: below 0.06 / 0.5 = 0.12 far away, above near the camera.
  EXPECT_GT(floor_counts.dark, 0);
  EXPECT_EQ(floor_measured.at<float>(camera.height - 1, 60) > 0, true) << "near floor measured";
  EXPECT_EQ(floor_measured.at<float>(46, 60), 0.0f) << "floor 13 m away at a grazing angle";
}

TEST(DepthSensorModel, HolesOnShinySurfacesNearTheMirrorDirection) {
  const Camera camera = SmallCamera();
  DepthSensorOptions options = NoiselessOptions(camera);
  std::mt19937_64 rng(1);
  // A shiny wall facing the camera: the central pixels see it within 20 degrees of its normal.
  DepthModelCounts counts;
  const cv::Mat facing =
      ApplyDepthSensorModel(Constant(camera, 1.0f), Constant(camera, 0.5f), Constant(camera, 1.0f),
                            camera, options, &rng, &counts);
  EXPECT_EQ(facing.at<float>(44, 59), 0.0f);
  EXPECT_GT(facing.at<float>(0, 0), 0.0f) << "the corners see it 37 degrees off its normal";
  // Within 20 degrees: a disc of radius tan(20) * f = 36 px about the principal point.
  EXPECT_NEAR(static_cast<double>(counts.specular), M_PI * 36.4 * 36.4, 150);
  // The same wall turned by 56 degrees about the vertical axis (z = 1 + 1.5 x_cam): every pixel
  // sees it more than 20 degrees off its normal, so it is measured.
  cv::Mat turned = Constant(camera, 0);
  for (int x = 0; x < camera.width; ++x) {
    const double u = (x - camera.cx) / camera.fx;
    turned.col(x).setTo(static_cast<float>(1.0 / (1.0 - 1.5 * u)));
  }
  DepthModelCounts turned_counts;
  ApplyDepthSensorModel(turned, Constant(camera, 0.5f), Constant(camera, 1.0f), camera, options,
                        &rng, &turned_counts);
  EXPECT_EQ(turned_counts.specular, 0);
  EXPECT_GT(turned_counts.measured, camera.width * camera.height / 2);
  // A matte wall facing the camera keeps every pixel.
  DepthModelCounts matte_counts;
  ApplyDepthSensorModel(Constant(camera, 1.0f), Constant(camera, 0.5f), Constant(camera, 0.0f),
                        camera, options, &rng, &matte_counts);
  EXPECT_EQ(matte_counts.measured, camera.width * camera.height);
}

TEST(DepthSensorModel, RefusesMismatchedImagesAndBadOptions) {
  const Camera camera = SmallCamera();
  DepthSensorOptions options;
  options.camera = camera;
  std::mt19937_64 rng(1);
  const cv::Mat wrong(10, 10, CV_32FC1, cv::Scalar(1));
  EXPECT_THROW(ApplyDepthSensorModel(wrong, Constant(camera, 0.5f), Constant(camera, 0.0f), camera,
                                     options, &rng),
               InvalidArgumentError);
  DepthSensorOptions bad = options;
  bad.fps = 0;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
  bad = options;
  bad.min_range_m = 5;
  bad.max_range_m = 4;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
  bad = options;
  bad.noise_at_1m_m = -1;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
}

TEST(DepthSensor, SeesTheRoomFromItsOwnPoseWithItsOwnIntrinsics) {
  const Scene room = MakeDefaultRoom();
  DepthSensorOptions options;
  options.camera = Camera::Pinhole(160, 120, 130.0, 130.0, 79.5, 59.5);
  options.fps = 15;
  options.first_frame_t_ns = 2'000'000;
  options.noise_at_1m_m = 0.0;
  const DepthSensor sensor(room, options);
  EXPECT_EQ(sensor.FrameTimeNs(0), 2'000'000);
  EXPECT_EQ(sensor.FrameTimeNs(3), 202'000'000);
  const Eigen::Vector3d position(0.3, -1.2, 1.4);
  const Rigid3d world_from_event(
      LookAtRotation(position, Eigen::Vector3d(0.0, 0.6, 0.8), Eigen::Vector3d::UnitZ()), position);
  DepthModelCounts counts;
  const cv::Mat measured = sensor.Capture(world_from_event, 0, &counts);
  ASSERT_EQ(measured.cols, 160);
  // The exact depth of the depth camera itself (its pose: the event camera's times the
  // extrinsic), not the event camera's.
  RenderOptions render;
  render.supersampling = 1;
  const Renderer exact_renderer(room, options.camera, render);
  cv::Mat gray;
  cv::Mat exact;
  exact_renderer.Render(world_from_event * options.event_from_depth, &gray, nullptr, &exact);
  int compared = 0;
  for (int y = 0; y < exact.rows; ++y) {
    for (int x = 0; x < exact.cols; ++x) {
      if (measured.at<float>(y, x) <= 0) continue;
      EXPECT_NEAR(measured.at<float>(y, x), exact.at<float>(y, x), 0.0005 + 1e-6);
      ++compared;
    }
  }
  EXPECT_GT(compared, 160 * 120 / 2);
  EXPECT_GT(counts.discontinuity, 0) << "the table and the box occlude the wall";
  // The same index gives the same noise; another index another one.
  DepthSensorOptions noisy = options;
  noisy.noise_at_1m_m = 0.002;
  const DepthSensor noisy_sensor(room, noisy);
  const cv::Mat a = noisy_sensor.Capture(world_from_event, 5);
  const cv::Mat b = noisy_sensor.Capture(world_from_event, 5);
  const cv::Mat c = noisy_sensor.Capture(world_from_event, 6);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_INF), 0.0);
}

TEST(DepthSensor, TheVarnishedTableTopLosesItsDepthSeenFromAbove) {
  const Scene room = MakeDefaultRoom();
  DepthSensorOptions options;
  options.camera = Camera::Pinhole(160, 120, 130.0, 130.0, 79.5, 59.5);
  options.noise_at_1m_m = 0.0;
  options.event_from_depth = Rigid3d();
  const DepthSensor sensor(room, options);
  // Straight down onto the table from 0.8 m above its top.
  double table_z = 0;
  Eigen::Vector3d table_center = Eigen::Vector3d::Zero();
  for (const Surface& surface : room.surfaces) {
    if (surface.name == "table_top/+z") {
      table_z = surface.origin.z();
      table_center = surface.PointAt(0.5 * surface.width, 0.5 * surface.height);
      EXPECT_GT(surface.specular, 0.5f);
    }
  }
  ASSERT_GT(table_z, 0);
  const Eigen::Vector3d position = table_center + Eigen::Vector3d(0, 0, 0.8);
  const Rigid3d world_from_event(LookAtRotation(position, table_center, Eigen::Vector3d::UnitY()),
                                 position);
  DepthModelCounts counts;
  const cv::Mat measured = sensor.Capture(world_from_event, 0, &counts);
  EXPECT_EQ(measured.at<float>(59, 79), 0.0f) << "the mirror direction of the table top";
  EXPECT_GT(counts.specular, 1000);
}

}  // namespace
}  // namespace evloc::sim
