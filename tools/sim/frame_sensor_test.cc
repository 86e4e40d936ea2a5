#include "tools/sim/frame_sensor.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

TEST(ExposureIntegrator, AveragesARampOverTheWindow) {
  // Radiance rising linearly from 0.2 to 0.6 over the window: the mean is 0.4.
  ExposureIntegrator integrator(1'000'000, 11'000'000);
  for (int i = 0; i <= 10; ++i) {
    integrator.Add(cv::Mat(2, 2, CV_32FC1, cv::Scalar(0.2 + 0.04 * i)), 1'000'000 + i * 1'000'000);
  }
  ASSERT_TRUE(integrator.complete());
  EXPECT_NEAR(integrator.Mean().at<float>(1, 1), 0.4, 1e-6);
  ExposureIntegrator late(0, 10);
  EXPECT_THROW(late.Add(cv::Mat(2, 2, CV_32FC1, cv::Scalar(0)), 1), InvalidArgumentError);
}

TEST(ExposureIntegrator, MovingEdgeIsBlurredOverItsPath) {
  // A bright half-plane whose edge moves 8 px during the exposure: pixels crossed by the edge
  // get intermediate values proportional to the time they were lit.
  const int width = 32;
  ExposureIntegrator integrator(0, 8'000'000);
  for (int step = 0; step <= 80; ++step) {
    cv::Mat image(1, width, CV_32FC1, cv::Scalar(0));
    const double edge = 10 + step * 0.1;
    for (int col = 0; col < width; ++col) image.at<float>(0, col) = col < edge ? 1.0f : 0.0f;
    integrator.Add(image, step * 100'000);
  }
  const cv::Mat mean = integrator.Mean();
  EXPECT_NEAR(mean.at<float>(0, 5), 1.0, 1e-5);
  EXPECT_NEAR(mean.at<float>(0, 25), 0.0, 1e-5);
  EXPECT_NEAR(mean.at<float>(0, 14), 0.5, 0.03);  // lit for the last half of the exposure
}

TEST(FrameSensor, NoiseFreeExposureIsLinearAndClips) {
  FrameSensorOptions options;
  options.noise = false;
  options.exposure_s = 0.01;
  options.electrons_per_second = 1e6;
  options.gain_dn_per_electron = 255.0 / 10000;
  FrameSensor sensor(options);
  cv::Mat radiance(1, 3, CV_32FC1);
  radiance.at<float>(0, 0) = 0.4f;
  radiance.at<float>(0, 1) = 1.0f;
  radiance.at<float>(0, 2) = 3.0f;
  const cv::Mat image = sensor.Expose(radiance);
  EXPECT_EQ(image.at<uint8_t>(0, 0), 102);  // 4000 e- * 0.0255 = 102
  EXPECT_EQ(image.at<uint8_t>(0, 1), 255);
  EXPECT_EQ(image.at<uint8_t>(0, 2), 255);  // full well
}

TEST(FrameSensor, ShotNoiseMatchesPoissonStatistics) {
  FrameSensorOptions options;
  options.exposure_s = 0.01;
  options.electrons_per_second = 1e4;  // radiance 1 -> 100 electrons
  options.gain_dn_per_electron = 1.0;
  options.read_noise_electrons = 0;
  FrameSensor sensor(options);
  const cv::Mat image = sensor.Expose(cv::Mat(200, 200, CV_32FC1, cv::Scalar(1.0)));
  cv::Scalar mean;
  cv::Scalar deviation;
  cv::meanStdDev(image, mean, deviation);
  EXPECT_NEAR(mean[0], 100, 0.3);
  EXPECT_NEAR(deviation[0], 10, 0.3);
}

TEST(LightingPreset, DarkFramesAreNoisierRelativeToSignalThanBright) {
  const Eigen::AlignedBox3d bounds(Eigen::Vector3d(-2, -2, 0), Eigen::Vector3d(2, 2, 2.5));
  double relative_noise[2];
  int index = 0;
  for (LightingCondition condition : {LightingCondition::kBright, LightingCondition::kDark}) {
    const LightingPreset preset = MakeLightingPreset(condition, bounds);
    FrameSensor sensor(preset.frames);
    cv::Mat radiance(100, 100, CV_32FC1, cv::Scalar(0.3 * preset.illumination.lit_factor));
    cv::Scalar mean;
    cv::Scalar deviation;
    cv::meanStdDev(sensor.Expose(radiance), mean, deviation);
    EXPECT_NEAR(mean[0], 0.3 * 255, 2.0) << LightingConditionName(condition);
    relative_noise[index++] = deviation[0] / mean[0];
  }
  EXPECT_GT(relative_noise[1], 3 * relative_noise[0]);
}

TEST(Illumination, HdrSplitsLitAndShadowedHalves) {
  const LightingPreset preset =
      MakeLightingPreset(LightingCondition::kHdr,
                         Eigen::AlignedBox3d(Eigen::Vector3d(-2, -2, 0), Eigen::Vector3d(2, 2, 2)));
  EXPECT_NEAR(preset.illumination.FactorAt(Eigen::Vector3d(1.5, 0, 1)), 4.0, 1e-6);
  EXPECT_NEAR(preset.illumination.FactorAt(Eigen::Vector3d(-1.5, 0, 1)), 0.04, 1e-6);
  // A camera at the origin looking along +x sees a wall at x = 1 (lit): every pixel is scaled 4x.
  const Camera camera = Camera::Pinhole(8, 6, 10, 10, 3.5, 2.5);
  const Rigid3d world_from_cam(
      Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY())),
      Eigen::Vector3d(0, 0, 1));
  cv::Mat image(6, 8, CV_32FC1, cv::Scalar(0.1));
  const cv::Mat depth(6, 8, CV_32FC1, cv::Scalar(1.0));
  ApplyIllumination(preset.illumination, ComputeRayTable(camera), world_from_cam, depth, &image);
  EXPECT_NEAR(image.at<float>(3, 4), 0.4, 1e-5);
}

}  // namespace
}  // namespace evloc::sim
