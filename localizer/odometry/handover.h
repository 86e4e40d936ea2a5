// The hand-over between map tracking and Canny-DEVO (docs/tracking.md, "Hand-over"): a session
// with a map and a depth camera keeps a pose where the map is not seen. While the map tracker
// tracks, Canny-DEVO only primes its time surfaces; when the map is no longer seen (the tracker
// selects too few map points, or is not TRACKING), DEVO starts from the last good map pose with
// the latest depth frame and its poses are reported (source: odometry) with a covariance that
// grows with the distance travelled. Meanwhile the map tracker keeps ingesting the events; once
// the map is in view of the odometry pose again, the map tracker is given that pose as a hint
// (Tracker::Reset) and its poses are reported again (source: map) once they are verified: as many
// consecutive TRACKING steps as the relocalization search's verification asks
// (TrackerOptions::relocalization_verify_steps), each with enough map points, the search's
// verification alignment (relocalization_verify_min_alignment) and consistent with the odometry
// within its covariance. One pose per map step, never a gap. Not thread-safe.
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/events/event.h"
#include "core/geometry/rigid3.h"
#include "localizer/odometry/canny_devo.h"
#include "localizer/tracking/map_source.h"
#include "localizer/tracking/tracker.h"

namespace evloc::odometry {

// Where a reported pose came from.
enum class PoseSource {
  // The map tracker (also its steps without an estimate: LOST, searching).
  kMap,
  // Canny-DEVO, started from the last good map pose.
  kOdometry,
};

// "map" or "odometry".
const char* PoseSourceName(PoseSource source);

// Options of the hand-over.
struct HandoverOptions {
  // Canny-DEVO's options; its tracker's step rate is set to the map tracker's (one odometry pose
  // per map step).
  CannyDevoOptions devo;
  // The map is not seen when a map step registers fewer map points than this (points_used; or
  // is not TRACKING): a step on a few points can be TRACKING yet centimetres to decimetres off.
  int min_map_points = 500;
  // The hand-over to odometry happens when a map step registers fewer map points than this
  // (0 = min_map_points): a higher value leaves the map earlier as it slides out of view, while
  // returns still need min_map_points (hysteresis).
  int leave_map_points = 0;
  // While on odometry, the map is looked for (its points projected from the odometry pose) at
  // most this often, seconds; when at least min_map_points project into the image the map
  // tracker is given the odometry pose.
  double map_probe_interval_s = 0.05;
  // After this many probes from the odometry pose failed, the map tracker searches instead
  // (Tracker::StartWithoutPose) within a prior around the odometry position of radius
  // max(search_min_radius_m, verify_sigmas x its standard deviation), updated at every probe
  // interval; its own verification (probes and margin) judges the pose it finds. A drifted
  // odometry pose is farther than one step can pull in, the search is not. 0 = hints only.
  int search_after_failed_probes = 2;
  double search_min_radius_m = 0.5;
  // The map tracker's pose must lie within this many standard deviations of the odometry's ...
  double verify_sigmas = 3.0;
  // ... and at least within these bounds (the odometry's own error right after a hand-over),
  // metres and degrees.
  double verify_min_distance_m = 0.05;
  double verify_min_angle_deg = 2.0;
  // The odometry's position standard deviation grows by this fraction of the distance travelled
  // since the hand-over (DEVO's measured drift, docs/accuracy.md), ...
  double drift_fraction = 0.02;
  // ... by this many metres per radian turned (turning fast is where DEVO drifts most:
  // docs/accuracy.md, "Hand-over") ...
  double drift_m_per_rad = 0.1;
  // ... its rotation standard deviation by this many degrees per metre travelled ...
  double rotation_drift_deg_per_m = 1.0;
  // ... and both by these amounts per second (drift while standing still), metres and degrees.
  double drift_m_per_s = 0.002;
  double rotation_drift_deg_per_s = 0.05;

  // Throws InvalidArgumentError naming the first bad field.
  void Check() const;
};

// One reported pose.
struct HandoverEstimate {
  // The step (its status: the map tracker's, or DEVO's while on odometry).
  tracking::PoseEstimate estimate;
  // Where it came from.
  PoseSource source = PoseSource::kMap;
};

// What the hand-over did so far.
struct HandoverCounts {
  // Hand-overs from the map to odometry.
  int64_t to_odometry = 0;
  // Returns from odometry to the map (verified).
  int64_t to_map = 0;
  // Poses reported from odometry.
  int64_t odometry_poses = 0;
  // Times the map tracker was given the odometry pose.
  int64_t map_probes = 0;
  // Times the map tracker started searching around the odometry (search_after_failed_probes).
  int64_t map_searches = 0;
  // Returns refused at the end of their verification because the relocalization search's
  // probes found another fit of the map nearly as good (Tracker::ProbeLastPose).
  int64_t ambiguous_returns = 0;
  // Hand-overs that could not start DEVO (no depth frame yet, or too few reference points).
  int64_t odometry_start_failures = 0;
  // DEVO started again from its last good pose after it lost its reference.
  int64_t odometry_restarts = 0;
  // Depth frames received.
  int64_t depth_frames = 0;
};

// The hand-over around a map tracker. `map_tracker` (and `map_source`, the source it tracks
// against) must outlive this object; the caller starts the map tracker (Reset or
// StartWithoutPose) and then feeds every event and depth frame through this object only.
class MapOdometryHandover {
 public:
  // `event_camera` is the map tracker's camera; `depth_camera` and `event_from_depth` the depth
  // camera. Throws InvalidArgumentError for bad options or cameras.
  MapOdometryHandover(tracking::Tracker& map_tracker, const tracking::MapSource& map_source,
                      const Camera& event_camera, const Camera& depth_camera,
                      const Rigid3d& event_from_depth, const HandoverOptions& options);
  ~MapOdometryHandover();

  // Ingests events (time-ordered, also across calls) into both trackers and returns one pose per
  // map step that became due. Feed at most a few step periods at a time: decisions (hand-over,
  // return) take effect after the call's steps.
  std::vector<HandoverEstimate> AddEvents(const EventBuffer& events);
  // As Tracker::AdvanceTo: every event up to t_ns has been given.
  std::vector<HandoverEstimate> AdvanceTo(int64_t t_ns);
  // A depth frame (CV_32FC1 metres of the depth camera, 0 = none) taken at t_ns, once every
  // event up to t_ns has been given (and the steps up to about t_ns have run: AddEvents or
  // AdvanceTo first). Runs no step: it is kept for the next hand-over and, on odometry, may
  // become DEVO's next reference frame. Throws InvalidArgumentError for a frame of the wrong
  // size or type, or a time not after the previous frame's.
  void AddDepthFrame(int64_t t_ns, const cv::Mat& depth_m);

  // Where the next pose will come from.
  PoseSource source() const { return source_; }
  // The counts.
  const HandoverCounts& counts() const { return counts_; }
  // The odometry (for its reference frames).
  const CannyDevo& devo() const { return *devo_; }

 private:
  // Merges the map steps with DEVO's steps (pending_odometry_) into the reported poses and
  // takes the hand-over decisions.
  std::vector<HandoverEstimate> Report(const std::vector<tracking::PoseEstimate>& map_steps);
  // True when the map step is a good one with enough map points.
  bool MapSeen(const tracking::PoseEstimate& step) const;
  // Starts DEVO at t_ns from `world_from_cam` with the latest depth frame; false when it cannot.
  bool StartOdometry(const Rigid3d& world_from_cam, int64_t t_ns, const Vector6d& velocity,
                     double decay_time_s);
  // Starts DEVO's tracker again at t_ns from `world_from_cam` with the latest depth frame; false
  // when the reference map has too few points.
  bool RestartOdometry(const Rigid3d& world_from_cam, int64_t t_ns, const Vector6d& velocity,
                       double decay_time_s);
  // The odometry's pose at t_ns (its step at t_ns, or the latest one moved by its velocity).
  tracking::PoseEstimate OdometryAt(int64_t t_ns);
  // The covariance added to the odometry's since the hand-over.
  Matrix6d DriftCovariance(int64_t t_ns) const;
  // Number of map points that project into the image from `world_from_cam`.
  int VisibleMapPoints(const Rigid3d& world_from_cam) const;
  // Back to the map at `map_step` (verified): reports it, stops DEVO and ends a search.
  void ReturnToMap(const tracking::PoseEstimate& map_step, std::vector<HandoverEstimate>* reported);
  // The radius of the search prior around the odometry pose (search_after_failed_probes).
  double SearchRadius(const tracking::PoseEstimate& odometry) const;
  // Sets the map tracker's search prior and hint to the odometry pose, and starts its search
  // at the step after t_ns unless one is already under way.
  void SearchAround(const tracking::PoseEstimate& odometry, int64_t t_ns);
  // True when the map step agrees with the odometry pose within the gate.
  bool ConsistentWithOdometry(const tracking::PoseEstimate& map_step,
                              const tracking::PoseEstimate& odometry) const;

  tracking::Tracker& map_tracker_;
  const tracking::MapSource& map_source_;
  Camera event_camera_;
  Camera depth_camera_;
  HandoverOptions options_;
  std::unique_ptr<CannyDevo> devo_;
  PoseSource source_ = PoseSource::kMap;
  HandoverCounts counts_;
  // The last good map step and the map tracker's velocity after it.
  std::optional<tracking::PoseEstimate> last_good_map_;
  Vector6d last_good_velocity_ = Vector6d::Zero();
  // The latest depth frame, its time and the event camera's pose then (from the trackers).
  cv::Mat depth_m_;
  int64_t depth_t_ns_ = 0;
  bool has_depth_ = false;
  // DEVO's steps not yet matched to a map step, and its latest one.
  std::deque<tracking::PoseEstimate> pending_odometry_;
  std::optional<tracking::PoseEstimate> last_odometry_;
  // DEVO's last TRACKING pose and its velocity then; the depth frame of its last (re)start.
  std::optional<tracking::PoseEstimate> last_good_odometry_;
  Vector6d last_good_odometry_velocity_ = Vector6d::Zero();
  int64_t restart_depth_t_ns_ = -1;
  // The hand-over: its time, covariance and the path length since.
  int64_t handover_t_ns_ = 0;
  Matrix6d handover_covariance_ = Matrix6d::Zero();
  double travelled_m_ = 0;
  double rotated_rad_ = 0;
  Rigid3d previous_odometry_pose_;
  Eigen::Quaterniond previous_odometry_rotation_ = Eigen::Quaterniond::Identity();
  // Returning to the map: the time of the last probe and the consecutive verified map steps.
  std::optional<int64_t> last_probe_t_ns_;
  int verified_steps_ = 0;
  bool probing_ = false;
  // Probes that failed since the hand-over (or the last search), and whether the map tracker is
  // searching around the odometry.
  int failed_probes_ = 0;
  bool searching_ = false;
};

}  // namespace evloc::odometry
