#include "localizer/offline/handover_track.h"

#include <algorithm>
#include <chrono>
#include <memory>

#include "core/common/error.h"
#include "core/events/event_reader.h"
#include "localizer/odometry/odometry_run.h"

namespace evloc::tracking {

HandoverTrackResult TrackWithHandover(const Dataset& dataset, const Map& map,
                                      const VisibilityIndex* visibility,
                                      const Rigid3d& initial_world_from_cam, int64_t initial_t_ns,
                                      const OfflineTrackingOptions& options,
                                      const odometry::HandoverOptions& handover,
                                      const StepCallback& on_step) {
  options.Check();
  if (options.tracker.events_per_step) {
    throw InvalidArgumentError("--handover needs fixed-rate steps (no --events-per-step)");
  }
  const auto start = std::chrono::steady_clock::now();
  const DepthCameraStream depth = odometry::DevoDepthStream(dataset);
  const std::unique_ptr<EventReader> reader = OpenDatasetEvents(dataset);
  const StaticMapSource source(map, visibility);
  Tracker tracker(source, dataset.camera, options.tracker);
  odometry::MapOdometryHandover runner(tracker, source, dataset.camera, depth.camera,
                                       depth.event_from_depth, handover);
  HandoverTrackResult run;
  OfflineTrackingResult& result = run.result;
  auto record = [&](const std::vector<odometry::HandoverEstimate>& estimates) {
    for (const odometry::HandoverEstimate& estimate : estimates) {
      const PoseEstimate& step = estimate.estimate;
      if (estimate.source == odometry::PoseSource::kOdometry ||
          step.status == TrackingStatus::kTracking || step.status == TrackingStatus::kLost) {
        result.trajectory.Append({step.t_ns, step.world_from_cam});
      }
      if (step.status == TrackingStatus::kLost) ++result.lost_steps;
      result.steps.push_back(step);
      result.pose_sources.push_back(odometry::PoseSourceName(estimate.source));
      if (on_step) on_step(step, tracker);
    }
  };
  const int64_t period_ns = std::max<int64_t>(1, std::llround(1e9 / options.tracker.step_rate_hz));
  size_t next_depth = 0;
  bool started = false;
  EventBuffer batch;
  EventBuffer part;
  // Feeds events [begin, end) of the batch, one step period at a time.
  auto feed = [&](size_t begin, size_t end) {
    while (begin < end) {
      const int64_t limit = batch.t_ns[begin] + period_ns;
      const size_t stop = static_cast<size_t>(
          std::upper_bound(batch.t_ns.begin() + begin, batch.t_ns.begin() + end, limit) -
          batch.t_ns.begin());
      part.clear();
      part.Append(batch, begin, stop - begin);
      record(runner.AddEvents(part));
      begin = stop;
    }
  };
  while (true) {
    batch.clear();
    if (reader->Read(options.read_batch_events, &batch) == 0) break;
    result.measurements += static_cast<int64_t>(batch.size());
    size_t begin = 0;
    while (begin < batch.size()) {
      // The next boundary: the start (the tracker is reset there) or the next depth frame.
      int64_t boundary = INT64_MAX;
      if (!started) boundary = initial_t_ns;
      if (next_depth < depth.frames.size()) {
        boundary = std::min(boundary, depth.frames[next_depth].t_ns);
      }
      const size_t end = static_cast<size_t>(
          std::upper_bound(batch.t_ns.begin() + begin, batch.t_ns.end(), boundary) -
          batch.t_ns.begin());
      feed(begin, end);
      begin = end;
      if (begin == batch.size()) break;  // the boundary may still get events in the next batch
      if (!started && boundary == initial_t_ns) {
        tracker.Reset(initial_world_from_cam, initial_t_ns);
        started = true;
      }
      if (next_depth < depth.frames.size() && depth.frames[next_depth].t_ns == boundary) {
        const TimedFile& file = depth.frames[next_depth];
        record(runner.AdvanceTo(file.t_ns));
        runner.AddDepthFrame(file.t_ns, ReadDepthPng(file.path, depth.units_per_metre));
        ++next_depth;
      }
    }
  }
  if (!started) {
    throw InvalidArgumentError("dataset '" + dataset.root.string() +
                               "': no event after the start time");
  }
  run.counts = runner.counts();
  result.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return run;
}

}  // namespace evloc::tracking
