// evloc-track --mode vo | devo: the mapless odometry of localizer/odometry over a dataset, its
// estimates reported as the tracker's PoseEstimate steps so that evloc-track writes the same
// trajectory, statistics and summary for every mode.
#pragma once

#include <cstdint>
#include <optional>
#include <ostream>

#include "core/dataset/dataset.h"
#include "core/geometry/rigid3.h"
#include "localizer/odometry/odometry_run.h"
#include "localizer/offline/offline_tracking.h"

namespace evloc::tracking {

// Runs `mode` over `dataset` from its first frame at or after `initial_t_ns` (DEVO: after a
// warm-up), which starts at `initial_world_from_cam` when given, else at the ground truth there;
// progress goes to `log` unless `quiet`. A frame (or step) that was not tracked is a LOST step
// whose pose is the prediction. `devo` holds DEVO's options (unused by VO). Throws what the
// odometry throws.
OfflineTrackingResult RunOdometryTrack(const Dataset& dataset, odometry::OdometryMode mode,
                                       const odometry::DevoRunOptions& devo,
                                       const std::optional<Rigid3d>& initial_world_from_cam,
                                       int64_t initial_t_ns, bool quiet, std::ostream& log);

}  // namespace evloc::tracking
