#include "localizer/offline/offline_tracking.h"

#include <chrono>
#include <string>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"

namespace evloc::tracking {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void Record(const PoseEstimate& step, const Tracker& tracker, const StepCallback& on_step,
            OfflineTrackingResult* result) {
  result->trajectory.Append(TimedPose{step.t_ns, step.world_from_cam});
  if (step.status == TrackingStatus::kLost) ++result->lost_steps;
  result->steps.push_back(step);
  if (on_step) on_step(step, tracker);
}

}  // namespace

void OfflineTrackingOptions::Check() const {
  tracker.Check();
  if (read_batch_events == 0) {
    throw InvalidArgumentError("offline tracking: read_batch_events must be positive");
  }
}

OfflineTrackingResult TrackEventStream(EventReader& reader, const Map& map,
                                       const VisibilityIndex* visibility, const Camera& camera,
                                       const Rigid3d& initial_world_from_cam, int64_t initial_t_ns,
                                       const OfflineTrackingOptions& options,
                                       const StepCallback& on_step) {
  options.Check();
  if (options.tracker.input != TrackerInput::kEvents) {
    throw InvalidArgumentError("offline tracking: event streams need the events input mode");
  }
  const auto start = std::chrono::steady_clock::now();
  Tracker tracker(map, visibility, camera, options.tracker);
  OfflineTrackingResult result;
  EventBuffer batch;
  EventBuffer before_start;
  bool started = false;
  while (true) {
    batch.clear();
    const size_t count = reader.Read(options.read_batch_events, &batch);
    if (count == 0) break;
    result.measurements += static_cast<int64_t>(count);
    if (!started) {
      // Split the batch at the initial time: events up to it are stored before the Reset so that
      // the surfaces are primed, the rest are tracked.
      size_t split = 0;
      while (split < batch.size() && batch.t_ns[split] <= initial_t_ns) ++split;
      if (split == batch.size()) {
        tracker.AddEvents(batch);
        continue;
      }
      EventBuffer head;
      EventBuffer tail;
      for (size_t i = 0; i < batch.size(); ++i) (i < split ? head : tail).push_back(batch[i]);
      if (!head.empty()) tracker.AddEvents(head);
      tracker.Reset(initial_world_from_cam, initial_t_ns);
      started = true;
      batch = std::move(tail);
    }
    for (const PoseEstimate& step : tracker.AddEvents(batch)) {
      Record(step, tracker, on_step, &result);
    }
  }
  result.wall_s = SecondsSince(start);
  return result;
}

OfflineTrackingResult TrackFrameSequence(const std::vector<FrameFile>& frames, const Map& map,
                                         const VisibilityIndex* visibility, const Camera& camera,
                                         const Rigid3d& initial_world_from_cam,
                                         int64_t initial_t_ns,
                                         const OfflineTrackingOptions& options,
                                         const StepCallback& on_step) {
  options.Check();
  if (options.tracker.input != TrackerInput::kFrames) {
    throw InvalidArgumentError("offline tracking: frame sequences need the frames input mode");
  }
  const auto start = std::chrono::steady_clock::now();
  Tracker tracker(map, visibility, camera, options.tracker);
  tracker.Reset(initial_world_from_cam, initial_t_ns);
  OfflineTrackingResult result;
  for (const FrameFile& frame : frames) {
    if (frame.t_ns <= initial_t_ns) continue;
    cv::Mat image = cv::imread(frame.path.string(), cv::IMREAD_GRAYSCALE);
    if (image.empty()) {
      throw IoError("cannot read frame '" + frame.path.string() +
                    "' (missing, or not an image OpenCV reads)");
    }
    ++result.measurements;
    if (const auto step = tracker.AddFrame(frame.t_ns, image)) {
      Record(*step, tracker, on_step, &result);
    }
  }
  result.wall_s = SecondsSince(start);
  return result;
}

}  // namespace evloc::tracking
