// Offline tracking of a recorded sequence: the same Tracker the service runs, fed from an event
// file (or a list of frames) in order. Used by evloc-track, the accuracy tests and, as the
// reference, by the service's equivalence test.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/camera/camera.h"
#include "core/dataset/dataset.h"
#include "core/events/event_reader.h"
#include "core/geometry/rigid3.h"
#include "core/trajectory/trajectory.h"
#include "localizer/tracking/tracker.h"
#include "maps/map.h"
#include "maps/visibility.h"

namespace evloc::tracking {

// Options of an offline run.
struct OfflineTrackingOptions {
  // The tracker's options (variant, rate, ...).
  TrackerOptions tracker;
  // Events read from the file per batch; any value gives the same poses (batching invariance).
  size_t read_batch_events = 1 << 16;
  // Batches a second thread reads (and decodes) ahead of the tracker, so that reading overlaps
  // tracking; 0 reads on the calling thread. The poses do not depend on it.
  int read_ahead_batches = 4;
  // Events before the start time are dropped instead of priming the time surfaces (evloc-track
  // --start: the run ignores what comes before it).
  bool discard_events_before_start = false;
  // The camera's velocity at the start (the body-frame twist per second of world_from_cam,
  // Tracker::Reset), so that a run that starts at speed does not start at rest (evloc-track
  // --initial-velocity); nullopt: at rest. Needs an initial pose.
  std::optional<Vector6d> initial_velocity;
  // Events with begin <= t_ns < end of this range are dropped before the tracker sees them (a
  // blackout of the sensor, for recovery tests; evloc-track --blackout); empty when begin >= end.
  int64_t blackout_begin_ns = 0;
  // End of the blackout, nanoseconds (exclusive).
  int64_t blackout_end_ns = 0;
  // Hypotheses from an image of the events for the global search (Tracker::
  // SetImageHypothesisSource; not owned, must outlive the run); null: none.
  const ImageHypothesisSource* image_hypotheses = nullptr;
  // A prior on where a run that starts without a pose is (evloc-track --gnss: a GNSS fix at the
  // start): the search looks only at viewpoints within search_prior_radius_m of this centre
  // (world frame, Tracker::SetSearchPrior) until it has tracked (checked before each batch of
  // events), then everywhere again.
  std::optional<Eigen::Vector3d> search_prior_center;
  // Its radius, metres (> 0 when a centre is given).
  double search_prior_radius_m = 0;

  // Throws InvalidArgumentError when a field is out of range.
  void Check() const;
};

// One search episode of a run (INITIALIZING or RELOCALIZING until TRACKING).
struct RelocalizationEpisode {
  // Time of its first step, nanoseconds.
  int64_t start_t_ns = 0;
  // Time of the step that ended it: the first TRACKING step ("found"), the step that gave up
  // ("not_found") or the last step of the run ("ended").
  int64_t end_t_ns = 0;
  // "found", "not_found" or "ended".
  std::string outcome;
  // Steps of the episode (the ending TRACKING step not included).
  int64_t steps = 0;
  // Search rounds judged or started.
  int rounds = 0;
  // Sum of the wall-clock step times of the episode, milliseconds.
  double total_ms = 0;
  // The longest step of the episode, milliseconds.
  double max_step_ms = 0;
};

// A reference frame (Canny-DEVO) or keyframe that a mapless run built, for the statistics.
struct ReferenceFrameRecord {
  // Its time since the run's start, seconds.
  double t_s = 0;
  // Points it kept, and the semi-dense pixels they were chosen from.
  int points = 0;
  int semi_dense_pixels = 0;
  // Median depth of its points, metres.
  double median_depth_m = 0;
  // Time its build took: wall clock, and CPU time of the building thread, milliseconds.
  double build_ms = 0;
  double build_cpu_ms = 0;
};

// What an offline run produced.
struct OfflineTrackingResult {
  // One pose per step that has one (TRACKING and LOST steps; INITIALIZING and RELOCALIZING steps
  // carry no pose), world_from_cam.
  Trajectory trajectory;
  // Every step's estimate, in order (status, quality, covariance, timings).
  std::vector<PoseEstimate> steps;
  // Events read from the source (or frames, in frame mode).
  int64_t measurements = 0;
  // Steps whose status was LOST.
  int64_t lost_steps = 0;
  // The noise filters' counts (cumulative) when each step ran, one per element of `steps`
  // (events mode).
  std::vector<EventFilterCounts> filter_counts;
  // The noise filters' counts at the end of the run.
  EventFilterCounts final_filter_counts;
  // The search episodes, in order.
  std::vector<RelocalizationEpisode> relocalizations;
  // Where each step's pose came from, "map" or "odometry" (hand-over runs, handover_track.h;
  // empty otherwise).
  std::vector<std::string> pose_sources;
  // The reference frames of a Canny-DEVO run, in order (empty otherwise).
  std::vector<ReferenceFrameRecord> reference_frames;
  // Wall-clock time of the run (reading included), seconds.
  double wall_s = 0;
};

// Called after every step, for progress display and debug output; `tracker` is the live tracker.
using StepCallback = std::function<void(const PoseEstimate& step, const Tracker& tracker)>;

// A Tracker fed an event stream in pieces of any size, started as every offline run and the ROS
// node start it: events up to `initial_t_ns` prime the time surfaces (or are dropped with
// `discard_events_before_start`), then the tracker is Reset at `initial_world_from_cam` (or
// started without a pose when it is nullopt) at `initial_t_ns`, and later events are tracked. The
// same events give the same steps however they are split into pieces. Not thread-safe.
class EventStreamTracker {
 public:
  // `source` must outlive the tracker. Throws InvalidArgumentError as Tracker's constructor does.
  EventStreamTracker(const MapSource& source, const Camera& camera, const TrackerOptions& options,
                     const std::optional<Rigid3d>& initial_world_from_cam, int64_t initial_t_ns,
                     bool discard_events_before_start = false);
  // The velocity the tracker starts with at the initial pose (at rest without it). Call before
  // the first events.
  void set_initial_velocity(const Vector6d& velocity) { initial_velocity_ = velocity; }

  // Adds the next events (time-ordered, also across calls) and returns the steps that became
  // due. `before_tracking`, when set, runs once the tracker has started, just before the events
  // after the initial time are tracked. Throws what Tracker::AddEvents throws.
  std::vector<PoseEstimate> AddEvents(
      const EventBuffer& events, const std::function<void(const Tracker&)>& before_tracking = {});
  // Tracker::AdvanceTo once started (every event with t_ns <= `t_ns` has been given); nothing
  // before.
  std::vector<PoseEstimate> AdvanceTo(int64_t t_ns);
  // True once the initial time has passed (the tracker was Reset or started without a pose).
  bool started() const { return started_; }
  // The tracker.
  const Tracker& tracker() const { return tracker_; }
  // The tracker, e.g. for a new pose hint (Tracker::Reset) after the start.
  Tracker& mutable_tracker() { return tracker_; }

 private:
  Tracker tracker_;
  std::optional<Rigid3d> initial_world_from_cam_;
  std::optional<Vector6d> initial_velocity_;
  int64_t initial_t_ns_ = 0;
  bool discard_events_before_start_ = false;
  bool started_ = false;
};

// Tracks the events of `reader` from `initial_world_from_cam` at `initial_t_ns`, or without a
// pose (Tracker::StartWithoutPose) when it is nullopt; events before initial_t_ns only prime the
// time surfaces (or are dropped with discard_events_before_start). With read_ahead_batches > 0 a
// second thread calls `reader` (it must not be used elsewhere meanwhile); the steps run and
// `on_step` is called on the calling thread. Throws what the reader and the tracker throw (a reader
// error after the events read before it have been tracked, as without the thread).
OfflineTrackingResult TrackEventStream(EventReader& reader, const Map& map,
                                       const VisibilityIndex* visibility, const Camera& camera,
                                       const std::optional<Rigid3d>& initial_world_from_cam,
                                       int64_t initial_t_ns, const OfflineTrackingOptions& options,
                                       const StepCallback& on_step = {});

// Called before each batch of events once the tracker has a pose: where a MapSource that
// changes with the pose (a site's TiledMapSource) follows the tracker, between two calls into it.
using BetweenBatchesCallback = std::function<void(const Tracker& tracker)>;

// TrackEventStream against any MapSource (which must outlive the call); `between_batches`, when
// set, runs before each batch after the start. The overload above is this with a
// StaticMapSource of `map` and `visibility`.
OfflineTrackingResult TrackEventStream(EventReader& reader, const MapSource& source,
                                       const Camera& camera,
                                       const std::optional<Rigid3d>& initial_world_from_cam,
                                       int64_t initial_t_ns, const OfflineTrackingOptions& options,
                                       const StepCallback& on_step,
                                       const BetweenBatchesCallback& between_batches);

// A frame of a sequence: its time and image file.
struct FrameFile {
  // Capture time, nanoseconds.
  int64_t t_ns = 0;
  // Image file (any format OpenCV reads; converted to 8-bit grey).
  std::filesystem::path path;
};

// The frames of a run: hands each (capture time in ns, pixels: CV_8UC1, CV_16UC1, CV_8UC3 BGR or
// CV_8UC4 BGRA) to its argument in time order, e.g. ForEachDatasetImage of a folder, bag or
// AEDAT4 file.
using FrameSource = std::function<void(const ImageSink&)>;

// Tracks the frames of `for_each_frame` with the frame-based twin (Canny-VT), starting from
// `initial_world_from_cam` at `initial_t_ns`; frames at or before initial_t_ns are skipped. Each
// frame is made 8-bit grey by ToGray8 (core/dataset), whatever its source. `source` names the
// frames in errors. Throws InvalidArgumentError (with `source` and the frame's time) for a frame
// whose size is not the camera's or whose time does not increase, and whatever the source throws.
OfflineTrackingResult TrackFrames(const FrameSource& for_each_frame, const std::string& source,
                                  const Map& map, const VisibilityIndex* visibility,
                                  const Camera& camera, const Rigid3d& initial_world_from_cam,
                                  int64_t initial_t_ns, const OfflineTrackingOptions& options,
                                  const StepCallback& on_step = {});

// TrackFrames over image files. Throws IoError for an unreadable frame.
OfflineTrackingResult TrackFrameSequence(const std::vector<FrameFile>& frames, const Map& map,
                                         const VisibilityIndex* visibility, const Camera& camera,
                                         const Rigid3d& initial_world_from_cam,
                                         int64_t initial_t_ns,
                                         const OfflineTrackingOptions& options,
                                         const StepCallback& on_step = {});

}  // namespace evloc::tracking
