#include "localizer/odometry/devo_reference_map.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::odometry {
namespace {

// A constructed scene in the event camera's frame: a square panel at z = 1 m (|x|, |y| <= 0.2)
// in front of a wall at z = 3 m. Returns the depth (camera z) of the first hit along the ray
// from `origin` in `direction` (event frame), and whether it is the panel.
double TraceDepthAlong(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                       bool* on_panel) {
  const double t_panel = (1.0 - origin.z()) / direction.z();
  const Eigen::Vector3d hit = origin + t_panel * direction;
  *on_panel = t_panel > 0 && std::abs(hit.x()) <= 0.2 && std::abs(hit.y()) <= 0.2;
  if (*on_panel) return t_panel;
  return (3.0 - origin.z()) / direction.z();
}

struct OcclusionScene {
  // Both cameras 160x120, f = 120 px; the depth camera sits 8 cm to the right of the event
  // camera (a large baseline: 8 px of parallax between panel and wall at these depths).
  Camera event_camera = Camera::Pinhole(160, 120, 120, 120, 79.5, 59.5);
  Camera depth_camera = Camera::Pinhole(160, 120, 120, 120, 79.5, 59.5);
  Rigid3d event_from_depth = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.08, 0, 0));

  // The depth image of the depth camera (z in its own frame).
  cv::Mat RenderDepth() const {
    cv::Mat depth(depth_camera.height, depth_camera.width, CV_32FC1);
    for (int y = 0; y < depth.rows; ++y) {
      for (int x = 0; x < depth.cols; ++x) {
        const Eigen::Vector3d ray((x - depth_camera.cx) / depth_camera.fx,
                                  (y - depth_camera.cy) / depth_camera.fy, 1);
        const Eigen::Vector3d origin = event_from_depth.translation;
        const Eigen::Vector3d direction = event_from_depth.rotation * ray;
        bool on_panel;
        const double t = TraceDepthAlong(origin, direction, &on_panel);
        depth.at<float>(y, x) = static_cast<float>(t * ray.z());  // depth-camera z (no rotation)
      }
    }
    return depth;
  }
  // The true depth of event pixel (x, y).
  double TrueDepth(int x, int y, bool* on_panel) const {
    const Eigen::Vector3d ray((x - event_camera.cx) / event_camera.fx,
                              (y - event_camera.cy) / event_camera.fy, 1);
    return TraceDepthAlong(Eigen::Vector3d::Zero(), ray, on_panel);
  }
  // The semi-dense region: the event pixels within 2 px of the panel's outline (where an edge
  // fires events), plus a few texture edges on the wall and on the panel.
  cv::Mat SemiDense() const {
    cv::Mat mask(event_camera.height, event_camera.width, CV_8UC1, cv::Scalar(0));
    const double left = -0.2 * event_camera.fx + event_camera.cx;
    const double right = 0.2 * event_camera.fx + event_camera.cx;
    const double top = -0.2 * event_camera.fy + event_camera.cy;
    const double bottom = 0.2 * event_camera.fy + event_camera.cy;
    for (int y = 0; y < mask.rows; ++y) {
      for (int x = 0; x < mask.cols; ++x) {
        const bool inside_rows = y >= top - 2 && y <= bottom + 2;
        const bool inside_cols = x >= left - 2 && x <= right + 2;
        const bool near_vertical =
            inside_rows && (std::abs(x - left) <= 2 || std::abs(x - right) <= 2);
        const bool near_horizontal =
            inside_cols && (std::abs(y - top) <= 2 || std::abs(y - bottom) <= 2);
        const bool texture = x == 20 || y == 10 || x == 80;
        if (near_vertical || near_horizontal || texture) mask.at<uint8_t>(y, x) = 255;
      }
    }
    return mask;
  }
};

TEST(BuildReferenceMap, OccludedDepthNeverLeaksAcrossThePanelsEdges) {
  const OcclusionScene scene;
  const cv::Mat depth = scene.RenderDepth();
  const cv::Mat semi_dense = scene.SemiDense();
  ReferenceMapStats stats;
  const std::vector<ReferencePoint> points =
      BuildReferenceMap(scene.event_camera, semi_dense, scene.depth_camera, depth,
                        scene.event_from_depth, ReferenceMapOptions(), &stats);
  ASSERT_GT(points.size(), 500u);
  // Only the depth points that land near the semi-dense region are kept.
  EXPECT_GT(stats.warped_points, static_cast<int>(points.size()));
  EXPECT_LT(stats.warped_points, depth.rows * depth.cols);
  int panel = 0;
  int wall = 0;
  for (const ReferencePoint& point : points) {
    bool on_panel;
    const double truth = scene.TrueDepth(point.pixel.x(), point.pixel.y(), &on_panel);
    // Every depth is its pixel's own surface: the panel's (1 m) or the wall's (3 m), never the
    // other one and never a blend.
    EXPECT_NEAR(point.position.z(), truth, 1e-3 * truth)
        << "pixel " << point.pixel.transpose() << (on_panel ? " (panel)" : " (wall)");
    (on_panel ? panel : wall) += 1;
    // The point lies on its pixel's ray.
    EXPECT_NEAR(point.position.x() / point.position.z(),
                (point.pixel.x() - scene.event_camera.cx) / scene.event_camera.fx, 1e-9);
  }
  EXPECT_GT(panel, 150);
  EXPECT_GT(wall, 150);
  // The wall strip beside the panel that the depth camera cannot see (8 px of parallax) gets no
  // depth: it is a hole, or the panel's depth would have leaked into it.
  EXPECT_GT(stats.without_depth + stats.not_surrounded, 100);

  // Without the foreground rule (every neighbour in the cluster), depths blend across the edges:
  // the test above would catch it.
  ReferenceMapOptions blend;
  blend.foreground_depth_fraction = 100;
  int wrong = 0;
  for (const ReferencePoint& point :
       BuildReferenceMap(scene.event_camera, semi_dense, scene.depth_camera, depth,
                         scene.event_from_depth, blend)) {
    bool on_panel;
    const double truth = scene.TrueDepth(point.pixel.x(), point.pixel.y(), &on_panel);
    if (std::abs(point.position.z() - truth) > 1e-2 * truth) ++wrong;
  }
  EXPECT_GT(wrong, 20);
}

TEST(BuildReferenceMap, InterpolatesASlantedPlaneExactlyThroughTheRay) {
  // A plane z = 2 + 0.5 x seen by both cameras (same pose): the warped points fall exactly on
  // the pixel centres, so shift the depth camera by a sub-pixel amount to exercise the fit.
  const Camera camera = Camera::Pinhole(80, 60, 60, 60, 39.5, 29.5);
  const Rigid3d event_from_depth(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.013, 0.007, 0));
  cv::Mat depth(60, 80, CV_32FC1);
  for (int y = 0; y < 60; ++y) {
    for (int x = 0; x < 80; ++x) {
      const Eigen::Vector3d ray((x - 39.5) / 60, (y - 29.5) / 60, 1);
      // Plane in the event frame: z = 2 + 0.5 x_e, with x_e = x_d + 0.013.
      const double z = (2 + 0.5 * 0.013) / (1 - 0.5 * ray.x());
      depth.at<float>(y, x) = static_cast<float>(z);
    }
  }
  const cv::Mat semi_dense(60, 80, CV_8UC1, cv::Scalar(255));
  const std::vector<ReferencePoint> points =
      BuildReferenceMap(camera, semi_dense, camera, depth, event_from_depth, ReferenceMapOptions());
  ASSERT_GT(points.size(), 3000u);
  for (const ReferencePoint& point : points) {
    EXPECT_NEAR(point.position.z(), 2 + 0.5 * point.position.x(), 2e-5);
  }
}

TEST(BuildReferenceMap, APixelsDepthDependsOnlyOnTheDepthAroundIt) {
  // Depth points far from every semi-dense pixel are dropped before the pixels gather their
  // neighbours: a pixel alone in its mask must get exactly the depth it gets among all others.
  const OcclusionScene scene;
  const cv::Mat depth = scene.RenderDepth();
  const cv::Mat semi_dense = scene.SemiDense();
  const std::vector<ReferencePoint> all =
      BuildReferenceMap(scene.event_camera, semi_dense, scene.depth_camera, depth,
                        scene.event_from_depth, ReferenceMapOptions());
  ASSERT_GT(all.size(), 500u);
  int compared = 0;
  for (size_t i = 0; i < all.size(); i += all.size() / 60) {
    cv::Mat alone = cv::Mat::zeros(semi_dense.size(), CV_8UC1);
    alone.at<uint8_t>(all[i].pixel.y(), all[i].pixel.x()) = 255;
    const std::vector<ReferencePoint> one =
        BuildReferenceMap(scene.event_camera, alone, scene.depth_camera, depth,
                          scene.event_from_depth, ReferenceMapOptions());
    ASSERT_EQ(one.size(), 1u) << "pixel " << all[i].pixel.transpose();
    EXPECT_EQ(one[0].position, all[i].position) << "pixel " << all[i].pixel.transpose();
    EXPECT_EQ(one[0].support, all[i].support);
    ++compared;
  }
  EXPECT_GE(compared, 60);
}

TEST(BuildReferenceMap, ABuildDoesNotDependOnTheBuildsBeforeIt) {
  // The buffers kept between builds (per thread) and the output vector reused: a build after a
  // larger image's and after another mask's gives what it gives alone.
  const OcclusionScene scene;
  const cv::Mat depth = scene.RenderDepth();
  const cv::Mat semi_dense = scene.SemiDense();
  const std::vector<ReferencePoint> first =
      BuildReferenceMap(scene.event_camera, semi_dense, scene.depth_camera, depth,
                        scene.event_from_depth, ReferenceMapOptions());
  ASSERT_GT(first.size(), 500u);
  // A build twice the size, every pixel semi-dense, a flat wall at 2 m.
  const Camera large = Camera::Pinhole(320, 240, 240, 240, 159.5, 119.5);
  const cv::Mat large_depth(240, 320, CV_32FC1, cv::Scalar(2.0f));
  const cv::Mat large_mask(240, 320, CV_8UC1, cv::Scalar(255));
  std::vector<ReferencePoint> reused;
  BuildReferenceMap(large, large_mask, large, large_depth, Rigid3d(), ReferenceMapOptions(),
                    &reused);
  EXPECT_GT(reused.size(), 70000u);
  // Half the mask, then the whole one again, into the same vector.
  cv::Mat half = semi_dense.clone();
  half(cv::Rect(0, 0, half.cols / 2, half.rows)).setTo(0);
  BuildReferenceMap(scene.event_camera, half, scene.depth_camera, depth, scene.event_from_depth,
                    ReferenceMapOptions(), &reused);
  EXPECT_LT(reused.size(), first.size());
  ReferenceMapStats stats;
  BuildReferenceMap(scene.event_camera, semi_dense, scene.depth_camera, depth,
                    scene.event_from_depth, ReferenceMapOptions(), &reused, &stats);
  ASSERT_EQ(reused.size(), first.size());
  for (size_t i = 0; i < first.size(); ++i) {
    EXPECT_EQ(reused[i].pixel, first[i].pixel) << i;
    EXPECT_EQ(reused[i].position, first[i].position) << i;
    EXPECT_EQ(reused[i].support, first[i].support) << i;
  }
  EXPECT_EQ(stats.semi_dense_pixels, cv::countNonZero(semi_dense));
}

TEST(EdgeAfter, MovesAnEdgeAlongItsImageFlowByItsAge) {
  const Camera camera = Camera::Pinhole(160, 120, 100, 100, 80, 60);
  const Eigen::Vector2i pixel(100, 40);
  const double z = 2.0;
  const Eigen::Vector3d position((pixel.x() - camera.cx) / camera.fx * z,
                                 (pixel.y() - camera.cy) / camera.fy * z, z);
  Eigen::Matrix<double, 6, 1> velocity = Eigen::Matrix<double, 6, 1>::Zero();
  // The camera moves 1 m/s along its x: a static point moves 1 cm along -x in 10 ms.
  velocity(0) = 1.0;
  Eigen::Vector3d moved = EdgeAfter(camera, pixel, position, velocity, 0.01);
  EXPECT_NEAR(moved.x(), position.x() - 0.01, 1e-12);
  EXPECT_NEAR(moved.y(), position.y(), 1e-12);
  EXPECT_EQ(moved.z(), z);
  // Turning about its y at 0.5 rad/s: a point on the optical axis moves by -omega x P, here
  // along -x by z * 0.5 * dt = 1 cm in 10 ms.
  velocity.setZero();
  velocity(4) = 0.5;
  const Eigen::Vector2i centre(80, 60);
  const Eigen::Vector3d on_axis((centre.x() - camera.cx) / camera.fx * z,
                                (centre.y() - camera.cy) / camera.fy * z, z);
  moved = EdgeAfter(camera, centre, on_axis, velocity, 0.01);
  EXPECT_NEAR(moved.x() - on_axis.x(), -0.01, 1e-9);
  EXPECT_NEAR(moved.y() - on_axis.y(), 0.0, 1e-12);
  // No age, no motion.
  EXPECT_EQ(EdgeAfter(camera, pixel, position, velocity, 0.0), position);
}

TEST(RegisterDepth, KeepsTheNearestSurfaceAndNeverTheOneBehindIt) {
  // The depth camera's frame seen from the event camera, 8 cm to the side: every pixel that
  // receives depth gets its own surface's (panel or wall), except a thin seam beside the panel's
  // outline where a panel point rounds onto a wall pixel; never the wall behind the panel.
  const OcclusionScene scene;
  const cv::Mat registered =
      RegisterDepth(scene.event_camera, scene.depth_camera, scene.RenderDepth(),
                    scene.event_from_depth, ReferenceMapOptions());
  ASSERT_EQ(registered.type(), CV_32FC1);
  ASSERT_EQ(registered.cols, scene.event_camera.width);
  ASSERT_EQ(registered.rows, scene.event_camera.height);
  int covered = 0;
  int exact = 0;
  int panel_pixels = 0;
  for (int y = 0; y < registered.rows; ++y) {
    for (int x = 0; x < registered.cols; ++x) {
      bool on_panel;
      const double truth = scene.TrueDepth(x, y, &on_panel);
      const float depth = registered.at<float>(y, x);
      if (on_panel) ++panel_pixels;
      if (depth == 0) continue;
      ++covered;
      EXPECT_LE(depth, truth * (1 + 1e-3)) << "pixel " << x << ", " << y << " sees behind";
      if (std::abs(depth - truth) <= 1e-3 * truth) ++exact;
    }
  }
  const int pixels = registered.rows * registered.cols;
  // Holes: the strip of wall the depth camera cannot see beside the panel, and the image border
  // the depth camera does not cover.
  EXPECT_GT(covered, pixels * 85 / 100);
  EXPECT_GT(exact, covered * 98 / 100);
  EXPECT_GT(panel_pixels, 1000);
}

TEST(BuildReferenceMap, RefusesBadInput) {
  const Camera camera = Camera::Pinhole(16, 12, 20, 20, 7.5, 5.5);
  const cv::Mat depth(12, 16, CV_32FC1, cv::Scalar(1));
  EXPECT_THROW(BuildReferenceMap(camera, cv::Mat(12, 16, CV_32FC1), camera, depth, Rigid3d(),
                                 ReferenceMapOptions()),
               InvalidArgumentError);
  EXPECT_THROW(BuildReferenceMap(camera, cv::Mat(12, 16, CV_8UC1), camera,
                                 cv::Mat(12, 16, CV_16UC1), Rigid3d(), ReferenceMapOptions()),
               InvalidArgumentError);
  ReferenceMapOptions bad;
  bad.neighbour_radius_px = 0.5;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::odometry
