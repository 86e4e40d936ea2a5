// Merging the keyframes' semi-dense points into one map (docs/mapper.md, "Merge"): duplicates
// within a voxel that agree in gradient direction become one point, statistical outliers are
// removed (PCL), and each keyframe's visibility index lists exactly the surviving points it
// observed.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "maps/map.h"

namespace evloc::mapper {

// A point of one keyframe before merging.
struct CandidatePoint {
  // Position in the world, metres.
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  // Unit 3D gradient direction in the world.
  Eigen::Vector3d gradient = Eigen::Vector3d::UnitX();
  // Standard deviation of the inverse depth, 1/m.
  double inverse_depth_sigma = 0.0;
  // Standard deviation of the position along the ray, metres (merging weight).
  double position_sigma = 0.0;
  // Size of one pixel at the point's depth, metres (sets the automatic voxel size).
  double pixel_footprint = 0.0;
  // Image gradient modulus at the source pixel.
  double gradient_magnitude = 0.0;
  // Index of the source keyframe.
  uint32_t source_keyframe = 0;
  // Keyframes observing the point: the source and those that confirmed it.
  std::vector<uint32_t> observing_keyframes;
};

// Options of MergePoints.
struct MapMergeOptions {
  // Voxel edge for duplicate merging, metres; std::nullopt: voxel_size_px times the median pixel
  // footprint of the points.
  std::optional<double> voxel_size;
  // Automatic voxel edge in pixels at the points' depth.
  double voxel_size_px = 1.0;
  // Points of one voxel merge only when their gradients agree within this angle, degrees.
  double max_gradient_angle_deg = 45.0;
  // Statistical outlier removal: neighbours considered per point (0 disables the removal).
  int outlier_neighbours = 10;
  // Statistical outlier removal: a point is an outlier when its mean neighbour distance exceeds
  // the global mean by this many standard deviations.
  double outlier_std_ratio = 2.0;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// Counts of the merge, for reports.
struct MergeStatistics {
  // Points given.
  size_t input_points = 0;
  // Points after duplicate merging.
  size_t merged_points = 0;
  // Points after outlier removal (the map's size).
  size_t output_points = 0;
  // Voxel edge used, metres.
  double voxel_size = 0.0;
};

// Merges `points` into `map` (whose keyframes must already be set; existing points are replaced)
// and rebuilds every keyframe's visible_points. Throws InvalidArgumentError when the options are
// bad or a point refers to a keyframe `map` does not have.
MergeStatistics MergePoints(const std::vector<CandidatePoint>& points,
                            const MapMergeOptions& options, Map* map);

}  // namespace evloc::mapper
