#include "tools/sim/renderer.h"

#include <chrono>
#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

// A fronto-parallel-ish white quad (albedo 1, shading 1) on a black background.
Scene SingleQuadScene(const Eigen::Vector3d& origin, const Eigen::Vector3d& u_axis,
                      const Eigen::Vector3d& v_axis, double width, double height) {
  Scene scene;
  scene.name = "quad";
  Surface surface;
  surface.name = "quad";
  surface.origin = origin;
  surface.u_axis = u_axis.normalized();
  surface.v_axis = (v_axis - v_axis.dot(surface.u_axis) * surface.u_axis).normalized();
  surface.width = width;
  surface.height = height;
  surface.texture.base = Gray(1.0f);
  scene.surfaces.push_back(surface);
  scene.UpdateBounds();
  scene.camera_region = Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 0));
  return scene;
}

// Finds the x where the projected 3D segment a-b crosses image row y (bisection on the segment
// parameter; the segment must cross the row once).
double ProjectedCrossingX(const Camera& camera, const Rigid3d& cam_from_world,
                          const Eigen::Vector3d& a, const Eigen::Vector3d& b, double y) {
  auto pixel_at = [&](double s) {
    Eigen::Vector2d pixel;
    EXPECT_TRUE(camera.Project(cam_from_world * (a + s * (b - a)), &pixel));
    return pixel;
  };
  double low = 0, high = 1;
  const bool increasing = pixel_at(1).y() > pixel_at(0).y();
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (low + high);
    if ((pixel_at(mid).y() < y) == increasing) {
      low = mid;
    } else {
      high = mid;
    }
  }
  return pixel_at(0.5 * (low + high)).x();
}

// Renders a tilted white quad and checks that its left edge, located per row to sub-pixel
// precision from the anti-aliased coverage, lies where the camera model projects it, and that
// the corner found by intersecting the measured edges lies where the 3D corner projects.
void CheckEdgesAndCorner(const Camera& camera) {
  const Scene scene =
      SingleQuadScene(Eigen::Vector3d(-0.3, -0.25, 2.0), Eigen::Vector3d(1, 0.05, 0.1),
                      Eigen::Vector3d(-0.06, 1, 0.2), 0.6, 0.5);
  RenderOptions options;
  options.supersampling = 8;
  const Renderer renderer(scene, camera, options);
  const Rigid3d world_from_cam(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.03, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(0.02, -0.01, 0));
  const Rigid3d cam_from_world = world_from_cam.Inverse();
  cv::Mat gray;
  renderer.Render(world_from_cam, &gray);
  const Surface& quad = scene.surfaces[0];
  const auto corners = quad.Corners();  // (0,0) (w,0) (w,h) (0,h)
  // Left edge: corners[0] -> corners[3]; top edge (smallest v): corners[0] -> corners[1].
  Eigen::Vector2d corner_pixel;
  ASSERT_TRUE(camera.Project(cam_from_world * corners[0], &corner_pixel));
  double max_error = 0;
  std::vector<Eigen::Vector2d> left_points;
  for (int y = static_cast<int>(corner_pixel.y()) + 3; y < static_cast<int>(corner_pixel.y()) + 20;
       ++y) {
    const double expected = ProjectedCrossingX(camera, cam_from_world, corners[0], corners[3], y);
    const int outside = static_cast<int>(std::floor(expected)) - 3;
    const int inside = static_cast<int>(std::floor(expected)) + 3;
    double covered = 0;
    for (int x = outside; x <= inside; ++x) covered += gray.at<float>(y, x);
    const double measured = inside + 0.5 - covered;
    max_error = std::max(max_error, std::abs(measured - expected));
    left_points.emplace_back(measured, y);
  }
  EXPECT_LT(max_error, 0.15);
  // Top edge, per column.
  std::vector<Eigen::Vector2d> top_points;
  Eigen::Vector2d right_pixel;
  ASSERT_TRUE(camera.Project(cam_from_world * corners[1], &right_pixel));
  for (int x = static_cast<int>(corner_pixel.x()) + 3; x < static_cast<int>(corner_pixel.x()) + 25;
       ++x) {
    int y_outside = static_cast<int>(corner_pixel.y()) - 8;
    double covered = 0;
    for (int y = y_outside; y <= y_outside + 20; ++y) covered += gray.at<float>(y, x);
    top_points.emplace_back(x, y_outside + 20 + 0.5 - covered);
  }
  // Fit lines (least squares) and intersect.
  auto fit = [](const std::vector<Eigen::Vector2d>& points, bool x_of_y) {
    // Returns (slope, intercept) of x = a*y + b (x_of_y) or y = a*x + b.
    double sxx = 0, sx = 0, sxy = 0, sy = 0;
    for (const auto& p : points) {
      const double t = x_of_y ? p.y() : p.x(), value = x_of_y ? p.x() : p.y();
      sxx += t * t;
      sx += t;
      sxy += t * value;
      sy += value;
    }
    const double n = static_cast<double>(points.size());
    const double slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    return Eigen::Vector2d(slope, (sy - slope * sx) / n);
  };
  const Eigen::Vector2d left = fit(left_points, true), top = fit(top_points, false);
  // x = l0 y + l1, y = t0 x + t1.
  const double x = (left[0] * top[1] + left[1]) / (1 - left[0] * top[0]);
  const double y = top[0] * x + top[1];
  EXPECT_LT((Eigen::Vector2d(x, y) - corner_pixel).norm(), camera.distortion.empty() ? 0.2 : 0.5)
      << "measured " << x << " " << y << " projected " << corner_pixel.transpose();
}

TEST(Renderer, EdgesAndCornerLandWherePinholeProjects) {
  CheckEdgesAndCorner(Camera::Pinhole(160, 120, 110, 110, 79.5, 59.5));
}

TEST(Renderer, EdgesAndCornerLandWhereDistortedCameraProjects) {
  Camera camera = Camera::Pinhole(160, 120, 110, 110, 79.5, 59.5);
  camera.model = CameraModel::kRadialTangential;
  camera.distortion = {-0.25, 0.08, 0.001, -0.0005, 0.0};
  CheckEdgesAndCorner(camera);
}

TEST(Renderer, BoxInFrontHidesTheWallAndDepthIsExact) {
  Scene scene;
  scene.name = "occlusion";
  Surface wall;
  wall.name = "wall";
  wall.origin = Eigen::Vector3d(-3, -3, 3);
  wall.u_axis = Eigen::Vector3d::UnitX();
  wall.v_axis = Eigen::Vector3d::UnitY();
  wall.width = wall.height = 6;
  wall.shading = 0.2f;
  wall.texture.base = Gray(1.0f);
  scene.surfaces.push_back(wall);
  BoxSpec box;
  box.name = "box";
  box.center = Eigen::Vector3d(0, 0, 1.5);
  box.size = Eigen::Vector3d(0.4, 0.4, 0.4);
  box.face_textures.fill(Texture{Gray(0.9f), {}});
  AddBox(box, &scene);
  scene.UpdateBounds();
  scene.camera_region =
      Eigen::AlignedBox3d(Eigen::Vector3d(-0.1, -0.1, -0.1), Eigen::Vector3d(0.1, 0.1, 0.1));
  const Camera camera = Camera::Pinhole(120, 90, 100, 100, 59.5, 44.5);
  const Renderer renderer(scene, camera);
  cv::Mat gray, depth, rgb;
  renderer.Render(Rigid3d::Identity(), &gray, &rgb, &depth);
  // Centre: the box's front face (-z, facing the camera) at z = 1.3, albedo 0.9 times its shading.
  const float box_shading = scene.surfaces[6].shading;  // the -z face
  EXPECT_NEAR(depth.at<float>(44, 59), 1.3, 1e-5);
  EXPECT_NEAR(gray.at<float>(44, 59), 0.9 * box_shading, 1e-5);
  EXPECT_NEAR(rgb.at<cv::Vec3f>(44, 59)[1], 0.9 * box_shading, 1e-5);
  // Corner of the image: the wall at z = 3, shading 0.2.
  EXPECT_NEAR(depth.at<float>(2, 2), 3.0, 1e-5);
  EXPECT_NEAR(gray.at<float>(2, 2), 0.2, 1e-6);
  // The box covers exactly its projected square: 0.4 m at 1.3 m = 30.77 px wide.
  double covered = 0;
  for (int x = 0; x < 120; ++x)
    covered += (gray.at<float>(44, x) - 0.2) / (0.9 * box_shading - 0.2);
  EXPECT_NEAR(covered, 100 * 0.4 / 1.3, 2 * 0.5 / 3);  // each edge within half a sub-sample
  // Depth everywhere equals the analytic ray-plane z of the surface hit.
  for (int y = 0; y < 90; y += 7) {
    for (int x = 0; x < 120; x += 7) {
      const Eigen::Vector3d ray((x - 59.5) / 100, (y - 44.5) / 100, 1);
      const auto hit = CastRay(scene, Eigen::Vector3d::Zero(), ray);
      ASSERT_TRUE(hit.has_value());
      EXPECT_NEAR(depth.at<float>(y, x), hit->distance, 1e-5 * hit->distance);
    }
  }
}

TEST(Renderer, TiltedPlaneDepthMatchesRayPlaneDistance) {
  const Scene scene = SingleQuadScene(Eigen::Vector3d(-5, -5, 2), Eigen::Vector3d(1, 0, 0.3),
                                      Eigen::Vector3d(0, 1, 0), 10, 10);
  Camera camera = Camera::Pinhole(100, 80, 90, 90, 49.5, 39.5);
  camera.model = CameraModel::kEquidistant;
  camera.distortion = {0.05, -0.01, 0.002, 0.0};
  const Renderer renderer(scene, camera);
  const Rigid3d world_from_cam(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX())),
                               Eigen::Vector3d(0.1, 0.2, -0.3));
  cv::Mat gray, depth;
  renderer.Render(world_from_cam, &gray, nullptr, &depth);
  const Surface& plane = scene.surfaces[0];
  const Rigid3d cam_from_world = world_from_cam.Inverse();
  const Eigen::Vector3d normal = cam_from_world.rotation * plane.Normal();
  const double offset = normal.dot(cam_from_world * plane.origin);
  double max_relative_error = 0;
  for (int y = 0; y < 80; ++y) {
    for (int x = 0; x < 100; ++x) {
      Eigen::Vector3d ray;
      ASSERT_TRUE(camera.Unproject(Eigen::Vector2d(x, y), &ray));
      const double z = offset / normal.dot(ray / ray.z());
      max_relative_error = std::max(max_relative_error, std::abs(depth.at<float>(y, x) - z) / z);
    }
  }
  EXPECT_LT(max_relative_error, 1e-6);
}

TEST(Renderer, DefaultRoomRendersDeterministicallyInParallelAndSerially) {
  const Scene room = MakeDefaultRoom();
  const Camera camera = Camera::Pinhole(160, 120, 80, 80, 79.5, 59.5);
  RenderOptions serial_options;
  serial_options.parallel = false;
  const Renderer parallel(room, camera), serial(room, camera, serial_options);
  const Eigen::Vector3d position = room.camera_region.center();
  // Look towards the north wall (world +y), camera y down = world -z.
  Eigen::Matrix3d world_from_cam_rotation;
  world_from_cam_rotation.col(0) = Eigen::Vector3d::UnitX();
  world_from_cam_rotation.col(1) = -Eigen::Vector3d::UnitZ();
  world_from_cam_rotation.col(2) = Eigen::Vector3d::UnitY();
  const Rigid3d pose(Eigen::Quaterniond(world_from_cam_rotation), position);
  cv::Mat a, b, depth;
  RenderStats stats;
  parallel.Render(pose, &a, nullptr, &depth, &stats);
  serial.Render(pose, &b);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  double min_value, max_value;
  cv::minMaxLoc(a, &min_value, &max_value);
  EXPECT_GE(min_value, 0.0);
  EXPECT_LE(max_value, 1.0);
  EXPECT_GT(max_value - min_value, 0.5);
  cv::minMaxLoc(depth, &min_value, &max_value);
  EXPECT_GT(min_value, 0.1);  // closed room: every pixel hits something
  EXPECT_GT(stats.supersampled_fraction, 0.01);
  EXPECT_LT(stats.supersampled_fraction, 0.9);
  EXPECT_THROW(parallel.Render(pose, nullptr), InvalidArgumentError);
}

TEST(RenderOptions, RejectsBadValues) {
  RenderOptions options;
  options.supersampling = 0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = RenderOptions();
  options.near_clip_m = 0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::sim
