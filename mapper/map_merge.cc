#include "mapper/map_merge.h"

#include <pcl/filters/statistical_outlier_removal.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <unordered_map>

#include "core/common/error.h"

namespace evloc::mapper {
namespace {

struct VoxelKey {
  int64_t x, y, z;
  bool operator==(const VoxelKey&) const = default;
};

struct VoxelKeyHash {
  size_t operator()(const VoxelKey& key) const {
    return static_cast<size_t>(key.x * 73856093LL ^ key.y * 19349663LL ^ key.z * 83492791LL);
  }
};

double Weight(const CandidatePoint& point) {
  return point.position_sigma > 0.0 ? 1.0 / (point.position_sigma * point.position_sigma) : 1.0;
}

}  // namespace

void MapMergeOptions::Check() const {
  if (voxel_size && !(*voxel_size > 0.0)) throw InvalidArgumentError("voxel_size must be > 0");
  if (!(voxel_size_px > 0.0)) throw InvalidArgumentError("voxel_size_px must be > 0");
  if (!(max_gradient_angle_deg > 0.0 && max_gradient_angle_deg <= 180.0)) {
    throw InvalidArgumentError("max_gradient_angle_deg must be in (0, 180]");
  }
  if (outlier_neighbours < 0) throw InvalidArgumentError("outlier_neighbours must be >= 0");
  if (!(outlier_std_ratio > 0.0)) throw InvalidArgumentError("outlier_std_ratio must be > 0");
}

MergeStatistics MergePoints(const std::vector<CandidatePoint>& points,
                            const MapMergeOptions& options, Map* map) {
  options.Check();
  const size_t num_keyframes = map->keyframes.size();
  for (const CandidatePoint& point : points) {
    const bool valid_source = point.source_keyframe < num_keyframes;
    const bool valid_observers =
        std::all_of(point.observing_keyframes.begin(), point.observing_keyframes.end(),
                    [&](uint32_t keyframe) { return keyframe < num_keyframes; });
    if (!valid_source || !valid_observers) {
      throw InvalidArgumentError("MergePoints: a point refers to a keyframe the map does not have");
    }
  }
  MergeStatistics statistics;
  statistics.input_points = points.size();

  double voxel_size = 0.0;
  if (options.voxel_size) {
    voxel_size = *options.voxel_size;
  } else {
    std::vector<double> footprints;
    for (const CandidatePoint& point : points) {
      if (point.pixel_footprint > 0.0) footprints.push_back(point.pixel_footprint);
    }
    if (!footprints.empty()) {
      const auto middle = footprints.begin() + footprints.size() / 2;
      std::nth_element(footprints.begin(), middle, footprints.end());
      voxel_size = options.voxel_size_px * *middle;
    } else {
      voxel_size = 1e-3;
    }
  }
  statistics.voxel_size = voxel_size;

  // Group by voxel, then split each voxel into clusters of agreeing gradients around the most
  // certain member.
  std::unordered_map<VoxelKey, std::vector<uint32_t>, VoxelKeyHash> voxels;
  for (uint32_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d cell = (points[i].position / voxel_size).array().floor();
    voxels[{static_cast<int64_t>(cell.x()), static_cast<int64_t>(cell.y()),
            static_cast<int64_t>(cell.z())}]
        .push_back(i);
  }
  struct Merged {
    Eigen::Vector3d position;
    Eigen::Vector3d gradient;
    double inverse_depth_sigma;
    double gradient_magnitude;
    uint32_t source_keyframe;
    std::vector<uint32_t> observers;
  };
  std::vector<Merged> merged;
  const double min_cos = std::cos(options.max_gradient_angle_deg * std::numbers::pi / 180.0);
  // Deterministic order: process voxels by their first point index.
  std::vector<const std::vector<uint32_t>*> ordered;
  ordered.reserve(voxels.size());
  for (const auto& [key, members] : voxels) ordered.push_back(&members);
  std::sort(ordered.begin(), ordered.end(),
            [](const auto* a, const auto* b) { return a->front() < b->front(); });
  for (const std::vector<uint32_t>* voxel : ordered) {
    std::vector<uint32_t> remaining = *voxel;
    std::sort(remaining.begin(), remaining.end(), [&](uint32_t a, uint32_t b) {
      return Weight(points[a]) != Weight(points[b]) ? Weight(points[a]) > Weight(points[b]) : a < b;
    });
    while (!remaining.empty()) {
      const CandidatePoint& seed = points[remaining.front()];
      Merged cluster{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), seed.inverse_depth_sigma,
                     seed.gradient_magnitude, seed.source_keyframe,    {}};
      double weight_sum = 0.0;
      std::vector<uint32_t> rest;
      for (const uint32_t index : remaining) {
        const CandidatePoint& member = points[index];
        if (member.gradient.dot(seed.gradient) < min_cos) {
          rest.push_back(index);
          continue;
        }
        const double weight = Weight(member);
        cluster.position += weight * member.position;
        cluster.gradient += weight * member.gradient;
        weight_sum += weight;
        cluster.observers.push_back(member.source_keyframe);
        cluster.observers.insert(cluster.observers.end(), member.observing_keyframes.begin(),
                                 member.observing_keyframes.end());
      }
      cluster.position /= weight_sum;
      cluster.gradient =
          cluster.gradient.norm() > 1e-12 ? cluster.gradient.normalized() : seed.gradient;
      std::sort(cluster.observers.begin(), cluster.observers.end());
      cluster.observers.erase(std::unique(cluster.observers.begin(), cluster.observers.end()),
                              cluster.observers.end());
      merged.push_back(std::move(cluster));
      remaining = std::move(rest);
    }
  }
  statistics.merged_points = merged.size();

  // Statistical outlier removal.
  std::vector<int> kept;
  if (options.outlier_neighbours > 0 &&
      merged.size() > static_cast<size_t>(options.outlier_neighbours)) {
    pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
    cloud->reserve(merged.size());
    for (const Merged& point : merged) {
      cloud->push_back(pcl::PointXYZ(static_cast<float>(point.position.x()),
                                     static_cast<float>(point.position.y()),
                                     static_cast<float>(point.position.z())));
    }
    pcl::StatisticalOutlierRemoval<pcl::PointXYZ> filter;
    filter.setInputCloud(cloud);
    filter.setMeanK(options.outlier_neighbours);
    filter.setStddevMulThresh(options.outlier_std_ratio);
    pcl::Indices indices;
    filter.filter(indices);
    kept.assign(indices.begin(), indices.end());
    std::sort(kept.begin(), kept.end());
  } else {
    kept.resize(merged.size());
    for (size_t i = 0; i < merged.size(); ++i) kept[i] = static_cast<int>(i);
  }

  map->positions.clear();
  map->gradients.clear();
  map->inverse_depth_sigma.clear();
  map->gradient_magnitude.clear();
  map->source_keyframe.clear();
  map->Reserve(kept.size());
  for (Keyframe& keyframe : map->keyframes) keyframe.visible_points.clear();
  for (const int index : kept) {
    const Merged& point = merged[index];
    const uint32_t point_index = static_cast<uint32_t>(map->size());
    map->AddPoint(point.position.cast<float>(), point.gradient.cast<float>().normalized(),
                  static_cast<float>(point.inverse_depth_sigma),
                  static_cast<float>(point.gradient_magnitude), point.source_keyframe);
    for (const uint32_t keyframe : point.observers) {
      map->keyframes[keyframe].visible_points.push_back(point_index);
    }
  }
  statistics.output_points = map->size();
  return statistics;
}

}  // namespace evloc::mapper
