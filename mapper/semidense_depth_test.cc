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

TEST(SemiDenseDepth, Gradient3dProjectsOntoTheImageGradient) {
  const Camera camera = Camera::Pinhole(640, 480, 500.0, 500.0, 319.5, 239.5);
  // Fronto-parallel point on the optical axis: the 3D gradient is the image gradient.
  Eigen::Vector3d gradient;
  ASSERT_TRUE(ComputeGradient3d(camera, {319.5, 239.5}, {1.0, 0.0}, {0.0, 0.0, 2.0}, &gradient));
  EXPECT_TRUE(gradient.isApprox(Eigen::Vector3d::UnitX(), 1e-9));
  // Off-axis: projecting P and P + s g gives the image gradient direction, and g is
  // perpendicular to the viewing ray.
  std::mt19937 random(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::Vector2d pixel(320 + 250 * uniform(random), 240 + 200 * uniform(random));
    const Eigen::Vector2d direction =
        Eigen::Vector2d(uniform(random), uniform(random)).normalized();
    Eigen::Vector3d ray;
    ASSERT_TRUE(camera.Unproject(pixel, &ray));
    const Eigen::Vector3d point = ray * (1.0 + 2.0 * std::abs(uniform(random)));
    ASSERT_TRUE(ComputeGradient3d(camera, pixel, direction, point, &gradient));
    EXPECT_NEAR(gradient.norm(), 1.0, 1e-12);
    EXPECT_NEAR(gradient.dot(point.normalized()), 0.0, 1e-9);
    Eigen::Vector2d start;
    Eigen::Vector2d end;
    ASSERT_TRUE(camera.Project(point, &start));
    ASSERT_TRUE(camera.Project(point + 1e-4 * gradient, &end));
    EXPECT_GT((end - start).normalized().dot(direction), 1.0 - 1e-6);
  }
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

namespace evloc::mapper {
namespace {

TEST(SurfaceGradients3d, RecoversTheInSurfaceGradientOfATiltedPlane) {
  // Parallel texture lines on a plane tilted away from the camera (a floor-like view); the true
  // gradient t is in the plane and perpendicular to the lines, which run along x.
  const Camera camera = Camera::Pinhole(160, 120, 100.0, 100.0, 79.5, 59.5);
  const Eigen::Vector3d origin(0.0, 0.0, 2.0);
  const Eigen::Vector3d normal = Eigen::Vector3d(0.0, 0.6, -0.8);
  const Eigen::Vector3d truth = Eigen::Vector3d(0.0, 0.8, 0.6);
  KeyframeDepth depth;
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      Eigen::Vector3d ray;
      ASSERT_TRUE(camera.Unproject(Eigen::Vector2d(u, v), &ray));
      const double scale = normal.dot(origin) / normal.dot(ray);
      const Eigen::Vector3d point = scale * ray;
      const double across = (point - origin).dot(truth);
      // Lines every 5 cm, one pixel wide.
      const double footprint = point.z() / camera.fx * 1.5;
      const double offset = across - 0.05 * std::round(across / 0.05);
      if (std::abs(offset) > 0.5 * footprint) continue;
      // The image gradient is perpendicular to the projected line, towards the projected t.
      Eigen::Vector2d pixel;
      Eigen::Vector2d along;
      Eigen::Vector2d tip;
      ASSERT_TRUE(camera.Project(point, &pixel));
      ASSERT_TRUE(camera.Project(point + 1e-3 * Eigen::Vector3d::UnitX(), &along));
      ASSERT_TRUE(camera.Project(point + 1e-3 * truth, &tip));
      Eigen::Vector2d gradient_direction(-(along - pixel).y(), (along - pixel).x());
      if (gradient_direction.dot(tip - pixel) < 0.0) gradient_direction = -gradient_direction;
      DepthPixel depth_pixel;
      depth_pixel.pixel = Eigen::Vector2i(u, v);
      depth_pixel.inverse_depth = 1.0 / point.z();
      depth_pixel.gradient_direction = gradient_direction.normalized();
      depth.pixels.push_back(depth_pixel);
    }
  }
  ASSERT_GT(depth.pixels.size(), 500u);
  const std::vector<std::optional<Eigen::Vector3d>> gradients =
      SurfaceGradients3d(camera, depth, SemiDenseOptions());
  ASSERT_EQ(gradients.size(), depth.pixels.size());
  size_t found = 0;
  double worst_deg = 0.0;
  double worst_view_deg = 0.0;
  for (size_t i = 0; i < gradients.size(); ++i) {
    if (!gradients[i]) continue;
    ++found;
    worst_deg = std::max(worst_deg, std::acos(std::clamp(gradients[i]->dot(truth), -1.0, 1.0)));

    const Eigen::Vector3d point =
        Eigen::Vector3d(depth.pixels[i].pixel.x() - camera.cx,
                        depth.pixels[i].pixel.y() - camera.cy, camera.fx) /
        camera.fx / depth.pixels[i].inverse_depth;
    Eigen::Vector3d view_gradient;
    ASSERT_TRUE(ComputeGradient3d(camera, depth.pixels[i].pixel.cast<double>(),
                                  depth.pixels[i].gradient_direction, point, &view_gradient));
    worst_view_deg =
        std::max(worst_view_deg, std::acos(std::clamp(view_gradient.dot(truth), -1.0, 1.0)));
  }
  EXPECT_GT(found, depth.pixels.size() / 2);

  EXPECT_LT(worst_deg * 180.0 / std::numbers::pi, 2.0);
  // The §3.4 gradient faces the camera and misses the tilt.
  EXPECT_GT(worst_view_deg * 180.0 / std::numbers::pi, 20.0);
  // Disabled: no surface gradients.
  SemiDenseOptions disabled;
  disabled.surface_window_px = 0;
  for (const auto& gradient : SurfaceGradients3d(camera, depth, disabled)) {
    EXPECT_FALSE(gradient.has_value());
  }
}

// A floor-wall crease whose brighter side is the floor: the gradient lies in the floor (pointing
// from the crease towards the camera), although the wall's points are as close in the image.
// Vertical lines every 10 cm on both faces give each face its plane; the wall (facing the camera)
// alone would give the wall's in-plane direction, 90 degrees off.
TEST(SurfaceGradients3d, ACreaseGradientLiesInTheBrighterFace) {
  const Camera camera = Camera::Pinhole(160, 120, 100.0, 100.0, 79.5, 59.5);
  const double wall_z = 2.5;
  const double floor_y = 1.0;  // seen at 22 degrees at the crease (below 17: edge-on)
  const int crease_row = static_cast<int>(std::lround(camera.cy + camera.fy * floor_y / wall_z));
  KeyframeDepth depth;
  std::vector<bool> on_crease;
  const auto add = [&](int u, int v, const Eigen::Vector3d& point, const Eigen::Vector2d& direction,
                       bool crease) {
    DepthPixel pixel;
    pixel.pixel = Eigen::Vector2i(u, v);
    pixel.inverse_depth = 1.0 / point.z();
    pixel.gradient_direction = direction.normalized();
    depth.pixels.push_back(pixel);
    on_crease.push_back(crease);
  };
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      Eigen::Vector3d ray;
      ASSERT_TRUE(camera.Unproject(Eigen::Vector2d(u, v), &ray));
      if (v == crease_row) {
        // The crease: brighter below (the floor).
        add(u, v, ray * (wall_z / ray.z()), Eigen::Vector2d(0.0, 1.0), true);
        continue;
      }
      // Wall above the crease row, floor below.
      const Eigen::Vector3d point =
          v < crease_row ? ray * (wall_z / ray.z()) : ray * (floor_y / ray.y());
      const double footprint = point.z() / camera.fx * 1.5;
      const double offset = point.x() - 0.1 * std::round(point.x() / 0.1);
      if (std::abs(offset) > 0.5 * footprint) continue;
      // A line along the face's vertical (wall) or depth (floor) direction; the image gradient is
      // perpendicular to its projection.
      const Eigen::Vector3d along =
          v < crease_row ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitZ();
      Eigen::Vector2d pixel;
      Eigen::Vector2d next;
      ASSERT_TRUE(camera.Project(point, &pixel));
      ASSERT_TRUE(camera.Project(point + 1e-3 * along, &next));
      add(u, v, point, Eigen::Vector2d(-(next - pixel).y(), (next - pixel).x()), false);
    }
  }
  const Eigen::Vector3d truth(0.0, 0.0, -1.0);  // in the floor, from the crease to the camera
  // Crease pixels away from the image border, and how many got a gradient within 2 degrees.
  const auto count = [&](const SemiDenseOptions& options, size_t* right) {
    const std::vector<std::optional<Eigen::Vector3d>> gradients =
        SurfaceGradients3d(camera, depth, options);
    size_t crease_pixels = 0;
    *right = 0;
    for (size_t i = 0; i < gradients.size(); ++i) {
      if (!on_crease[i] || depth.pixels[i].pixel.x() < 30 || depth.pixels[i].pixel.x() > 130) {
        continue;
      }
      ++crease_pixels;
      if (gradients[i] && gradients[i]->dot(truth) > std::cos(2.0 * std::numbers::pi / 180.0)) {
        ++*right;
      }
    }
    return crease_pixels;
  };
  size_t right = 0;
  const size_t crease_pixels = count(SemiDenseOptions(), &right);
  ASSERT_GT(crease_pixels, 50u);
  EXPECT_GT(right, crease_pixels * 9 / 10);
  // Fitting both sides mixes the two faces: no plane, or the wrong one.
  SemiDenseOptions both_sides;
  both_sides.surface_edge_band_px = 1e9;
  count(both_sides, &right);
  EXPECT_LT(right, crease_pixels / 10);
}

}  // namespace
}  // namespace evloc::mapper
