#include "mapper/semidense_depth.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"

namespace evloc::mapper {
namespace {

// A textured plane z = kPlaneDepth + kPlaneSlope * x in the world, rendered by ray casting.
constexpr double kPlaneDepth = 2.0;
constexpr double kPlaneSlope = 0.2;

cv::Mat MakeTexture() {
  std::mt19937 random(7);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  cv::Mat texture(600, 600, CV_32F, cv::Scalar(0.5));
  for (int i = 0; i < 140; ++i) {
    const cv::Point center(static_cast<int>(uniform(random) * 600),
                           static_cast<int>(uniform(random) * 600));
    const double value = 0.1 + 0.8 * uniform(random);
    if (i % 2 == 0) {
      cv::circle(texture, center, 8 + static_cast<int>(uniform(random) * 30), cv::Scalar(value),
                 cv::FILLED, cv::LINE_AA);
    } else {
      const cv::Size size(10 + static_cast<int>(uniform(random) * 50),
                          10 + static_cast<int>(uniform(random) * 50));
      cv::rectangle(texture, cv::Rect(center, size), cv::Scalar(value), cv::FILLED);
    }
  }
  cv::GaussianBlur(texture, texture, cv::Size(0, 0), 1.2);
  return texture;
}

// World x, y in [-1.5, 1.5] map onto the texture.
double TexelOf(double world) { return (world + 1.5) * 200.0; }

// Ray-plane distance along a camera ray with z = 1 (the depth), for world_from_cam.
double DepthOnPlane(const Rigid3d& world_from_cam, const Eigen::Vector3d& ray_in_cam) {
  const Eigen::Vector3d center = world_from_cam.translation;
  const Eigen::Vector3d direction = world_from_cam.rotation * ray_in_cam;
  return (kPlaneDepth + kPlaneSlope * center.x() - center.z()) /
         (direction.z() - kPlaneSlope * direction.x());
}

cv::Mat Render(const Camera& camera, const Rigid3d& cam_from_world, const cv::Mat& texture) {
  const Rigid3d world_from_cam = cam_from_world.Inverse();
  cv::Mat map_x(camera.height, camera.width, CV_32F);
  cv::Mat map_y(camera.height, camera.width, CV_32F);
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      Eigen::Vector3d ray;
      EXPECT_TRUE(camera.Unproject(Eigen::Vector2d(u, v), &ray));
      const Eigen::Vector3d point = world_from_cam * (ray * DepthOnPlane(world_from_cam, ray));
      map_x.at<float>(v, u) = static_cast<float>(TexelOf(point.x()));
      map_y.at<float>(v, u) = static_cast<float>(TexelOf(point.y()));
    }
  }
  cv::Mat rendered;
  cv::remap(texture, rendered, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  cv::Mat image;
  rendered.convertTo(image, CV_8U, 255.0);
  return image;
}

Rigid3d CamFromWorld(const Eigen::Vector3d& center, const Eigen::Vector3d& rotation_vector) {
  return Rigid3d(ExpSO3(rotation_vector), center).Inverse();
}

struct SyntheticRig {
  Camera camera = Camera::Pinhole(320, 240, 300.0, 300.0, 159.5, 119.5);
  std::vector<DepthFrame> frames;
};

SyntheticRig MakeRig(const SemiDenseOptions& options) {
  SyntheticRig rig;
  const cv::Mat texture = MakeTexture();
  const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> poses = {
      {{0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}},        {{0.15, 0.0, 0.0}, {0.0, -0.02, 0.0}},
      {{-0.15, 0.02, 0.0}, {0.0, 0.02, 0.01}},   {{0.0, 0.15, 0.05}, {0.02, 0.0, 0.0}},
      {{0.02, -0.14, 0.0}, {-0.02, 0.0, -0.01}}, {{0.11, 0.11, -0.05}, {0.01, -0.01, 0.02}}};
  for (const auto& [center, rotation] : poses) {
    const Rigid3d cam_from_world = CamFromWorld(center, rotation);
    rig.frames.push_back(MakeDepthFrame(Render(rig.camera, cam_from_world, texture), rig.camera,
                                        cam_from_world, options));
  }
  return rig;
}

// Relative errors of the estimated depths against the plane.
std::vector<double> RelativeDepthErrors(const DepthFrame& frame, const KeyframeDepth& depth) {
  std::vector<double> errors;
  const Rigid3d world_from_cam = frame.cam_from_world.Inverse();
  for (const DepthPixel& pixel : depth.pixels) {
    Eigen::Vector3d ray;
    EXPECT_TRUE(frame.camera.Unproject(pixel.pixel.cast<double>(), &ray));
    const double truth = DepthOnPlane(world_from_cam, ray);
    errors.push_back(std::abs(1.0 / pixel.inverse_depth - truth) / truth);
  }
  std::sort(errors.begin(), errors.end());
  return errors;
}

TEST(SemiDenseDepth, RecoversTexturedPlane) {
  SemiDenseOptions options;
  const SyntheticRig rig = MakeRig(options);
  std::vector<const DepthFrame*> neighbours;
  for (size_t i = 1; i < rig.frames.size(); ++i) neighbours.push_back(&rig.frames[i]);
  const KeyframeDepth depth = EstimateKeyframeDepth(rig.frames[0], neighbours, 1.3, 3.2, options);
  ASSERT_GT(depth.num_candidates, 1000u);
  // Most edge pixels get a depth.
  EXPECT_GT(depth.pixels.size(), depth.num_candidates / 3);
  const std::vector<double> errors = RelativeDepthErrors(rig.frames[0], depth);
  ASSERT_FALSE(errors.empty());
  EXPECT_LT(errors[errors.size() / 2], 0.005);
  EXPECT_LT(errors[errors.size() * 9 / 10], 0.02);
  for (const DepthPixel& pixel : depth.pixels) {
    EXPECT_GT(pixel.inverse_depth_variance, 0.0);
    EXPECT_NEAR(pixel.gradient_direction.norm(), 1.0, 1e-9);
  }
}

TEST(SemiDenseDepth, SingleNeighbourCannotFormACompatibleSet) {
  SemiDenseOptions options;
  const SyntheticRig rig = MakeRig(options);
  const KeyframeDepth depth =
      EstimateKeyframeDepth(rig.frames[0], {&rig.frames[1]}, 1.3, 3.2, options);
  EXPECT_GT(depth.num_candidates, 1000u);
  EXPECT_EQ(depth.num_fused, 0u);
}

TEST(SemiDenseDepth, ConsistencyKeepsConfirmedPointsAndRefinesThem) {
  SemiDenseOptions options;
  const SyntheticRig rig = MakeRig(options);
  std::vector<const DepthFrame*> keyframes;
  std::vector<KeyframeDepth> depths;
  for (size_t k = 0; k < 3; ++k) {
    keyframes.push_back(&rig.frames[k]);
    std::vector<const DepthFrame*> neighbours;
    for (size_t i = 0; i < rig.frames.size(); ++i) {
      if (i != k) neighbours.push_back(&rig.frames[i]);
    }
    depths.push_back(EstimateKeyframeDepth(rig.frames[k], neighbours, 1.3, 3.2, options));
  }
  const size_t before = depths[0].pixels.size();
  // Corrupt one keyframe's estimate: a point 20 % off must lose its confirmations.
  depths[0].pixels[before / 2].inverse_depth *= 1.2;
  const Eigen::Vector2i corrupted = depths[0].pixels[before / 2].pixel;
  EnforceInterKeyframeConsistency(keyframes, {{1, 2}, {0, 2}, {0, 1}}, options, &depths);
  EXPECT_GT(depths[0].pixels.size(), before / 3);
  EXPECT_LT(depths[0].pixels.size(), before);
  for (const DepthPixel& pixel : depths[0].pixels) {
    EXPECT_NE(pixel.pixel, corrupted);
    EXPECT_GE(pixel.confirming_keyframes.size(), 2u);
  }
  const std::vector<double> errors = RelativeDepthErrors(rig.frames[0], depths[0]);
  ASSERT_FALSE(errors.empty());
  EXPECT_LT(errors[errors.size() / 2], 0.004);
  EXPECT_LT(errors.back(), 0.05);
}

TEST(SemiDenseDepth, SparseDepthRangeUsesPercentilesAndMargin) {
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 100; ++i) points.emplace_back(0.0, 0.0, 1.0 + 0.01 * i);
  points.emplace_back(0.0, 0.0, -5.0);  // behind: ignored
  double min_depth = 0.0;
  double max_depth = 0.0;
  ASSERT_TRUE(SparseDepthRange(Rigid3d(), points, 1.25, &min_depth, &max_depth));
  EXPECT_NEAR(min_depth, 1.01 / 1.25, 1e-9);
  EXPECT_NEAR(max_depth, 1.98 * 1.25, 1e-9);
  EXPECT_FALSE(SparseDepthRange(Rigid3d(), {{0, 0, 1}, {0, 0, 2}}, 1.25, &min_depth, &max_depth));
}

TEST(SemiDenseDepth, OptionsAreChecked) {
  SemiDenseOptions options;
  EXPECT_NO_THROW(options.Check());
  options.min_compatible_hypotheses = 0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = SemiDenseOptions();
  options.canny_high_threshold = 1.0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::mapper
