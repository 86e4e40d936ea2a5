#include "maps/visibility.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <tuple>

#include "core/common/error.h"

namespace evloc {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Bounds of the normalised image coordinates x/z and y/z of the camera's field of view.
struct FrustumBounds {
  // False when the field of view could not be bounded (wide-angle lens): no lateral culling.
  bool bounded = false;
  double min_x = 0, max_x = 0, min_y = 0, max_y = 0;
};

// Back-projects pixels along the image border (and the principal point row and column, where a
// distorted border bulges) and takes the extreme normalised coordinates.
FrustumBounds ComputeFrustumBounds(const Camera& camera) {
  constexpr int kSamplesPerSide = 16;
  FrustumBounds bounds;
  bounds.min_x = bounds.min_y = std::numeric_limits<double>::infinity();
  bounds.max_x = bounds.max_y = -std::numeric_limits<double>::infinity();
  const double right = camera.width - 1.0;
  const double bottom = camera.height - 1.0;
  std::vector<Eigen::Vector2d> border;
  for (int i = 0; i <= kSamplesPerSide; ++i) {
    const double s = static_cast<double>(i) / kSamplesPerSide;
    border.emplace_back(s * right, 0.0);
    border.emplace_back(s * right, bottom);
    border.emplace_back(0.0, s * bottom);
    border.emplace_back(right, s * bottom);
  }
  border.emplace_back(std::clamp(camera.cx, 0.0, right), 0.0);
  border.emplace_back(std::clamp(camera.cx, 0.0, right), bottom);
  border.emplace_back(0.0, std::clamp(camera.cy, 0.0, bottom));
  border.emplace_back(right, std::clamp(camera.cy, 0.0, bottom));
  for (const Eigen::Vector2d& pixel : border) {
    Eigen::Vector3d ray;
    if (!camera.Unproject(pixel, &ray) || !(ray.z() > 0.0) || !ray.allFinite()) return {};
    bounds.min_x = std::min(bounds.min_x, ray.x() / ray.z());
    bounds.max_x = std::max(bounds.max_x, ray.x() / ray.z());
    bounds.min_y = std::min(bounds.min_y, ray.y() / ray.z());
    bounds.max_y = std::max(bounds.max_y, ray.y() / ray.z());
  }
  // The sampled border misses bulges between samples; widen by 5% of the span.
  const double widen_x = 0.05 * (bounds.max_x - bounds.min_x);
  const double widen_y = 0.05 * (bounds.max_y - bounds.min_y);
  bounds.min_x -= widen_x;
  bounds.max_x += widen_x;
  bounds.min_y -= widen_y;
  bounds.max_y += widen_y;
  bounds.bounded = true;
  return bounds;
}

// True when a sphere (centre in camera coordinates) may intersect the frustum.
bool SphereMayBeVisible(const Eigen::Vector3d& centre, double radius, const FrustumBounds& bounds,
                        const VisibilityQueryOptions& options) {
  if (centre.z() + radius < options.min_depth_m || centre.z() - radius > options.max_depth_m) {
    return false;
  }
  if (!bounds.bounded) return true;
  // Each side plane passes through the camera centre: e.g. x = max_x * z, outward normal
  // (1, 0, -max_x) / sqrt(1 + max_x^2).
  const auto outside = [radius](double along, double slope, double z, double sign) {
    return sign * (along - slope * z) / std::sqrt(1.0 + slope * slope) > radius;
  };
  return !(outside(centre.x(), bounds.max_x, centre.z(), 1.0) ||
           outside(centre.x(), bounds.min_x, centre.z(), -1.0) ||
           outside(centre.y(), bounds.max_y, centre.z(), 1.0) ||
           outside(centre.y(), bounds.min_y, centre.z(), -1.0));
}

// The per-point test shared by both index kinds.
class PointTester {
 public:
  PointTester(const Camera& camera, const Rigid3d& world_from_cam,
              const VisibilityQueryOptions& options)
      : camera_(camera),
        cam_from_world_(world_from_cam.Inverse()),
        rotation_(cam_from_world_.RotationMatrix()),
        options_(options) {}

  bool IsVisible(const Eigen::Vector3f& position_in_world) const {
    const Eigen::Vector3d point_in_cam =
        rotation_ * position_in_world.cast<double>() + cam_from_world_.translation;
    if (!(point_in_cam.z() >= options_.min_depth_m && point_in_cam.z() <= options_.max_depth_m)) {
      return false;
    }
    Eigen::Vector2d pixel;
    return camera_.Project(point_in_cam, &pixel) &&
           camera_.IsInside(pixel, options_.image_margin_px);
  }

  const Rigid3d& cam_from_world() const { return cam_from_world_; }
  const Eigen::Matrix3d& rotation() const { return rotation_; }

 private:
  const Camera& camera_;
  Rigid3d cam_from_world_;
  Eigen::Matrix3d rotation_;
  const VisibilityQueryOptions& options_;
};

// Integer coordinates of the voxel holding a point.
Eigen::Vector3i VoxelCoordinates(const Eigen::Vector3f& position, double voxel_size) {
  return Eigen::Vector3i(static_cast<int>(std::floor(position.x() / voxel_size)),
                         static_cast<int>(std::floor(position.y() / voxel_size)),
                         static_cast<int>(std::floor(position.z() / voxel_size)));
}

}  // namespace

void VisibilityIndexOptions::Check() const {
  if (!std::isfinite(voxel_size_m) || voxel_size_m <= 0.0) {
    throw InvalidArgumentError("visibility voxel_size_m must be finite and > 0, got " +
                               std::to_string(voxel_size_m));
  }
}

void VisibilityQueryOptions::Check() const {
  if (num_nearest_keyframes < 1) {
    throw InvalidArgumentError("visibility num_nearest_keyframes must be >= 1, got " +
                               std::to_string(num_nearest_keyframes));
  }
  if (!std::isfinite(viewing_angle_weight_m_per_rad) || viewing_angle_weight_m_per_rad < 0.0) {
    throw InvalidArgumentError(
        "visibility viewing_angle_weight_m_per_rad must be finite and >= 0, got " +
        std::to_string(viewing_angle_weight_m_per_rad));
  }
  if (!(max_viewing_angle_rad > 0.0 && max_viewing_angle_rad <= kPi)) {
    throw InvalidArgumentError("visibility max_viewing_angle_rad must be in (0, pi], got " +
                               std::to_string(max_viewing_angle_rad));
  }
  if (!(std::isfinite(min_depth_m) && std::isfinite(max_depth_m) && min_depth_m > 0.0 &&
        min_depth_m < max_depth_m)) {
    throw InvalidArgumentError("visibility depth range needs 0 < min_depth_m < max_depth_m, got [" +
                               std::to_string(min_depth_m) + ", " + std::to_string(max_depth_m) +
                               "]");
  }
  if (!std::isfinite(image_margin_px) || image_margin_px < 0.0) {
    throw InvalidArgumentError("visibility image_margin_px must be finite and >= 0, got " +
                               std::to_string(image_margin_px));
  }
}

VisibilityIndex::VisibilityIndex(const Map& map, const VisibilityIndexOptions& options)
    : map_(map), options_(options) {
  options_.Check();
  const size_t num_keyframes = map.keyframes.size();
  if (map.source_keyframe.size() != map.size() || map.gradients.size() != map.size()) {
    throw InvalidArgumentError("visibility index needs a consistent map; call Map::Check()");
  }
  points_by_source_keyframe_.resize(num_keyframes);
  for (size_t k = 0; k < num_keyframes; ++k) {
    const Keyframe& keyframe = map.keyframes[k];
    if (keyframe.camera_index >= map.cameras.size()) {
      throw InvalidArgumentError("map keyframe " + std::to_string(k) + " uses camera " +
                                 std::to_string(keyframe.camera_index) + " but the map has " +
                                 std::to_string(map.cameras.size()));
    }
    const Rigid3d world_from_keyframe = keyframe.cam_from_world.Inverse();
    keyframe_centres_.push_back(world_from_keyframe.translation);
    keyframe_axes_.push_back(world_from_keyframe.rotation * Eigen::Vector3d::UnitZ());
    if (!keyframe.visible_points.empty()) uses_keyframes_ = true;
  }
  for (size_t i = 0; i < map.size(); ++i) {
    const uint32_t source = map.source_keyframe[i];
    if (source == kNoKeyframe || source >= num_keyframes) continue;
    if (map.keyframes[source].visible_points.empty()) {
      points_by_source_keyframe_[source].push_back(static_cast<uint32_t>(i));
      uses_keyframes_ = true;
    }
  }
  if (!options_.use_keyframes) uses_keyframes_ = false;
  if (uses_keyframes_) return;
  points_by_source_keyframe_.clear();

  // Voxel grid: sort the points by voxel, then record each run of equal voxels.
  std::vector<Eigen::Vector3i> coordinates(map.size());
  for (size_t i = 0; i < map.size(); ++i) {
    coordinates[i] = VoxelCoordinates(map.positions[i], options_.voxel_size_m);
  }
  voxel_points_.resize(map.size());
  std::iota(voxel_points_.begin(), voxel_points_.end(), 0u);
  const auto less = [&coordinates](uint32_t a, uint32_t b) {
    const Eigen::Vector3i& ca = coordinates[a];
    const Eigen::Vector3i& cb = coordinates[b];
    return std::tie(ca.x(), ca.y(), ca.z(), a) < std::tie(cb.x(), cb.y(), cb.z(), b);
  };
  std::sort(voxel_points_.begin(), voxel_points_.end(), less);
  for (size_t begin = 0; begin < voxel_points_.size();) {
    const Eigen::Vector3i& voxel = coordinates[voxel_points_[begin]];
    size_t end = begin + 1;
    while (end < voxel_points_.size() && coordinates[voxel_points_[end]] == voxel) ++end;
    Voxel entry;
    entry.centre = (voxel.cast<double>() + Eigen::Vector3d::Constant(0.5)) * options_.voxel_size_m;
    entry.first = static_cast<uint32_t>(begin);
    entry.count = static_cast<uint32_t>(end - begin);
    voxels_.push_back(entry);
    begin = end;
  }
}

std::vector<uint32_t> VisibilityIndex::NearestKeyframes(
    const Rigid3d& world_from_cam, const VisibilityQueryOptions& options) const {
  options.Check();
  if (!uses_keyframes_) return {};
  const Eigen::Vector3d centre = world_from_cam.translation;
  const Eigen::Vector3d axis = world_from_cam.rotation * Eigen::Vector3d::UnitZ();
  std::vector<std::pair<double, uint32_t>> scored;
  for (size_t k = 0; k < keyframe_centres_.size(); ++k) {
    const double angle = std::acos(std::clamp(axis.dot(keyframe_axes_[k]), -1.0, 1.0));
    if (angle > options.max_viewing_angle_rad) continue;
    const double distance =
        (centre - keyframe_centres_[k]).norm() + options.viewing_angle_weight_m_per_rad * angle;
    scored.emplace_back(distance, static_cast<uint32_t>(k));
  }
  const size_t keep = std::min(scored.size(), static_cast<size_t>(options.num_nearest_keyframes));
  std::partial_sort(scored.begin(), scored.begin() + keep, scored.end());
  std::vector<uint32_t> nearest;
  for (size_t i = 0; i < keep; ++i) nearest.push_back(scored[i].second);
  return nearest;
}

std::vector<uint32_t> VisibilityIndex::Query(const Camera& camera, const Rigid3d& world_from_cam,
                                             const VisibilityQueryOptions& options) const {
  options.Check();
  camera.Check();
  const PointTester tester(camera, world_from_cam, options);
  std::vector<uint32_t> visible;
  if (uses_keyframes_) {
    // A bitmap marks candidates already tested, so points seen by several keyframes are tested
    // (and returned) once.
    std::vector<uint64_t> tested((map_.size() + 63) / 64, 0);
    for (const uint32_t k : NearestKeyframes(world_from_cam, options)) {
      const std::vector<uint32_t>& candidates = map_.keyframes[k].visible_points.empty()
                                                    ? points_by_source_keyframe_[k]
                                                    : map_.keyframes[k].visible_points;
      for (const uint32_t point : candidates) {
        uint64_t& word = tested[point >> 6];
        const uint64_t bit = uint64_t{1} << (point & 63);
        if (word & bit) continue;
        word |= bit;
        if (tester.IsVisible(map_.positions[point])) visible.push_back(point);
      }
    }
  } else {
    const FrustumBounds bounds = ComputeFrustumBounds(camera);
    const double radius = 0.5 * std::sqrt(3.0) * options_.voxel_size_m;
    for (const Voxel& voxel : voxels_) {
      const Eigen::Vector3d centre_in_cam =
          tester.rotation() * voxel.centre + tester.cam_from_world().translation;
      if (!SphereMayBeVisible(centre_in_cam, radius, bounds, options)) continue;
      for (uint32_t i = voxel.first; i < voxel.first + voxel.count; ++i) {
        const uint32_t point = voxel_points_[i];
        if (tester.IsVisible(map_.positions[point])) visible.push_back(point);
      }
    }
  }
  std::sort(visible.begin(), visible.end());
  return visible;
}

namespace {

template <typename T>
uint64_t VectorBytes(const std::vector<T>& values) {
  return values.capacity() * sizeof(T);
}

}  // namespace

uint64_t MapMemoryBytes(const Map& map) {
  uint64_t bytes = sizeof(Map) + VectorBytes(map.positions) + VectorBytes(map.gradients) +
                   VectorBytes(map.inverse_depth_sigma) + VectorBytes(map.gradient_magnitude) +
                   VectorBytes(map.source_keyframe) + VectorBytes(map.cameras);
  for (const Keyframe& keyframe : map.keyframes) {
    bytes +=
        sizeof(Keyframe) + keyframe.image_name.capacity() + VectorBytes(keyframe.visible_points);
  }
  if (map.relocalization) {
    bytes +=
        VectorBytes(map.relocalization->landmarks) + VectorBytes(map.relocalization->vocabulary);
    for (const KeyframeFeatures& features : map.relocalization->keyframes) {
      bytes += sizeof(KeyframeFeatures) + VectorBytes(features.keypoints) +
               VectorBytes(features.descriptors) + VectorBytes(features.landmarks) +
               VectorBytes(features.global_descriptor);
    }
  }
  // The visibility index: one point index per point (voxel order or per source keyframe), one
  // voxel record at most per point, and a centre and an axis per keyframe.
  bytes += map.size() * (sizeof(uint32_t) + 32) + map.keyframes.size() * 48;
  return bytes;
}

}  // namespace evloc
