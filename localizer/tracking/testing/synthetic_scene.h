// Synthetic scenes for the tracking tests and benchmark: bright planar rectangles at several
// depths (their outlines as map points with in-plane gradients pointing inwards, towards the
// bright side), a smooth camera motion, ideal edge events and rendered frames.
#pragma once

#include <cstdint>
#include <functional>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/events/event.h"
#include "core/geometry/rigid3.h"
#include "localizer/tracking/map_source.h"
#include "maps/map.h"

namespace evloc::tracking::testing {

// A camera trajectory: world_from_cam at a time.
using TrajectoryFunction = std::function<Rigid3d(int64_t t_ns)>;

// One bright rectangle: centre, two orthonormal in-plane axes, half sizes.
struct Rectangle {
  // Centre in the world, metres.
  Eigen::Vector3d centre;
  // Unit in-plane axis of the first side.
  Eigen::Vector3d axis_u;
  // Unit in-plane axis of the second side (orthogonal to axis_u).
  Eigen::Vector3d axis_v;
  // Half length along axis_u, metres.
  double half_u;
  // Half length along axis_v, metres.
  double half_v;
};

// The rectangles of the default scene, in front of a camera at the origin looking down +z
// (depths 1.5 to 3.5 m, two of them tilted so that every pose direction is observable).
std::vector<Rectangle> DefaultRectangles();

// The outlines of `rectangles` sampled every `spacing_m`, gradients pointing inwards.
Map MakeRectangleMap(const std::vector<Rectangle>& rectangles, double spacing_m);

// Adds keyframes (camera `camera`, appended to map->cameras) along SmoothMotion every
// `period_ns` from 0 to `end_ns`, each displaced by the body-frame twist `displacement` and
// shifted by `shift` in the world: the viewpoints of a map built from another pass.
void AddKeyframesBesideThePath(Map* map, const Camera& camera, int64_t end_ns, int64_t period_ns,
                               const Vector6d& displacement,
                               const Eigen::Vector3d& shift = Eigen::Vector3d::Zero());

// DefaultRectangles and a copy of them shifted by `shift`: a scene of two identical places.
std::vector<Rectangle> TwinRectangles(const Eigen::Vector3d& shift);

// A smooth motion starting at the identity: translation (0.3, 0.1, 0.15) m/s with a slow
// sinusoid, rotation rates (0.15, -0.25, 0.1) rad/s, scaled by `speed`.
Rigid3d SmoothMotion(int64_t t_ns, double speed = 1.0);

// Distance between the camera centre of `world_from_cam` and SmoothMotion(t_ns), metres.
double PositionErrorToSmoothMotion(const Rigid3d& world_from_cam, int64_t t_ns);

// Angle between the orientation of `world_from_cam` and SmoothMotion(t_ns), radians.
double RotationErrorToSmoothMotion(const Rigid3d& world_from_cam, int64_t t_ns);

// When SimulateEdgeEvents fires a pixel.
enum class EdgeEventTiming {
  // When the point enters the pixel (its rounded pixel changes), half a pixel of motion before
  // the edge reaches the pixel's centre. The freshest pixels then lie where the edge is at the
  // step time on average: the registered pose has no lag, and moving it forward by the surface's
  // age (TrackerOptions::stamp_at_step_time) overshoots.
  kEnterPixel,
  // When the point crosses the pixel's centre, as an area-sampled pixel whose contrast threshold
  // is half the edge's step fires (and as evloc-sim's rendered events do): the freshest pixels
  // trail the edge by up to a pixel, and the registered pose lags the step time by their age.
  kCrossCentre,
};

// Ideal edge events of the map points seen by a pinhole `camera` moving along `trajectory`:
// rendered every `render_period_ns` in [t_begin_ns, t_end_ns]; a point emits an event at a
// pixel as `timing` says, with polarity sign(-d . f) (brightness constancy, d the projected
// gradient, f the pixel motion). Sorted by time.
EventBuffer SimulateEdgeEvents(const Map& map, const Camera& camera,
                               const TrajectoryFunction& trajectory, int64_t t_begin_ns,
                               int64_t t_end_ns, int64_t render_period_ns = 100'000,
                               EdgeEventTiming timing = EdgeEventTiming::kEnterPixel);

// A grey frame (CV_8UC1) of the bright rectangles (200) on a dark background (40), seen from
// `world_from_cam` by a pinhole `camera`, painted far to near.
cv::Mat RenderRectangles(const std::vector<Rectangle>& rectangles, const Camera& camera,
                         const Rigid3d& world_from_cam);

// The events with first_ns < t_ns <= last_ns.
EventBuffer EventsBetween(const EventBuffer& events, int64_t first_ns, int64_t last_ns);

// A MapSource whose point set is swapped for another map between calls into the tracker, each
// swap a new generation (a local map that grows, a tile replaced mid-session, the tiles near a
// GNSS fix arriving during a search); its candidates and viewpoints are those of the map it
// serves (StaticMapSource without a visibility index).
class SwappingMapSource final : public MapSource {
 public:
  explicit SwappingMapSource(const Map* map) : map_(map) {}
  void Swap(const Map* map) {
    map_ = map;
    ++generation_;
  }
  uint64_t generation() const override { return generation_; }
  MapPoints points() const override { return {map_->positions, map_->gradients}; }
  void VisibleCandidates(const Camera& camera, const Rigid3d& world_from_cam,
                         const VisibilityQueryOptions& options,
                         std::vector<uint32_t>* candidates) const override {
    StaticMapSource(*map_).VisibleCandidates(camera, world_from_cam, options, candidates);
  }
  void CandidateViewpoints(const ViewpointQuery& query,
                           std::vector<Rigid3d>* world_from_cams) const override {
    StaticMapSource(*map_).CandidateViewpoints(query, world_from_cams);
  }

 private:
  const Map* map_;
  uint64_t generation_ = 0;
};

}  // namespace evloc::tracking::testing
