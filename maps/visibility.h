// Which map points a camera sees from a predicted pose (docs/map-format.md, docs/map-format.md
// "Visibility"). Maps with keyframes: the keyframes nearest the pose (by position and viewing
// direction) give the candidates. Maps without (imported PCD): a voxel grid of the points, culled
// with the camera frustum, gives them. Either way every candidate then passes a per-point depth
// and projection test with Camera::Project.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "maps/map.h"

namespace evloc {

// How a VisibilityIndex is built.
struct VisibilityIndexOptions {
  // Edge length of the voxels of the synthesised index used for maps without keyframe
  // visibility, metres. Smaller voxels cull tighter but cost more per query.
  double voxel_size_m = 0.25;
  // Use the keyframes' visibility when the map has it; false always builds the voxel grid (the
  // tiles of a site: a tile's keyframes do not list the points of its neighbours they see).
  bool use_keyframes = true;

  // Throws InvalidArgumentError unless voxel_size_m is finite and > 0.
  void Check() const;
};

// What a visibility query keeps.
struct VisibilityQueryOptions {
  // Number of keyframes nearest the predicted pose whose points are candidates (keyframe maps).
  int num_nearest_keyframes = 5;
  // Weight of the viewing-direction difference in the keyframe distance, metres per radian:
  // distance = |centre - keyframe centre| + weight * angle between the optical axes.
  double viewing_angle_weight_m_per_rad = 0.5;
  // Keyframes whose optical axis is further than this from the query's are never selected,
  // radians.
  double max_viewing_angle_rad = 1.5707963267948966;
  // Points nearer than this along the optical axis are not visible, metres.
  double min_depth_m = 0.05;
  // Points further than this along the optical axis are not visible, metres.
  double max_depth_m = 50.0;
  // Points projecting closer than this to the image border are not visible, pixels.
  double image_margin_px = 0.0;

  // Throws InvalidArgumentError unless num_nearest_keyframes >= 1, the weight and margin are
  // finite and >= 0, the angle is in (0, pi], and 0 < min_depth_m < max_depth_m (finite).
  void Check() const;
};

// A visibility index over one map, built once and shared: Query is const and thread-safe, so
// many tracking sessions can query one index concurrently. The index keeps a reference to the
// map, which must outlive it and must not change while it exists.
class VisibilityIndex {
 public:
  // Builds the index. Uses the keyframes when at least one keyframe lists visible points or is
  // the source keyframe of some point; otherwise builds a voxel grid of the points. Throws
  // InvalidArgumentError when the options are invalid.
  explicit VisibilityIndex(const Map& map, const VisibilityIndexOptions& options = {});

  // Indices of the points visible from `world_from_cam` with `camera`, ascending: candidates
  // from the nearest keyframes (or the voxels that intersect the frustum), kept when their depth
  // is within [min_depth_m, max_depth_m] and they project inside the image with the margin.
  // Throws InvalidArgumentError when the options or the camera are invalid.
  std::vector<uint32_t> Query(const Camera& camera, const Rigid3d& world_from_cam,
                              const VisibilityQueryOptions& options = {}) const;

  // Indices of the keyframes used for a query at `world_from_cam`, nearest first (empty for a
  // voxel index).
  std::vector<uint32_t> NearestKeyframes(const Rigid3d& world_from_cam,
                                         const VisibilityQueryOptions& options = {}) const;

  // True when queries use keyframes, false when they use the voxel grid.
  bool uses_keyframes() const { return uses_keyframes_; }
  // Number of occupied voxels (0 for a keyframe index).
  size_t num_voxels() const { return voxels_.size(); }

 private:
  // An occupied voxel: its centre and its points, a range of voxel_points_.
  struct Voxel {
    Eigen::Vector3d centre;
    uint32_t first = 0;
    uint32_t count = 0;
  };

  const Map& map_;
  VisibilityIndexOptions options_;
  bool uses_keyframes_ = false;
  // Keyframe centres and optical axes in the world frame.
  std::vector<Eigen::Vector3d> keyframe_centres_;
  std::vector<Eigen::Vector3d> keyframe_axes_;
  // Candidates of keyframes that list no visible points: the points they are the source of.
  std::vector<std::vector<uint32_t>> points_by_source_keyframe_;
  // Voxel grid (maps without keyframe visibility).
  std::vector<Voxel> voxels_;
  std::vector<uint32_t> voxel_points_;
};

// Estimated memory of `map` with a visibility index, bytes: its arrays plus the index's (what
// the service's map and tile caches count against their budget).
uint64_t MapMemoryBytes(const Map& map);

}  // namespace evloc
