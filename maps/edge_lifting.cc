#include "maps/edge_lifting.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include <Eigen/Eigenvalues>

#include "core/common/error.h"

namespace evloc {

void SurfaceGradientOptions::Check() const {
  const auto require = [](bool condition, const std::string& message) {
    if (!condition) throw InvalidArgumentError("SurfaceGradientOptions: " + message);
  };
  require(window_px >= 0, "window_px must be >= 0");
  require(window_doublings >= 0 && window_doublings <= 4, "window_doublings must be in [0, 4]");
  require(max_slope >= 0.0, "max_slope must be >= 0");
  require(edge_band_px >= 0.0, "edge_band_px must be >= 0");
  require(min_points >= 3, "min_points must be at least 3");
  require(max_depth_difference > 0.0, "max_depth_difference must be > 0");
  require(max_thickness_ratio > 0.0 && max_thickness_ratio < 1.0,
          "max_thickness_ratio must be in (0, 1)");
  require(min_width_ratio >= 0.0 && min_width_ratio < 1.0, "min_width_ratio must be in [0, 1)");
}

bool ComputeGradient3d(const Camera& camera, const Eigen::Vector2d& pixel,
                       const Eigen::Vector2d& gradient_direction,
                       const Eigen::Vector3d& point_in_cam, Eigen::Vector3d* gradient_in_cam) {
  Eigen::Vector3d shifted_ray;
  if (!camera.Unproject(pixel + gradient_direction.normalized(), &shifted_ray)) return false;
  const double distance = point_in_cam.norm();
  if (!(distance > 0.0)) return false;
  const Eigen::Vector3d normal = point_in_cam / distance;
  const double along = normal.dot(shifted_ray);
  if (std::abs(along) < 1e-12) return false;
  const Eigen::Vector3d intersection = shifted_ray * (normal.dot(point_in_cam) / along);
  const Eigen::Vector3d offset = intersection - point_in_cam;
  if (!(offset.norm() > 0.0)) return false;
  *gradient_in_cam = offset.normalized();
  return true;
}

std::vector<std::optional<Eigen::Vector3d>> SurfaceGradients3d(
    const Camera& camera, const std::vector<EdgeDepthPixel>& pixels,
    const SurfaceGradientOptions& options) {
  options.Check();
  std::vector<std::optional<Eigen::Vector3d>> gradients(pixels.size());
  const int window = options.window_px;
  if (window == 0 || pixels.empty()) return gradients;
  // Points in the camera, bucketed in square cells of the base window's size.
  std::vector<Eigen::Vector3d> points(pixels.size(), Eigen::Vector3d::Zero());
  std::vector<bool> valid(pixels.size(), false);
  const int cell = window;
  const int cells_x = (camera.width + cell - 1) / cell;
  const int cells_y = (camera.height + cell - 1) / cell;
  std::vector<std::vector<uint32_t>> buckets(static_cast<size_t>(cells_x * cells_y));
  for (size_t i = 0; i < pixels.size(); ++i) {
    const EdgeDepthPixel& pixel = pixels[i];
    Eigen::Vector3d ray;
    if (!(pixel.inverse_depth > 0.0) || !camera.Unproject(pixel.pixel.cast<double>(), &ray)) {
      continue;
    }
    if (pixel.pixel.x() < 0 || pixel.pixel.y() < 0 || pixel.pixel.x() >= camera.width ||
        pixel.pixel.y() >= camera.height) {
      continue;
    }
    points[i] = ray / pixel.inverse_depth;
    valid[i] = true;
    buckets[static_cast<size_t>((pixel.pixel.y() / cell) * cells_x + pixel.pixel.x() / cell)]
        .push_back(static_cast<uint32_t>(i));
  }
  const double max_thickness_squared = options.max_thickness_ratio * options.max_thickness_ratio;
  const double min_width_squared = options.min_width_ratio * options.min_width_ratio;
  std::vector<Eigen::Vector3d> neighbourhood;
  // The points within `half_size` pixels of `center` on the same surface (similar depth).
  const auto gather = [&](size_t i, int half_size) {
    const Eigen::Vector2i& center = pixels[i].pixel;
    const Eigen::Vector2d& bright = pixels[i].gradient_direction;
    const double max_difference =
        points[i].z() *
        std::max(options.max_depth_difference, options.max_slope * half_size / camera.fx);
    neighbourhood.clear();
    const int x_begin = std::max(0, (center.x() - half_size) / cell);
    const int x_end = std::min(cells_x - 1, (center.x() + half_size) / cell);
    const int y_begin = std::max(0, (center.y() - half_size) / cell);
    const int y_end = std::min(cells_y - 1, (center.y() + half_size) / cell);
    for (int cy = y_begin; cy <= y_end; ++cy) {
      for (int cx = x_begin; cx <= x_end; ++cx) {
        for (const uint32_t other : buckets[static_cast<size_t>(cy * cells_x + cx)]) {
          const Eigen::Vector2i& at = pixels[other].pixel;
          if (std::abs(at.x() - center.x()) > half_size ||
              std::abs(at.y() - center.y()) > half_size ||
              std::abs(points[other].z() - points[i].z()) > max_difference ||
              (at - center).cast<double>().dot(bright) < -options.edge_band_px) {
            continue;
          }
          neighbourhood.push_back(points[other]);
        }
      }
    }
  };
  for (size_t i = 0; i < pixels.size(); ++i) {
    if (!valid[i]) continue;
    const Eigen::Vector2i& center = pixels[i].pixel;
    // The smallest window whose points form a plane (planar, and not one line).
    std::optional<Eigen::Vector3d> plane_normal;
    for (int doubling = 0; doubling <= options.window_doublings && !plane_normal; ++doubling) {
      gather(i, window << doubling);
      if (neighbourhood.size() < static_cast<size_t>(options.min_points)) continue;
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (const Eigen::Vector3d& point : neighbourhood) mean += point;
      mean /= static_cast<double>(neighbourhood.size());
      Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
      for (const Eigen::Vector3d& point : neighbourhood) {
        covariance += (point - mean) * (point - mean).transpose();
      }
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
      if (solver.info() != Eigen::Success) continue;
      const Eigen::Vector3d& eigenvalues = solver.eigenvalues();  // increasing
      if (!(eigenvalues(2) > 0.0) || eigenvalues(0) > max_thickness_squared * eigenvalues(1) ||
          eigenvalues(1) < min_width_squared * eigenvalues(2)) {
        continue;
      }
      plane_normal = solver.eigenvectors().col(0);
    }
    if (!plane_normal) continue;
    const Eigen::Vector3d& normal = *plane_normal;
    Eigen::Vector3d view_gradient;
    if (!ComputeGradient3d(camera, center.cast<double>(), pixels[i].gradient_direction, points[i],
                           &view_gradient)) {
      continue;
    }
    // The plane through the camera centre and the image edge (perpendicular to the image
    // gradient) cuts the surface along the 3D edge; the gradient is the in-surface direction
    // perpendicular to that edge: the edge plane's normal projected onto the surface.
    const Eigen::Vector2d& direction = pixels[i].gradient_direction;
    Eigen::Vector3d edge_in_view;
    if (!ComputeGradient3d(camera, center.cast<double>(),
                           Eigen::Vector2d(-direction.y(), direction.x()), points[i],
                           &edge_in_view)) {
      continue;
    }
    const Eigen::Vector3d edge_plane_normal = points[i].normalized().cross(edge_in_view);
    Eigen::Vector3d surface_gradient = edge_plane_normal - edge_plane_normal.dot(normal) * normal;
    if (surface_gradient.norm() < 0.3) continue;  // Surface seen nearly edge-on.
    surface_gradient.normalize();
    if (surface_gradient.dot(view_gradient) < 0.0) surface_gradient = -surface_gradient;
    gradients[i] = surface_gradient;
  }
  return gradients;
}

std::vector<std::optional<LiftedEdgePoint>> LiftEdgePixels(
    const Camera& camera, const std::vector<EdgeDepthPixel>& pixels,
    const SurfaceGradientOptions& options) {
  const std::vector<std::optional<Eigen::Vector3d>> surface_gradients =
      SurfaceGradients3d(camera, pixels, options);
  std::vector<std::optional<LiftedEdgePoint>> lifted(pixels.size());
  for (size_t i = 0; i < pixels.size(); ++i) {
    const EdgeDepthPixel& pixel = pixels[i];
    if (!(pixel.inverse_depth > 0.0)) continue;
    LiftedEdgePoint point;
    if (!camera.Unproject(pixel.pixel.cast<double>(), &point.ray)) continue;
    point.point_in_cam = point.ray / pixel.inverse_depth;
    if (!ComputeGradient3d(camera, pixel.pixel.cast<double>(), pixel.gradient_direction,
                           point.point_in_cam, &point.gradient_in_cam)) {
      continue;
    }
    if (surface_gradients[i]) {
      point.gradient_in_cam = *surface_gradients[i];
      point.surface_gradient = true;
    }
    lifted[i] = point;
  }
  return lifted;
}

}  // namespace evloc
