// The map a Tracker registers against, behind an interface: today's fixed Map with its
// VisibilityIndex (StaticMapSource), and later a local map that grows during mapless odometry or
// tiles swapped mid-session. The tracker asks the source for the candidate points visible from
// a predicted pose and reads the point positions and gradients through MapPoints spans, fetched
// once per generation, so the per-point loops make no virtual call (docs/tracking.md, "Map
// source").
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "maps/map.h"
#include "maps/visibility.h"

namespace evloc::tracking {

// A read-only view of the point arrays of one generation of a MapSource.
struct MapPoints {
  // Positions p_world, metres, indexed by point index.
  std::span<const Eigen::Vector3f> positions;
  // Unit 3D gradient directions g_world, one per position.
  std::span<const Eigen::Vector3f> gradients;

  // Number of points.
  size_t size() const { return positions.size(); }
};

// Where a global search (relocalization) asks for starting viewpoints.
struct ViewpointQuery {
  // Viewpoints sampled between two consecutive keyframes (in time order), besides the keyframes.
  int samples_between_keyframes = 2;
  // When set, only viewpoints whose camera centre lies within search_radius_m of this position
  // (world frame, metres) are returned.
  std::optional<Eigen::Vector3d> search_center;
  // Radius around search_center, metres.
  double search_radius_m = 0;
};

// Throws InvalidArgumentError starting with `what` unless a search region's centre is finite and
// its radius positive (Tracker::SetSearchPrior, TiledMapSource::SetSearchRegion, an offline
// run's search prior).
void CheckSearchRegion(const Eigen::Vector3d& center, double radius_m, const std::string& what);

// The points a tracker registers against. Contract: the spans returned by points() and the
// indices returned by VisibleCandidates stay valid and unchanged as long as generation() returns
// the same value; whoever changes the point set (adds, removes, moves or swaps points) changes
// the generation, and does so only between two calls into the tracker (the tracker is not
// thread-safe, neither is this hand-over).
class MapSource {
 public:
  virtual ~MapSource() = default;

  // A counter that changes whenever the point set changes; the tracker drops its cached point
  // selection and re-reads points() when it differs from the value it saw last.
  virtual uint64_t generation() const = 0;

  // The point arrays of the current generation.
  virtual MapPoints points() const = 0;

  // Replaces `candidates` with the indices (ascending) of the points that may be visible from
  // `world_from_cam` with `camera` under the depth range and image margin of `options`; the
  // tracker's own selection projects them again, so a superset (every point) is correct, only
  // slower.
  virtual void VisibleCandidates(const Camera& camera, const Rigid3d& world_from_cam,
                                 const VisibilityQueryOptions& options,
                                 std::vector<uint32_t>* candidates) const = 0;

  // Replaces `world_from_cams` with the viewpoints a global search starts from (the tracker adds
  // perturbations around each). The default returns none: a source without viewpoints cannot
  // relocalize, and the tracker keeps searching without result.
  virtual void CandidateViewpoints(const ViewpointQuery& query,
                                   std::vector<Rigid3d>* world_from_cams) const;
};

// The viewpoints of a global search over keyframes given as (time, world_from_cam): each keyframe
// and query.samples_between_keyframes poses interpolated between consecutive ones in time order
// (equal times keep their order), those outside the query's search region dropped.
void ViewpointsAlongKeyframes(std::vector<std::pair<int64_t, Rigid3d>> keyframes,
                              const ViewpointQuery& query, std::vector<Rigid3d>* world_from_cams);

// A fixed Map, with an optional VisibilityIndex built on it: generation 0 forever. Without an
// index every point is a candidate.
class StaticMapSource final : public MapSource {
 public:
  // `map` (and `visibility`, when given) must outlive the source. Throws InvalidArgumentError
  // when the map has not one gradient per point.
  explicit StaticMapSource(const Map& map, const VisibilityIndex* visibility = nullptr);

  // Always 0: the map never changes.
  uint64_t generation() const override { return 0; }
  // The map's positions and gradients.
  MapPoints points() const override { return {map_.positions, map_.gradients}; }
  // VisibilityIndex::Query, or every point without an index.
  void VisibleCandidates(const Camera& camera, const Rigid3d& world_from_cam,
                         const VisibilityQueryOptions& options,
                         std::vector<uint32_t>* candidates) const override;
  // The map's keyframe poses and the poses interpolated between consecutive keyframes (ordered
  // by time), filtered by the query's search region.
  void CandidateViewpoints(const ViewpointQuery& query,
                           std::vector<Rigid3d>* world_from_cams) const override;

 private:
  const Map& map_;
  const VisibilityIndex* visibility_;
};

}  // namespace evloc::tracking
