#include "localizer/offline/odometry_track.h"

#include <algorithm>

namespace evloc::tracking {

OfflineTrackingResult RunOdometryTrack(const Dataset& dataset, odometry::OdometryMode mode,
                                       const odometry::DevoRunOptions& devo,
                                       const std::optional<Rigid3d>& initial_world_from_cam,
                                       int64_t initial_t_ns, bool quiet, std::ostream& log) {
  OfflineTrackingResult result;
  if (mode == odometry::OdometryMode::kVo) {
    if (!quiet) {
      log << "evloc-track: Canny-VO on " << dataset.root.string() << " (" << dataset.images.size()
          << " images, " << dataset.depth.size() << " depth maps)\n";
    }
    int64_t frame = 0;
    const odometry::VoRunResult run = odometry::RunCannyVo(
        dataset, initial_world_from_cam, initial_t_ns, odometry::VoRunOptions(),
        [&](const odometry::VoEstimate& estimate) {
          if (!quiet && frame % 100 == 0) {
            log << "  t=" << static_cast<double>(estimate.t_ns - initial_t_ns) * 1e-9 << " s  "
                << (estimate.tracked ? "TRACKING" : "LOST") << "  points " << estimate.points_used
                << "  inliers " << estimate.inlier_fraction << "\n";
          }
          ++frame;
        });
    for (const odometry::VoEstimate& estimate : run.steps) {
      PoseEstimate step;
      step.t_ns = estimate.t_ns;
      step.world_from_cam = estimate.world_from_cam;
      step.covariance = estimate.covariance;
      step.status = estimate.tracked ? TrackingStatus::kTracking : TrackingStatus::kLost;
      step.quality.points_used = estimate.points_used;
      step.quality.points_selected = estimate.points_used;
      step.quality.on_edge_fraction = estimate.inlier_fraction;
      step.quality.alignment = estimate.inlier_fraction;
      step.quality.iterations = estimate.iterations;
      step.timings.surface_ms = estimate.fields_ms;
      step.timings.selection_ms = estimate.keyframe_ms;
      step.timings.solve_ms = estimate.solve_ms;
      step.timings.total_ms = estimate.total_ms;
      result.steps.push_back(step);
    }
    result.trajectory = run.trajectory;
    result.measurements = static_cast<int64_t>(run.steps.size());
    result.lost_steps = run.untracked_frames;
    result.wall_s = run.wall_s;
    if (!quiet) log << "evloc-track: " << run.keyframes << " keyframes\n";
    return result;
  }
  if (!quiet) {
    log << "evloc-track: Canny-DEVO on " << dataset.root.string() << " (events, "
        << dataset.depth.size() << " depth maps)\n";
  }
  int64_t step_index = 0;
  const odometry::DevoRunResult run = odometry::RunCannyDevo(
      dataset, initial_world_from_cam, initial_t_ns, devo, [&](const PoseEstimate& step) {
        if (!quiet && step_index % 300 == 0) {
          log << "  t=" << static_cast<double>(step.t_ns - initial_t_ns) * 1e-9 << " s  "
              << TrackingStatusName(step.status) << "  points " << step.quality.points_used
              << "  on-edge " << step.quality.on_edge_fraction << "\n";
        }
        ++step_index;
      });
  result.steps = run.steps;
  result.trajectory = run.trajectory;
  result.measurements = run.events;
  result.lost_steps = run.lost_steps;
  result.wall_s = run.wall_s;
  for (const odometry::ReferenceFrameInfo& reference : run.reference_frames) {
    ReferenceFrameRecord record;
    record.t_s = static_cast<double>(reference.t_ns - initial_t_ns) * 1e-9;
    record.points = reference.points;
    record.semi_dense_pixels = reference.stats.semi_dense_pixels;
    record.median_depth_m = reference.median_depth_m;
    record.build_ms = reference.build_ms;
    record.build_cpu_ms = reference.build_cpu_ms;
    result.reference_frames.push_back(record);
  }
  if (!quiet) {
    double build_ms = 0;
    for (const odometry::ReferenceFrameInfo& reference : run.reference_frames) {
      build_ms = std::max(build_ms, reference.build_ms);
      log << "  reference frame t=" << static_cast<double>(reference.t_ns - initial_t_ns) * 1e-9
          << " s: " << reference.points << " points of " << reference.stats.semi_dense_pixels
          << " semi-dense pixels, median depth " << reference.median_depth_m << " m, decay "
          << reference.decay_time_s * 1e3 << " ms, built in " << reference.build_ms << " ms ("
          << reference.build_cpu_ms << " ms CPU)\n";
    }
    log << "evloc-track: " << run.reference_frames.size() << " reference frames (longest build "
        << build_ms << " ms)\n";
  }
  return result;
}

}  // namespace evloc::tracking
