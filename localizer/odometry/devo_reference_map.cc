#include "localizer/odometry/devo_reference_map.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <string>
#include <utility>
#include <vector>

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
  // A pinhole ray's x depends on the column alone and its z is 1: the per-column values are
  // computed once (the same divisions, so the same values), and z / 1 is z.
  thread_local std::vector<double> column_ray_x;
  if (pinhole) {
    column_ray_x.resize(static_cast<size_t>(depth_m.cols));
    for (int x = 0; x < depth_m.cols; ++x) {
      column_ray_x[static_cast<size_t>(x)] = (x - depth_camera.cx) / depth_camera.fx;
    }
  }
  for (int y = 0; y < depth_m.rows; ++y) {
    const float* row = depth_m.ptr<float>(y);
    const double row_ray_y = (y - depth_camera.cy) / depth_camera.fy;
    for (int x = 0; x < depth_m.cols; ++x) {
      const float z = row[x];
      if (!(z >= options.min_depth_m && z <= options.max_depth_m)) continue;
      Eigen::Vector3d scaled_ray;
      if (pinhole) {
        const double depth = z;
        scaled_ray << column_ray_x[static_cast<size_t>(x)] * depth, row_ray_y * depth, depth;
      } else {
        Eigen::Vector3d ray;
        if (!depth_camera.Unproject(Eigen::Vector2d(x, y), &ray)) continue;
        scaled_ray = ray * (z / ray.z());
      }
      const Eigen::Vector3d point = rotation * scaled_ray + target_from_depth.translation;
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

namespace {

// A depth point warped into the event image: its position, depth and nearest pixel (row-major).
struct WarpedDepthPoint {
  float u;
  float v;
  float z;
  int32_t cell;
};

// A warped point near a semi-dense pixel: its offset from the pixel centre and its depth.
struct NeighbourPoint {
  double du;
  double dv;
  float z;
};

// The buffers of a build, kept for the next one: each build fills megabytes of them, and fresh
// allocations of that size cost page faults (measured: up to a third of a VGA build).
struct BuildWorkspace {
  cv::Mat near_semi_dense;
  std::vector<int32_t> cell_count;
  std::vector<WarpedDepthPoint> warped;
  std::vector<WarpedDepthPoint> sorted;
  std::vector<NeighbourPoint> neighbours;
};

}  // namespace

std::vector<ReferencePoint> BuildReferenceMap(const Camera& event_camera, const cv::Mat& semi_dense,
                                              const Camera& depth_camera, const cv::Mat& depth_m,
                                              const Rigid3d& event_from_depth,
                                              const ReferenceMapOptions& options,
                                              ReferenceMapStats* stats) {
  std::vector<ReferencePoint> points;
  BuildReferenceMap(event_camera, semi_dense, depth_camera, depth_m, event_from_depth, options,
                    &points, stats);
  return points;
}

void BuildReferenceMap(const Camera& event_camera, const cv::Mat& semi_dense,
                       const Camera& depth_camera, const cv::Mat& depth_m,
                       const Rigid3d& event_from_depth, const ReferenceMapOptions& options,
                       std::vector<ReferencePoint>* points, ReferenceMapStats* stats) {
  options.Check();
  if (semi_dense.type() != CV_8UC1 || semi_dense.cols != event_camera.width ||
      semi_dense.rows != event_camera.height) {
    throw InvalidArgumentError("BuildReferenceMap: the semi-dense mask must be CV_8UC1 of " +
                               std::to_string(event_camera.width) + "x" +
                               std::to_string(event_camera.height));
  }
  CheckDepthFrame("BuildReferenceMap", depth_camera, depth_m);
  if (points == nullptr) throw InvalidArgumentError("BuildReferenceMap: no output for the points");
  points->clear();
  thread_local BuildWorkspace workspace;
  ReferenceMapStats local_stats;
  const int width = event_camera.width;
  const int height = event_camera.height;
  // Warp every depth pixel into the event image; bucket the points by their nearest pixel. Only
  // the points whose pixel lies within `reach` cells of a semi-dense pixel can be anyone's
  // neighbour: the others are not kept (most of a VGA depth frame).
  const int reach = static_cast<int>(std::ceil(options.neighbour_radius_px));
  cv::Mat& near_semi_dense = workspace.near_semi_dense;
  cv::dilate(semi_dense, near_semi_dense,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * reach + 1, 2 * reach + 1)));
  std::vector<WarpedDepthPoint>& warped = workspace.warped;
  warped.clear();
  std::vector<int32_t>& cell_count = workspace.cell_count;
  cell_count.assign(static_cast<size_t>(width) * height + 1, 0);
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
  // Counting sort of the points by cell, into a copy: the pixels below visit the cells in raster
  // order, so the points they read lie (nearly) in sequence in memory. cell_count[c] becomes the
  // first point of cell c.
  for (size_t i = 1; i < cell_count.size(); ++i) cell_count[i] += cell_count[i - 1];
  std::vector<WarpedDepthPoint>& sorted = workspace.sorted;
  sorted.resize(warped.size());
  for (const WarpedDepthPoint& point : warped) {
    sorted[static_cast<size_t>(cell_count[static_cast<size_t>(point.cell)]++)] = point;
  }
  // Each cell's count moved its start to the next cell's: shift back.
  for (size_t i = cell_count.size() - 1; i > 0; --i) cell_count[i] = cell_count[i - 1];
  cell_count[0] = 0;
  const double radius_squared = options.neighbour_radius_px * options.neighbour_radius_px;
  // The cells within `reach` that can hold a neighbour: a point of the cell at offset (dx, dy)
  // lies at least |dx| - 0.5 and |dy| - 0.5 pixels away along each axis (its nearest pixel is the
  // cell), so a cell whose nearest corner is beyond the radius (with a margin far above the
  // float rounding of a position) holds none: 13 of the 25 cells at the default 1.5 px. Those of
  // one row form a run |dx| <= half_width[dy + reach], whose points are contiguous in `sorted`.
  std::vector<int> half_width(static_cast<size_t>(2 * reach + 1), -1);
  for (int dy = -reach; dy <= reach; ++dy) {
    for (int dx = 0; dx <= reach; ++dx) {
      const double gap_x = std::max(0.0, dx - 0.5);
      const double gap_y = std::max(0.0, std::abs(dy) - 0.5);
      if (gap_x * gap_x + gap_y * gap_y <= radius_squared + 1e-3) half_width[dy + reach] = dx;
    }
  }
  const double tolerance = options.surround_tolerance_px;
  std::vector<NeighbourPoint>& neighbours = workspace.neighbours;
  for (int y = 0; y < height; ++y) {
    const uint8_t* mask_row = semi_dense.ptr<uint8_t>(y);
    for (int x = 0; x < width; ++x) {
      if (mask_row[x] == 0) continue;
      ++local_stats.semi_dense_pixels;
      neighbours.clear();
      float nearest = std::numeric_limits<float>::max();
      for (int dy = -reach; dy <= reach; ++dy) {
        const int cy = y + dy;
        const int half = half_width[dy + reach];
        if (cy < 0 || cy >= height || half < 0) continue;
        const size_t row_cell = static_cast<size_t>(cy) * width;
        const WarpedDepthPoint* point =
            sorted.data() + cell_count[row_cell + std::max(0, x - half)];
        const WarpedDepthPoint* end =
            sorted.data() + cell_count[row_cell + std::min(width - 1, x + half) + 1];
        for (; point != end; ++point) {
          const double du = point->u - x;
          const double dv = point->v - y;
          if (du * du + dv * dv > radius_squared) continue;
          neighbours.push_back({du, dv, point->z});
          nearest = std::min(nearest, point->z);
        }
      }
      // The foreground cluster: the neighbours within the fraction of the nearest depth.
      const float limit = nearest * static_cast<float>(1 + options.foreground_depth_fraction);
      int count = 0;
      bool left = false, right = false, above = false, below = false;
      // The normal equations of the plane below, J^T J and J^T b for the rows (du, dv, 1) and
      // b = 1/z: the upper triangle, each entry summed in neighbour order.
      double uu = 0, uv = 0, u1 = 0, vv = 0, v1 = 0, ones = 0;
      double bu = 0, bv = 0, b1 = 0;
      for (const NeighbourPoint& point : neighbours) {
        if (point.z > limit) continue;
        const double du = point.du;
        const double dv = point.dv;
        left |= du <= tolerance;
        right |= du >= -tolerance;
        above |= dv <= tolerance;
        below |= dv >= -tolerance;
        // Inverse depth as a plane over the image: 1/z = a du + b dv + c.
        const double z = point.z;
        uu += du * du;
        uv += du * dv;
        u1 += du;
        vv += dv * dv;
        v1 += dv;
        ones += 1;
        bu += du / z;
        bv += dv / z;
        b1 += 1 / z;
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
      // The ray through the pixel centre meets the plane at 1/z = c, by Cramer's rule (the
      // normal matrix is symmetric positive semi-definite; a determinant near zero means too few
      // or collinear points, and then the mean inverse depth is taken).
      double inverse_depth = b1 / count;
      const double minor_uv = uv * v1 - vv * u1;
      const double determinant =
          uu * (vv * ones - v1 * v1) - uv * (uv * ones - v1 * u1) + u1 * minor_uv;
      if (count >= 3 && std::abs(determinant) > 1e-6 * count * count * count) {
        const double c =
            (uu * (vv * b1 - bv * v1) - uv * (uv * b1 - bv * u1) + bu * minor_uv) / determinant;
        // Keep the plane only when it stays within the cluster's depths (a fit across a fold
        // would extrapolate).
        if (std::isfinite(c) && c > 0 && c >= 1.0 / limit * 0.999 && c <= 1.0 / nearest * 1.001) {
          inverse_depth = c;
        }
      }
      const double depth = 1.0 / inverse_depth;
      ReferencePoint reference;
      reference.pixel = Eigen::Vector2i(x, y);
      reference.position = Eigen::Vector3d((x - event_camera.cx) / event_camera.fx * depth,
                                           (y - event_camera.cy) / event_camera.fy * depth, depth);
      reference.support = count;
      points->push_back(reference);
    }
  }
  if (stats != nullptr) *stats = local_stats;
}

Eigen::Vector3d EdgeAfter(const Camera& camera, const Eigen::Vector2i& pixel,
                          const Eigen::Vector3d& position,
                          const Eigen::Matrix<double, 6, 1>& velocity, double age_s) {
  const Eigen::Vector3d rate = -(velocity.tail<3>().cross(position) + velocity.head<3>());
  const double z = position.z();
  const double u =
      pixel.x() + camera.fx * (rate.x() * z - position.x() * rate.z()) / (z * z) * age_s;
  const double v =
      pixel.y() + camera.fy * (rate.y() * z - position.y() * rate.z()) / (z * z) * age_s;
  return Eigen::Vector3d((u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z);
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
