// evloc-track --handover: map tracking that hands over to Canny-DEVO where the map is not seen
// and comes back once the map is seen again and the pose verified (localizer/odometry/handover.h,
// docs/tracking.md "Hand-over"), over a dataset with events and depth.
#pragma once

#include <cstdint>

#include "core/dataset/dataset.h"
#include "core/geometry/rigid3.h"
#include "localizer/odometry/handover.h"
#include "localizer/offline/offline_tracking.h"
#include "maps/map.h"
#include "maps/visibility.h"

namespace evloc::tracking {

// What a hand-over run did besides the steps.
struct HandoverTrackResult {
  // The steps (one pose per map step, from the map or from odometry) and the trajectory; its
  // pose_sources say which.
  OfflineTrackingResult result;
  // The hand-over's counts.
  odometry::HandoverCounts counts;
};

// Tracks the events of `dataset` against `map` from `initial_world_from_cam` at `initial_t_ns`
// (events before it prime the time surfaces) with the hand-over to Canny-DEVO on the dataset's
// depth (odometry::DevoDepthStream: its depth camera, else depth.txt). Events are fed one step
// period at a time and each depth frame once every event up to its time has been given. Calls
// `on_step` after every reported pose (the tracker is the map tracker). Throws
// InvalidArgumentError when the dataset has no events or no depth, and what the readers throw.
HandoverTrackResult TrackWithHandover(const Dataset& dataset, const Map& map,
                                      const VisibilityIndex* visibility,
                                      const Rigid3d& initial_world_from_cam, int64_t initial_t_ns,
                                      const OfflineTrackingOptions& options,
                                      const odometry::HandoverOptions& handover,
                                      const StepCallback& on_step = {});

}  // namespace evloc::tracking
