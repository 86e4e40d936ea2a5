#include "tools/sim/ground_truth_map.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "tools/sim/renderer.h"

namespace evloc::sim {
namespace {

Surface FlatQuad(const std::string& name, const Eigen::Vector3d& origin, const Eigen::Vector3d& u,
                 const Eigen::Vector3d& v, double width, double height, float shading, Color base) {
  Surface surface;
  surface.name = name;
  surface.origin = origin;
  surface.u_axis = u;
  surface.v_axis = v;
  surface.width = width;
  surface.height = height;
  surface.shading = shading;
  surface.texture.base = base;
  return surface;
}

Scene WithRegion(Scene scene) {
  scene.UpdateBounds();
  scene.camera_region =
      Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, 0.5), Eigen::Vector3d(1, 1, 1.5));
  return scene;
}

TEST(GroundTruthEdges, DiscEdgeIsExactWithGradientTowardsTheBrighterSide) {
  Scene scene;
  Surface floor = FlatQuad("floor", Eigen::Vector3d(0, 0, 0), Eigen::Vector3d::UnitX(),
                           Eigen::Vector3d::UnitY(), 1, 1, 1.0f, Gray(0.2f));
  floor.texture.layers.push_back(TextureLayer::Disc({0.5, 0.4}, 0.1, Gray(0.8f)));
  // A disc too faint to pass min_contrast: ln(0.21 / 0.2) = 0.049.
  floor.texture.layers.push_back(TextureLayer::Disc({0.2, 0.8}, 0.05, Gray(0.21f)));
  scene.surfaces.push_back(floor);
  GroundTruthMapOptions options;
  options.point_spacing_m = 0.005;
  const auto points = SampleGroundTruthEdges(WithRegion(scene), options);
  const int expected = static_cast<int>(std::ceil(2 * M_PI * 0.1 / 0.005));
  ASSERT_EQ(static_cast<int>(points.size()), expected);
  for (const auto& point : points) {
    const Eigen::Vector3d radial = point.position - Eigen::Vector3d(0.5, 0.4, 0);
    EXPECT_NEAR(radial.norm(), 0.1, 1e-12);
    EXPECT_NEAR(point.gradient.dot(-radial.normalized()), 1.0, 1e-9);  // into the bright disc
    EXPECT_NEAR(point.intensity_step, 0.6, 1e-6);
    EXPECT_NEAR(point.log_contrast, std::log(0.801 / 0.201), 1e-6);
    EXPECT_EQ(point.kind, EdgeKind::kTexture);
  }
}

TEST(GroundTruthEdges, CreasesPointIntoTheBrighterFaceAndAreClassified) {
  Scene scene;
  // Floor (shading 1) and a wall standing on it along x (shading 0.5), same albedo.
  scene.surfaces.push_back(FlatQuad("floor", Eigen::Vector3d(-1, -1, 0), Eigen::Vector3d::UnitX(),
                                    Eigen::Vector3d::UnitY(), 2, 2, 1.0f, Gray(0.5f)));
  scene.surfaces.push_back(FlatQuad("wall", Eigen::Vector3d(-1, 1, 0), Eigen::Vector3d::UnitX(),
                                    Eigen::Vector3d::UnitZ(), 2, 1, 0.5f, Gray(0.5f)));
  BoxSpec box;
  box.name = "box";
  box.center = Eigen::Vector3d(0, 0, 0.1);
  box.size = Eigen::Vector3d(0.2, 0.2, 0.2);
  // Dark enough that every face contrasts with the floor whatever its shading.
  box.face_textures.fill(Texture{Gray(0.3f), {}});
  box.bottom_face = false;
  AddBox(box, &scene);
  GroundTruthMapOptions options;
  options.point_spacing_m = 0.01;
  const auto points = SampleGroundTruthEdges(WithRegion(scene), options);
  int wall_floor = 0, box_floor = 0, box_top = 0;
  for (const auto& point : points) {
    const Eigen::Vector3d& p = point.position;
    if (std::abs(p.y() - 1) < 1e-9 && std::abs(p.z()) < 1e-9) {
      ++wall_floor;  // the floor is brighter: gradient along -y on the floor
      EXPECT_EQ(point.kind, EdgeKind::kConcaveCrease);
      EXPECT_NEAR(point.gradient.y(), -1.0, 1e-12);
      EXPECT_NEAR(point.intensity_step, 0.25, 1e-6);
    } else if (std::abs(p.z()) < 1e-9) {
      ++box_floor;
      EXPECT_EQ(point.kind, EdgeKind::kConcaveCrease);
      EXPECT_NEAR(std::max(std::abs(p.x()), std::abs(p.y())), 0.1, 1e-9);
    } else if (std::abs(p.z() - 0.2) < 1e-9) {
      ++box_top;
      EXPECT_EQ(point.kind, EdgeKind::kConvexCrease);
    }
  }
  EXPECT_EQ(wall_floor, 200);  // sampled once although the edge is on both outlines
  EXPECT_EQ(box_floor, 4 * 20);
  EXPECT_EQ(box_top, 4 * 20);
}

// Two walls meeting at a right angle on a floor, sampled so that a point of one wall's bottom
// edge falls exactly on the other wall: that edge runs along the other wall's normal there (it
// crosses it), which is no crease of the two. Every point keeps a unit gradient (the car park at
// --map-spacing 0.2 had one of zero length, which the map refused).
TEST(GroundTruthEdges, AnEdgeCrossingAnotherSurfaceIsNoCreaseWithIt) {
  Scene scene;
  scene.surfaces.push_back(FlatQuad("floor", Eigen::Vector3d(-1, -1, 0), Eigen::Vector3d::UnitX(),
                                    Eigen::Vector3d::UnitY(), 2, 2, 1.0f, Gray(0.5f)));
  scene.surfaces.push_back(FlatQuad("wall a", Eigen::Vector3d(-1, 1, 0), Eigen::Vector3d::UnitX(),
                                    Eigen::Vector3d::UnitZ(), 2, 1, 0.5f, Gray(0.5f)));
  // At x = 0.1: the 6th of the 10 samples of wall a's 2 m bottom edge at 0.2 m spacing.
  scene.surfaces.push_back(FlatQuad("wall b", Eigen::Vector3d(0.1, 0, 0), Eigen::Vector3d::UnitY(),
                                    Eigen::Vector3d::UnitZ(), 1, 1, 0.7f, Gray(0.5f)));
  GroundTruthMapOptions options;
  options.point_spacing_m = 0.2;
  const auto points = SampleGroundTruthEdges(WithRegion(scene), options);
  ASSERT_FALSE(points.empty());
  for (const auto& point : points) {
    EXPECT_NEAR(point.gradient.norm(), 1.0, 1e-9)
        << "at " << point.position.transpose() << " (surface " << point.surface_index << ")";
  }
}

TEST(GroundTruthMap, VisibilityIsOcclusionCorrect) {
  Scene scene;
  Surface wall = FlatQuad("wall", Eigen::Vector3d(-2, -2, 3), Eigen::Vector3d::UnitX(),
                          Eigen::Vector3d::UnitY(), 4, 4, 1.0f, Gray(0.2f));
  wall.texture.layers.push_back(
      TextureLayer::Rectangle({1.9, 1.9}, {2.1, 2.1}, Gray(0.9f)));  // hidden
  wall.texture.layers.push_back(
      TextureLayer::Rectangle({3.0, 3.0}, {3.2, 3.2}, Gray(0.9f)));  // seen
  scene.surfaces.push_back(wall);
  BoxSpec box;
  box.name = "occluder";
  box.center = Eigen::Vector3d(0, 0, 1.5);
  box.size = Eigen::Vector3d(0.5, 0.5, 0.5);
  box.face_textures.fill(Texture{Gray(0.5f), {}});
  AddBox(box, &scene);
  scene = WithRegion(scene);
  scene.camera_region =
      Eigen::AlignedBox3d(Eigen::Vector3d(-0.1, -0.1, -0.1), Eigen::Vector3d(0.1, 0.1, 0.1));
  EXPECT_FALSE(IsPointUnoccluded(scene, Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, 3)));
  EXPECT_TRUE(IsPointUnoccluded(scene, Eigen::Vector3d::Zero(), Eigen::Vector3d(1.1, 1.1, 3)));
  const Camera camera = Camera::Pinhole(200, 200, 100, 100, 99.5, 99.5);
  GroundTruthMapOptions options;
  options.include_creases = false;
  const Map map = BuildGroundTruthMap(scene, camera, {Rigid3d::Identity()}, options);
  ASSERT_EQ(map.keyframes.size(), 1u);
  int hidden_seen = 0, visible_seen = 0;
  for (uint32_t index : map.keyframes[0].visible_points) {
    const Eigen::Vector3f& p = map.positions[index];
    if (std::abs(p.x()) < 0.2f) ++hidden_seen;
    if (p.x() > 0.9f) ++visible_seen;
  }
  EXPECT_EQ(hidden_seen, 0);
  EXPECT_EQ(visible_seen, 80);  // 4 sides x 0.2 m / 0.01 m
  for (size_t i = 0; i < map.size(); ++i) {
    EXPECT_EQ(map.source_keyframe[i], map.positions[i].x() > 0.9f ? 0u : kNoKeyframe);
  }
}

// Bilinear sample of a CV_32FC1 image.
double Bilinear(const cv::Mat& image, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const double ax = x - x0, ay = y - y0;
  auto at = [&](int yy, int xx) {
    xx = std::clamp(xx, 0, image.cols - 1);
    yy = std::clamp(yy, 0, image.rows - 1);
    return static_cast<double>(image.at<float>(yy, xx));
  };
  return (1 - ay) * ((1 - ax) * at(y0, x0) + ax * at(y0, x0 + 1)) +
         ay * ((1 - ax) * at(y0 + 1, x0) + ax * at(y0 + 1, x0 + 1));
}

// Projects the ground-truth map of the default room into renders from two viewpoints and
// measures (1) the distance from each point to the image-gradient maximum along the projected
// gradient direction, (2) whether the image brightens along the projected gradient.
TEST(GroundTruthMap, PointsLieOnRenderedEdgesWithTheImageGradientSign) {
  const Scene room = MakeDefaultRoom();
  const Camera camera = Camera::Pinhole(640, 480, 400, 400, 319.5, 239.5);
  std::vector<Rigid3d> poses;
  const Eigen::Vector3d centre = room.camera_region.center();
  for (const double yaw : {0.0, 0.9, -2.2}) {
    // Camera z forward horizontal at heading yaw from world +y, tilted down 0.35 rad.
    const Eigen::Vector3d forward(std::sin(yaw) * std::cos(0.35), std::cos(yaw) * std::cos(0.35),
                                  -std::sin(0.35));
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    Eigen::Matrix3d rotation;
    rotation.col(0) = right;
    rotation.col(1) = forward.cross(right);
    rotation.col(2) = forward;
    poses.emplace_back(Eigen::Quaterniond(rotation), centre);
  }
  GroundTruthMapOptions options;
  options.point_spacing_m = 0.02;
  options.visibility_margin_px = 4;
  const Map map = BuildGroundTruthMap(room, camera, poses, options);
  const std::vector<GroundTruthEdgePoint> edges = SampleGroundTruthEdges(room, options);
  ASSERT_EQ(edges.size(), map.size());
  const Renderer renderer(room, camera);
  for (size_t k = 0; k < poses.size(); ++k) {
    cv::Mat gray, gradient_x, gradient_y, magnitude;
    renderer.Render(poses[k], &gray);
    cv::Sobel(gray, gradient_x, CV_32F, 1, 0, 3);
    cv::Sobel(gray, gradient_y, CV_32F, 0, 1, 3);
    cv::magnitude(gradient_x, gradient_y, magnitude);
    const Rigid3d cam_from_world = poses[k].Inverse();
    std::vector<double> distances;
    int sign_checked = 0, sign_agrees = 0;
    for (uint32_t index : map.keyframes[k].visible_points) {
      const Eigen::Vector3d p = map.positions[index].cast<double>();
      const Eigen::Vector3d g = map.gradients[index].cast<double>();
      Eigen::Vector2d pixel, ahead;
      ASSERT_TRUE(camera.Project(cam_from_world * p, &pixel));
      ASSERT_TRUE(camera.Project(cam_from_world * (p + 0.002 * g), &ahead));
      if ((ahead - pixel).norm() < 1e-6) continue;
      const Eigen::Vector2d d = (ahead - pixel).normalized();
      // Gradient maximum along d within +-2 px, refined by a parabola.
      double best_t = 0, best = -1;
      for (double t = -2; t <= 2.001; t += 0.25) {
        const double value = Bilinear(magnitude, pixel.x() + t * d.x(), pixel.y() + t * d.y());
        if (value > best) {
          best = value;
          best_t = t;
        }
      }
      const double h = 0.25;
      const double left =
          Bilinear(magnitude, pixel.x() + (best_t - h) * d.x(), pixel.y() + (best_t - h) * d.y());
      const double right =
          Bilinear(magnitude, pixel.x() + (best_t + h) * d.x(), pixel.y() + (best_t + h) * d.y());
      const double curvature = left - 2 * best + right;
      if (curvature < 0) best_t += 0.5 * h * (left - right) / curvature;
      distances.push_back(std::abs(best_t));
      if (edges[index].kind != EdgeKind::kConvexCrease) {
        const double brighter = Bilinear(gray, pixel.x() + 0.6 * d.x(), pixel.y() + 0.6 * d.y());
        const double darker = Bilinear(gray, pixel.x() - 0.6 * d.x(), pixel.y() - 0.6 * d.y());
        ++sign_checked;
        if (brighter > darker) ++sign_agrees;
      }
    }
    ASSERT_GT(distances.size(), 500u) << "view " << k;
    std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
    const double median = distances[distances.size() / 2];
    const double agreement = static_cast<double>(sign_agrees) / sign_checked;
    std::printf(
        "view %zu: %zu visible points, median distance to image edge %.3f px, gradient sign "
        "agreement %.3f\n",
        k, distances.size(), median, agreement);
    EXPECT_LE(median, 0.5);
    EXPECT_GT(agreement, 0.9);
  }
}

TEST(GroundTruthMapOptions, RejectsBadValues) {
  GroundTruthMapOptions options;
  options.point_spacing_m = 0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = GroundTruthMapOptions();
  options.min_contrast = -1;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::sim
