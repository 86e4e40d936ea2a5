#include "localizer/offline/offline_tracking.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/trajectory/tum_io.h"

namespace evloc::tracking {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Follows the search episodes through the steps: opens one at a searching step, closes it at the
// first TRACKING step ("found") or at a step that gave up ("not_found").
void RecordEpisode(const PoseEstimate& step, std::vector<RelocalizationEpisode>* episodes,
                   bool* open) {
  if (*open && step.status == TrackingStatus::kTracking) {
    episodes->back().end_t_ns = step.t_ns;
    episodes->back().outcome = "found";
    *open = false;
    return;
  }
  if (!IsSearching(step.status)) return;
  if (!*open) {
    episodes->push_back({step.t_ns, step.t_ns, "ended", 0, 0, 0, 0});
    *open = true;
  }
  RelocalizationEpisode& episode = episodes->back();
  episode.end_t_ns = step.t_ns;
  ++episode.steps;
  episode.rounds = std::max(episode.rounds, step.search.round);
  episode.total_ms += step.timings.total_ms;
  episode.max_step_ms = std::max(episode.max_step_ms, step.timings.total_ms);
  if (step.search.gave_up) {
    episode.outcome = "not_found";
    *open = false;
  }
}

void Record(const PoseEstimate& step, const Tracker& tracker, const StepCallback& on_step,
            OfflineTrackingResult* result) {
  if (!IsSearching(step.status))
    result->trajectory.Append(TimedPose{step.t_ns, step.world_from_cam});
  if (step.status == TrackingStatus::kLost) ++result->lost_steps;
  // An episode is open while its outcome is still "ended" (what it is when the run stops).
  bool open = !result->relocalizations.empty() && result->relocalizations.back().outcome == "ended";
  RecordEpisode(step, &result->relocalizations, &open);
  result->steps.push_back(step);
  result->filter_counts.push_back(tracker.event_filter().counts());
  if (on_step) on_step(step, tracker);
}

// Reads batches of `batch_events` from a reader on a second thread, at most `depth` batches ahead
// of the consumer (a bounded queue; the buffers are recycled). Next returns them in order;
// an exception of the reader is rethrown by Next after the batches read before it.
class ReadAheadQueue {
 public:
  ReadAheadQueue(EventReader& reader, size_t batch_events, int depth)
      : reader_(reader), batch_events_(batch_events), free_(depth) {
    thread_ = std::thread([this] { Produce(); });
  }
  ReadAheadQueue(const ReadAheadQueue&) = delete;
  ReadAheadQueue& operator=(const ReadAheadQueue&) = delete;
  ~ReadAheadQueue() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    changed_.notify_all();
    thread_.join();
  }

  // Swaps the next batch into `batch` (whose old buffer is recycled); false at the end.
  bool Next(EventBuffer* batch) {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait(lock, [this] { return !filled_.empty() || finished_; });
    if (filled_.empty()) {
      if (error_) std::rethrow_exception(error_);
      return false;
    }
    std::swap(*batch, filled_.front());
    free_.push_back(std::move(filled_.front()));
    filled_.pop_front();
    lock.unlock();
    changed_.notify_all();
    return true;
  }

 private:
  void Produce() {
    EventBuffer batch;
    try {
      while (true) {
        {
          std::unique_lock<std::mutex> lock(mutex_);
          changed_.wait(lock, [this] { return !free_.empty() || stop_; });
          if (stop_) break;
          batch = std::move(free_.back());
          free_.pop_back();
        }
        batch.clear();
        const size_t count = reader_.Read(batch_events_, &batch);
        std::lock_guard<std::mutex> lock(mutex_);
        if (count == 0) break;
        filled_.push_back(std::move(batch));
        changed_.notify_all();
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(mutex_);
      error_ = std::current_exception();
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      finished_ = true;
    }
    changed_.notify_all();
  }

  EventReader& reader_;
  const size_t batch_events_;
  std::mutex mutex_;
  std::condition_variable changed_;
  // Buffers waiting to be filled, and filled batches in reading order.
  std::vector<EventBuffer> free_;
  std::deque<EventBuffer> filled_;
  std::exception_ptr error_;
  bool finished_ = false;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace

void OfflineTrackingOptions::Check() const {
  tracker.Check();
  if (read_batch_events == 0) {
    throw InvalidArgumentError("offline tracking: read_batch_events must be positive");
  }
  if (read_ahead_batches < 0 || read_ahead_batches > 1024) {
    throw InvalidArgumentError("offline tracking: read_ahead_batches must be in 0..1024");
  }
  if (search_prior_center) {
    CheckSearchRegion(*search_prior_center, search_prior_radius_m,
                      "offline tracking: the search prior");
  }
  if (initial_velocity && !initial_velocity->allFinite()) {
    throw InvalidArgumentError("offline tracking: the initial velocity is not finite");
  }
}

EventStreamTracker::EventStreamTracker(const MapSource& source, const Camera& camera,
                                       const TrackerOptions& options,
                                       const std::optional<Rigid3d>& initial_world_from_cam,
                                       int64_t initial_t_ns, bool discard_events_before_start)
    : tracker_(source, camera, options),
      initial_world_from_cam_(initial_world_from_cam),
      initial_t_ns_(initial_t_ns),
      discard_events_before_start_(discard_events_before_start) {}

std::vector<PoseEstimate> EventStreamTracker::AddEvents(
    const EventBuffer& events, const std::function<void(const Tracker&)>& before_tracking) {
  if (started_) {
    if (before_tracking) before_tracking(tracker_);
    return tracker_.AddEvents(events);
  }
  // Split the events at the initial time: those up to it are stored before the Reset so that
  // the surfaces are primed, the rest are tracked.
  size_t split = 0;
  while (split < events.size() && events.t_ns[split] <= initial_t_ns_) ++split;
  if (split == events.size()) {
    if (!discard_events_before_start_ && !events.empty()) tracker_.AddEvents(events);
    return {};
  }
  EventBuffer head;
  EventBuffer tail;
  for (size_t i = 0; i < events.size(); ++i) (i < split ? head : tail).push_back(events[i]);
  if (!head.empty() && !discard_events_before_start_) tracker_.AddEvents(head);
  if (initial_world_from_cam_ && initial_velocity_) {
    tracker_.Reset(*initial_world_from_cam_, initial_t_ns_, *initial_velocity_);
  } else if (initial_world_from_cam_) {
    tracker_.Reset(*initial_world_from_cam_, initial_t_ns_);
  } else {
    tracker_.StartWithoutPose(initial_t_ns_);
  }
  started_ = true;
  if (before_tracking) before_tracking(tracker_);
  return tracker_.AddEvents(tail);
}

std::vector<PoseEstimate> EventStreamTracker::AdvanceTo(int64_t t_ns) {
  if (!started_) return {};
  return tracker_.AdvanceTo(t_ns);
}

OfflineTrackingResult TrackEventStream(EventReader& reader, const Map& map,
                                       const VisibilityIndex* visibility, const Camera& camera,
                                       const std::optional<Rigid3d>& initial_world_from_cam,
                                       int64_t initial_t_ns, const OfflineTrackingOptions& options,
                                       const StepCallback& on_step) {
  const StaticMapSource source(map, visibility);
  return TrackEventStream(reader, source, camera, initial_world_from_cam, initial_t_ns, options,
                          on_step, {});
}

OfflineTrackingResult TrackEventStream(EventReader& reader, const MapSource& source,
                                       const Camera& camera,
                                       const std::optional<Rigid3d>& initial_world_from_cam,
                                       int64_t initial_t_ns, const OfflineTrackingOptions& options,
                                       const StepCallback& on_step,
                                       const BetweenBatchesCallback& between_batches) {
  options.Check();
  if (options.tracker.input != TrackerInput::kEvents) {
    throw InvalidArgumentError("offline tracking: event streams need the events input mode");
  }
  const auto start = std::chrono::steady_clock::now();
  if (options.initial_velocity && !initial_world_from_cam) {
    throw InvalidArgumentError("offline tracking: an initial velocity needs an initial pose");
  }
  EventStreamTracker stream(source, camera, options.tracker, initial_world_from_cam, initial_t_ns,
                            options.discard_events_before_start);
  if (options.initial_velocity) stream.set_initial_velocity(*options.initial_velocity);
  if (options.image_hypotheses) {
    stream.mutable_tracker().SetImageHypothesisSource(options.image_hypotheses);
  }
  bool prior_set = false;
  if (options.search_prior_center) {
    stream.mutable_tracker().SetSearchPrior(*options.search_prior_center,
                                            options.search_prior_radius_m);
    prior_set = true;
  }
  // Before each batch (where the tracker may be changed): the prior ends once a step has tracked.
  const BetweenBatchesCallback before_step = [&](const Tracker& tracker) {
    if (prior_set && tracker.status() == TrackingStatus::kTracking) {
      stream.mutable_tracker().ClearSearchPrior();
      prior_set = false;
    }
    if (between_batches) between_batches(tracker);
  };
  OfflineTrackingResult result;
  EventBuffer batch;
  std::optional<ReadAheadQueue> read_ahead;
  if (options.read_ahead_batches > 0) {
    read_ahead.emplace(reader, options.read_batch_events, options.read_ahead_batches);
  }
  // The next batch, from the read-ahead thread or read here; false at the end.
  auto next_batch = [&]() -> bool {
    if (read_ahead) return read_ahead->Next(&batch);
    batch.clear();
    return reader.Read(options.read_batch_events, &batch) > 0;
  };
  while (next_batch()) {
    const size_t count = batch.size();
    result.measurements += static_cast<int64_t>(count);
    if (options.blackout_begin_ns < options.blackout_end_ns && count > 0 &&
        batch.t_ns[count - 1] >= options.blackout_begin_ns &&
        batch.t_ns[0] < options.blackout_end_ns) {
      EventBuffer kept;
      for (size_t i = 0; i < count; ++i) {
        if (batch.t_ns[i] < options.blackout_begin_ns || batch.t_ns[i] >= options.blackout_end_ns) {
          kept.push_back(batch[i]);
        }
      }
      batch = std::move(kept);
      if (batch.empty()) continue;
    }
    for (const PoseEstimate& step : stream.AddEvents(batch, before_step)) {
      Record(step, stream.tracker(), on_step, &result);
    }
  }
  result.final_filter_counts = stream.tracker().event_filter().counts();
  result.wall_s = SecondsSince(start);
  return result;
}

OfflineTrackingResult TrackFrames(const FrameSource& for_each_frame, const std::string& source,
                                  const Map& map, const VisibilityIndex* visibility,
                                  const Camera& camera, const Rigid3d& initial_world_from_cam,
                                  int64_t initial_t_ns, const OfflineTrackingOptions& options,
                                  const StepCallback& on_step) {
  options.Check();
  if (options.tracker.input != TrackerInput::kFrames) {
    throw InvalidArgumentError("offline tracking: frame sequences need the frames input mode");
  }
  const auto start = std::chrono::steady_clock::now();
  Tracker tracker(map, visibility, camera, options.tracker);
  tracker.Reset(initial_world_from_cam, initial_t_ns);
  OfflineTrackingResult result;
  std::optional<int64_t> last_t_ns;
  for_each_frame([&](int64_t t_ns, const cv::Mat& pixels) {
    const auto where = [&] {
      return source + ": the frame at " + FormatNanosecondsAsSeconds(t_ns) + " s";
    };
    if (last_t_ns && t_ns <= *last_t_ns) {
      throw InvalidArgumentError(where() + " does not come after the previous one (" +
                                 FormatNanosecondsAsSeconds(*last_t_ns) +
                                 " s): frames must be in time order");
    }
    last_t_ns = t_ns;
    if (t_ns <= initial_t_ns) return;
    if (pixels.cols != camera.width || pixels.rows != camera.height) {
      throw InvalidArgumentError(
          where() + " is " + std::to_string(pixels.cols) + "x" + std::to_string(pixels.rows) +
          ", the camera " + std::to_string(camera.width) + "x" + std::to_string(camera.height));
    }
    ++result.measurements;
    if (const auto step = tracker.AddFrame(t_ns, ToGray8(pixels))) {
      Record(*step, tracker, on_step, &result);
    }
  });
  result.wall_s = SecondsSince(start);
  return result;
}

OfflineTrackingResult TrackFrameSequence(const std::vector<FrameFile>& frames, const Map& map,
                                         const VisibilityIndex* visibility, const Camera& camera,
                                         const Rigid3d& initial_world_from_cam,
                                         int64_t initial_t_ns,
                                         const OfflineTrackingOptions& options,
                                         const StepCallback& on_step) {
  const auto read_files = [&frames](const ImageSink& add) {
    for (const FrameFile& frame : frames) add(frame.t_ns, ReadImageFile(frame.path));
  };
  return TrackFrames(read_files, "frame files", map, visibility, camera, initial_world_from_cam,
                     initial_t_ns, options, on_step);
}

}  // namespace evloc::tracking
