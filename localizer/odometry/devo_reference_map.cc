#include "localizer/odometry/devo_reference_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"

namespace evloc::odometry {

namespace {

// Throws InvalidArgumentError, naming `who`, unless `depth_m` is CV_32FC1 of the depth camera's
// size.
void CheckDepthFrame(const char* who, const Camera& depth_camera, const cv::Mat& depth_m) {
  if (depth_m.type() != CV_32FC1 || depth_m.cols != depth_camera.width ||
      depth_m.rows != depth_camera.height) {
    throw InvalidArgumentError(std::string(who) + ": the depth must be CV_32FC1 metres of " +
                               std::to_string(depth_camera.width) + "x" +
                               std::to_string(depth_camera.height));
  }
}

// Warps every depth pixel of `depth_m` (CV_32FC1 metres of `depth_camera`, within the options'
// depth range) into another camera: `project(point, &pixel)` maps a point of that camera's frame
// (p = target_from_depth * p_depth) to its pixel, false when it has none. Calls
// `visit(u, v, z, cx, cy)` for each point that lands on the width x height image, with its
// nearest pixel (std::lround's, without its call).
template <typename Project, typename Visit>
void ForEachWarpedDepthPixel(const Camera& depth_camera, const cv::Mat& depth_m,
                             const Rigid3d& target_from_depth, const ReferenceMapOptions& options,
                             const Project& project, int width, int height, const Visit& visit) {
  const Eigen::Matrix3d rotation = target_from_depth.RotationMatrix();
  const bool pinhole = depth_camera.model == CameraModel::kPinhole;
  for (int y = 0; y < depth_m.rows; ++y) {
    const float* row = depth_m.ptr<float>(y);
    for (int x = 0; x < depth_m.cols; ++x) {
      const float z = row[x];
      if (!(z >= options.min_depth_m && z <= options.max_depth_m)) continue;
      Eigen::Vector3d ray;
      if (pinhole) {
        ray << (x - depth_camera.cx) / depth_camera.fx, (y - depth_camera.cy) / depth_camera.fy, 1;
      } else if (!depth_camera.Unproject(Eigen::Vector2d(x, y), &ray)) {
        continue;
      }
      const Eigen::Vector3d point =
          rotation * (ray * (z / ray.z())) + target_from_depth.translation;
      if (!(point.z() > options.min_depth_m)) continue;
      Eigen::Vector2d pixel;
      if (!project(point, &pixel)) continue;
      const double u = pixel.x();
      const double v = pixel.y();
      // u + 0.5 > 0 here, so truncation rounds it down.
      if (!(u > -0.5 && v > -0.5 && u < width - 0.5 && v < height - 0.5)) continue;
      const int cx = static_cast<int>(u + 0.5);
      const int cy = static_cast<int>(v + 0.5);
      if (cx >= width || cy >= height) continue;
      visit(u, v, point.z(), cx, cy);
    }
  }
}

}  // namespace

void ReferenceMapOptions::Check() const {
  if (!(neighbour_radius_px >= 0.75) || !(neighbour_radius_px <= 5)) {
    throw InvalidArgumentError("ReferenceMapOptions: neighbour_radius_px must be in [0.75, 5]");
  }
  if (!(foreground_depth_fraction > 0)) {
    throw InvalidArgumentError("ReferenceMapOptions: foreground_depth_fraction must be > 0");
  }
  if (min_cluster_points < 1) {
    throw InvalidArgumentError("ReferenceMapOptions: min_cluster_points must be >= 1");
  }
  if (!(surround_tolerance_px >= 0)) {
    throw InvalidArgumentError("ReferenceMapOptions: surround_tolerance_px must be >= 0");
  }
  if (!(min_depth_m > 0) || !(max_depth_m > min_depth_m)) {
    throw InvalidArgumentError("ReferenceMapOptions: need 0 < min_depth_m < max_depth_m");
  }
}

std::vector<ReferencePoint> BuildReferenceMap(const Camera& event_camera, const cv::Mat& semi_dense,
                                              const Camera& depth_camera, const cv::Mat& depth_m,
                                              const Rigid3d& event_from_depth,
                                              const ReferenceMapOptions& options,
                                              ReferenceMapStats* stats) {
  options.Check();
  if (semi_dense.type() != CV_8UC1 || semi_dense.cols != event_camera.width ||
      semi_dense.rows != event_camera.height) {
    throw InvalidArgumentError("BuildReferenceMap: the semi-dense mask must be CV_8UC1 of " +
                               std::to_string(event_camera.width) + "x" +
                               std::to_string(event_camera.height));
  }
  CheckDepthFrame("BuildReferenceMap", depth_camera, depth_m);
  ReferenceMapStats local_stats;
  const int width = event_camera.width;
  const int height = event_camera.height;
  // Warp every depth pixel into the event image; bucket the points by their nearest pixel. Only
  // the points whose pixel lies within `reach` cells of a semi-dense pixel can be anyone's
  // neighbour: the others are not kept (most of a VGA depth frame).
  const int reach = static_cast<int>(std::ceil(options.neighbour_radius_px));
  cv::Mat near_semi_dense;
  cv::dilate(semi_dense, near_semi_dense,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * reach + 1, 2 * reach + 1)));
  struct Warped {
    float u;
    float v;
    float z;
    int32_t cell;
  };
  std::vector<Warped> warped;
  warped.reserve(static_cast<size_t>(cv::countNonZero(near_semi_dense)) * 2);
  std::vector<int32_t> cell_count(static_cast<size_t>(width) * height + 1, 0);
  ForEachWarpedDepthPixel(
      depth_camera, depth_m, event_from_depth, options,
      [&](const Eigen::Vector3d& point, Eigen::Vector2d* pixel) {
        *pixel = Eigen::Vector2d(event_camera.fx * point.x() / point.z() + event_camera.cx,
                                 event_camera.fy * point.y() / point.z() + event_camera.cy);
        return true;
      },
      width, height,
      [&](double u, double v, double z, int cx, int cy) {
        if (near_semi_dense.at<uint8_t>(cy, cx) == 0) return;
        const int32_t cell = cy * width + cx;
        warped.push_back(
            {static_cast<float>(u), static_cast<float>(v), static_cast<float>(z), cell});
        ++cell_count[static_cast<size_t>(cell) + 1];
      });
  local_stats.warped_points = static_cast<int>(warped.size());
  // Counting sort of the points by cell.
  for (size_t i = 1; i < cell_count.size(); ++i) cell_count[i] += cell_count[i - 1];
  std::vector<int32_t> cell_start(cell_count.begin(), cell_count.end());
  std::vector<int32_t> order(warped.size());
  for (size_t i = 0; i < warped.size(); ++i) {
    order[cell_start[static_cast<size_t>(warped[i].cell)]++] = static_cast<int32_t>(i);
  }
  const double radius_squared = options.neighbour_radius_px * options.neighbour_radius_px;
  // The cells within `reach` that can hold a neighbour: a point of the cell at offset (dx, dy)
  // lies at least |dx| - 0.5 and |dy| - 0.5 pixels away along each axis (its nearest pixel is the
  // cell), so a cell whose nearest corner is beyond the radius (with a margin far above the
  // float rounding of a position) holds none: 13 of the 25 cells at the default 1.5 px.
  std::vector<std::pair<int, int>> cell_offsets;
  for (int dy = -reach; dy <= reach; ++dy) {
    for (int dx = -reach; dx <= reach; ++dx) {
      const double gap_x = std::max(0.0, std::abs(dx) - 0.5);
      const double gap_y = std::max(0.0, std::abs(dy) - 0.5);
      if (gap_x * gap_x + gap_y * gap_y <= radius_squared + 1e-3) cell_offsets.emplace_back(dx, dy);
    }
  }
  const double tolerance = options.surround_tolerance_px;
  std::vector<ReferencePoint> points;
  std::vector<const Warped*> neighbours;
  for (int y = 0; y < height; ++y) {
    const uint8_t* mask_row = semi_dense.ptr<uint8_t>(y);
    for (int x = 0; x < width; ++x) {
      if (mask_row[x] == 0) continue;
      ++local_stats.semi_dense_pixels;
      neighbours.clear();
      float nearest = std::numeric_limits<float>::max();
      for (const auto& [dx, dy] : cell_offsets) {
        const int cx = x + dx;
        const int cy = y + dy;
        if (cx < 0 || cy < 0 || cx >= width || cy >= height) continue;
        const size_t cell = static_cast<size_t>(cy) * width + cx;
        for (int32_t k = cell_count[cell]; k < cell_count[cell + 1]; ++k) {
          const Warped& point = warped[order[k]];
          const double du = point.u - x;
          const double dv = point.v - y;
          if (du * du + dv * dv > radius_squared) continue;
          neighbours.push_back(&point);
          nearest = std::min(nearest, point.z);
        }
      }
      // The foreground cluster: the neighbours within the fraction of the nearest depth.
      const float limit = nearest * static_cast<float>(1 + options.foreground_depth_fraction);
      int count = 0;
      bool left = false, right = false, above = false, below = false;
      Eigen::Matrix3d normal_matrix = Eigen::Matrix3d::Zero();
      Eigen::Vector3d right_side = Eigen::Vector3d::Zero();
      for (const Warped* point : neighbours) {
        if (point->z > limit) continue;
        const double du = point->u - x;
        const double dv = point->v - y;
        left |= du <= tolerance;
        right |= du >= -tolerance;
        above |= dv <= tolerance;
        below |= dv >= -tolerance;
        // Inverse depth as a plane over the image: 1/z = a du + b dv + c.
        const Eigen::Vector3d row(du, dv, 1);
        normal_matrix += row * row.transpose();
        right_side += row / point->z;
        ++count;
      }
      if (count < options.min_cluster_points) {
        ++local_stats.without_depth;
        continue;
      }
      if (!(left && right && above && below)) {
        ++local_stats.not_surrounded;
        continue;
      }
      // The ray through the pixel centre meets the plane at 1/z = c; with too few or collinear
      // points, the mean inverse depth.
      double inverse_depth = right_side(2) / count;
      const Eigen::LDLT<Eigen::Matrix3d> ldlt(normal_matrix);
      if (count >= 3 && ldlt.info() == Eigen::Success && ldlt.isPositive() &&
          std::abs(normal_matrix.determinant()) > 1e-6 * count * count * count) {
        const Eigen::Vector3d plane = ldlt.solve(right_side);
        // Keep the plane only when it stays within the cluster's depths (a fit across a fold
        // would extrapolate).
        if (plane.allFinite() && plane(2) > 0 && plane(2) >= 1.0 / limit * 0.999 &&
            plane(2) <= 1.0 / nearest * 1.001) {
          inverse_depth = plane(2);
        }
      }
      const double depth = 1.0 / inverse_depth;
      ReferencePoint reference;
      reference.pixel = Eigen::Vector2i(x, y);
      reference.position = Eigen::Vector3d((x - event_camera.cx) / event_camera.fx * depth,
                                           (y - event_camera.cy) / event_camera.fy * depth, depth);
      reference.support = count;
      points.push_back(reference);
    }
  }
  if (stats != nullptr) *stats = local_stats;
  return points;
}

cv::Mat RegisterDepth(const Camera& camera, const Camera& depth_camera, const cv::Mat& depth_m,
                      const Rigid3d& camera_from_depth, const ReferenceMapOptions& options) {
  options.Check();
  CheckDepthFrame("RegisterDepth", depth_camera, depth_m);
  cv::Mat registered(camera.height, camera.width, CV_32FC1, cv::Scalar(0));
  ForEachWarpedDepthPixel(
      depth_camera, depth_m, camera_from_depth, options,
      [&](const Eigen::Vector3d& point, Eigen::Vector2d* pixel) {
        return camera.Project(point, pixel);
      },
      camera.width, camera.height,
      [&](double, double, double z, int cx, int cy) {
        float& depth = registered.at<float>(cy, cx);
        if (depth == 0 || z < depth) depth = static_cast<float>(z);
      });
  return registered;
}

}  // namespace evloc::odometry
