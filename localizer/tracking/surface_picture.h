// Pictures of a tracker's time surface with the map reprojected onto it: the first panel of
// evloc-track's debug pictures (localizer/offline/debug_images.h) and the live viewer's time
// surface of a session (docs/viewer.md).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "localizer/tracking/map_source.h"
#include "localizer/tracking/time_surface.h"
#include "localizer/tracking/tracker.h"

namespace evloc::tracking {

// The tracker's time surface `channel` at `t_ns` with its decay (CV_8UC1, the sensor's size):
// 255 for an event at t_ns, falling to 0 with the decay time.
cv::Mat TimeSurfacePicture(const Tracker& tracker, SurfaceChannel channel, int64_t t_ns);

// Draws the points `indices` of `positions` seen from `world_from_cam` through `camera` onto
// `picture` (CV_8UC3, the size of `surface`) as dots: green where `surface` (CV_8UC1) is not 0
// (on an active pixel), red elsewhere. Points behind the camera or outside the image are skipped.
void DrawReprojectedPoints(const Camera& camera, std::span<const Eigen::Vector3f> positions,
                           const std::vector<uint32_t>& indices, const Rigid3d& world_from_cam,
                           const cv::Mat& surface, cv::Mat* picture);

// The unsigned time surface at `t_ns` (grey) with the map points `source` says may be visible
// from `world_from_cam` reprojected onto it (DrawReprojectedPoints), CV_8UC3.
cv::Mat SurfaceWithReprojectedMap(const Tracker& tracker, const MapSource& source,
                                  const Rigid3d& world_from_cam, int64_t t_ns);

}  // namespace evloc::tracking
