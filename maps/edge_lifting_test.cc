#include "maps/edge_lifting.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include "core/common/error.h"

namespace evloc {
namespace {

TEST(EdgeLifting, Gradient3dProjectsOntoTheImageGradient) {
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

TEST(EdgeLifting, RecoversTheInSurfaceGradientOfATiltedPlane) {
  // Parallel texture lines on a plane tilted away from the camera (a floor-like view); the true
  // gradient t is in the plane and perpendicular to the lines, which run along x.
  const Camera camera = Camera::Pinhole(160, 120, 100.0, 100.0, 79.5, 59.5);
  const Eigen::Vector3d origin(0.0, 0.0, 2.0);
  const Eigen::Vector3d normal = Eigen::Vector3d(0.0, 0.6, -0.8);
  const Eigen::Vector3d truth = Eigen::Vector3d(0.0, 0.8, 0.6);
  std::vector<EdgeDepthPixel> depth;
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
      EdgeDepthPixel depth_pixel;
      depth_pixel.pixel = Eigen::Vector2i(u, v);
      depth_pixel.inverse_depth = 1.0 / point.z();
      depth_pixel.gradient_direction = gradient_direction.normalized();
      depth.push_back(depth_pixel);
    }
  }
  ASSERT_GT(depth.size(), 500u);
  const std::vector<std::optional<Eigen::Vector3d>> gradients =
      SurfaceGradients3d(camera, depth, SurfaceGradientOptions());
  ASSERT_EQ(gradients.size(), depth.size());
  size_t found = 0;
  double worst_deg = 0.0;
  double worst_view_deg = 0.0;
  for (size_t i = 0; i < gradients.size(); ++i) {
    if (!gradients[i]) continue;
    ++found;
    worst_deg = std::max(worst_deg, std::acos(std::clamp(gradients[i]->dot(truth), -1.0, 1.0)));

    const Eigen::Vector3d point =
        Eigen::Vector3d(depth[i].pixel.x() - camera.cx, depth[i].pixel.y() - camera.cy, camera.fx) /
        camera.fx / depth[i].inverse_depth;
    Eigen::Vector3d view_gradient;
    ASSERT_TRUE(ComputeGradient3d(camera, depth[i].pixel.cast<double>(),
                                  depth[i].gradient_direction, point, &view_gradient));
    worst_view_deg =
        std::max(worst_view_deg, std::acos(std::clamp(view_gradient.dot(truth), -1.0, 1.0)));
  }
  EXPECT_GT(found, depth.size() / 2);

  EXPECT_LT(worst_deg * 180.0 / std::numbers::pi, 2.0);
  // The ray–plane gradient faces the camera and misses the tilt.
  EXPECT_GT(worst_view_deg * 180.0 / std::numbers::pi, 20.0);
  // Disabled: no surface gradients.
  SurfaceGradientOptions disabled;
  disabled.window_px = 0;
  for (const auto& gradient : SurfaceGradients3d(camera, depth, disabled)) {
    EXPECT_FALSE(gradient.has_value());
  }
}

// A floor-wall crease whose brighter side is the floor: the gradient lies in the floor (pointing
// from the crease towards the camera), although the wall's points are as close in the image.
// Vertical lines every 10 cm on both faces give each face its plane; the wall (facing the camera)
// alone would give the wall's in-plane direction, 90 degrees off.
TEST(EdgeLifting, ACreaseGradientLiesInTheBrighterFace) {
  const Camera camera = Camera::Pinhole(160, 120, 100.0, 100.0, 79.5, 59.5);
  const double wall_z = 2.5;
  const double floor_y = 1.0;  // seen at 22 degrees at the crease (below 17: edge-on)
  const int crease_row = static_cast<int>(std::lround(camera.cy + camera.fy * floor_y / wall_z));
  std::vector<EdgeDepthPixel> depth;
  std::vector<bool> on_crease;
  const auto add = [&](int u, int v, const Eigen::Vector3d& point, const Eigen::Vector2d& direction,
                       bool crease) {
    EdgeDepthPixel pixel;
    pixel.pixel = Eigen::Vector2i(u, v);
    pixel.inverse_depth = 1.0 / point.z();
    pixel.gradient_direction = direction.normalized();
    depth.push_back(pixel);
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
  const auto count = [&](const SurfaceGradientOptions& options, size_t* right) {
    const std::vector<std::optional<Eigen::Vector3d>> gradients =
        SurfaceGradients3d(camera, depth, options);
    size_t crease_pixels = 0;
    *right = 0;
    for (size_t i = 0; i < gradients.size(); ++i) {
      if (!on_crease[i] || depth[i].pixel.x() < 30 || depth[i].pixel.x() > 130) {
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
  const size_t crease_pixels = count(SurfaceGradientOptions(), &right);
  ASSERT_GT(crease_pixels, 50u);
  EXPECT_GT(right, crease_pixels * 9 / 10);
  // Fitting both sides mixes the two faces: no plane, or the wrong one.
  SurfaceGradientOptions both_sides;
  both_sides.edge_band_px = 1e9;
  count(both_sides, &right);
  EXPECT_LT(right, crease_pixels / 10);
}

// Lifting puts each point on its pixel's ray at its depth with the surface gradient where there is
// one and the ray–plane gradient elsewhere; pixels without depth are left out.
TEST(EdgeLifting, LiftsPixelsOntoTheirRaysWithTheirGradients) {
  const Camera camera = Camera::Pinhole(160, 120, 100.0, 100.0, 79.5, 59.5);
  // A fronto-parallel plane at 2 m with vertical lines every 10 cm (gradient along +x).
  std::vector<EdgeDepthPixel> pixels;
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; u += 5) pixels.push_back({{u, v}, 0.5, {1.0, 0.0}});
  }
  pixels.push_back({{10, 10}, 0.0, {1.0, 0.0}});  // no depth
  const std::vector<std::optional<LiftedEdgePoint>> lifted =
      LiftEdgePixels(camera, pixels, SurfaceGradientOptions());
  ASSERT_EQ(lifted.size(), pixels.size());
  EXPECT_FALSE(lifted.back().has_value());
  size_t surface = 0;
  for (size_t i = 0; i + 1 < pixels.size(); ++i) {
    ASSERT_TRUE(lifted[i].has_value()) << i;
    const LiftedEdgePoint& point = *lifted[i];
    EXPECT_NEAR(point.point_in_cam.z(), 2.0, 1e-12);
    Eigen::Vector2d projected;
    ASSERT_TRUE(camera.Project(point.point_in_cam, &projected));
    EXPECT_LT((projected - pixels[i].pixel.cast<double>()).norm(), 1e-9);
    EXPECT_NEAR(point.gradient_in_cam.norm(), 1.0, 1e-12);
    if (point.surface_gradient) {
      // On a fronto-parallel plane the in-surface gradient is +x, like the image gradient.
      EXPECT_GT(point.gradient_in_cam.x(), 1.0 - 1e-9);
      ++surface;
    } else {
      // Near the right border no points lie on the brighter side: the ray–plane gradient, which is
      // perpendicular to the viewing ray.
      EXPECT_NEAR(point.gradient_in_cam.dot(point.point_in_cam.normalized()), 0.0, 1e-9);
    }
  }
  EXPECT_GT(surface, pixels.size() / 2);
  // Without surface windows every gradient is the ray–plane one.
  SurfaceGradientOptions disabled;
  disabled.window_px = 0;
  const std::vector<std::optional<LiftedEdgePoint>> view = LiftEdgePixels(camera, pixels, disabled);
  for (size_t i = 0; i + 1 < pixels.size(); ++i) {
    ASSERT_TRUE(view[i].has_value());
    EXPECT_FALSE(view[i]->surface_gradient);
    Eigen::Vector3d expected;
    ASSERT_TRUE(ComputeGradient3d(camera, pixels[i].pixel.cast<double>(),
                                  pixels[i].gradient_direction, view[i]->point_in_cam, &expected));
    EXPECT_TRUE(view[i]->gradient_in_cam.isApprox(expected, 1e-12));
  }
  disabled.min_points = 2;
  EXPECT_THROW(LiftEdgePixels(camera, pixels, disabled), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc
