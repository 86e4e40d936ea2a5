// Canny-DEVO (Zuo et al. 2022; docs/tracking.md, "Mapless odometry"): events tracked against a
// local map of reference frames, each built from one depth frame (devo_reference_map.h) on the
// semi-dense region of the time surface at the depth frame's time. The events go to the map
// tracker of localizer/tracking unchanged, through its public API; the local map (the union of
// the kept reference frames nearest the camera) reaches it through the MapSource seam (a new
// generation whenever that set changes). A new reference frame is taken from the next depth frame
// once no kept frame is near: every kept frame's baseline exceeds a fraction of its median depth,
// or its rotation an angle.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/camera/undistortion_table.h"
#include "core/events/event.h"
#include "core/geometry/rigid3.h"
#include "localizer/odometry/devo_reference_map.h"
#include "localizer/tracking/map_source.h"
#include "localizer/tracking/time_surface.h"
#include "localizer/tracking/tracker.h"
#include "localizer/tracking/tracker_options.h"

namespace evloc::odometry {

// Options of Canny-DEVO.
struct CannyDevoOptions {
  // The event tracker's options. The reference points carry no intensity gradient (their region
  // comes from events), so the polarity-aware registration is off by default; so is the
  // occlusion culling, because the local map holds each edge once per reference frame that saw
  // it, and the culling lets only one point claim an edge pixel (variant EVT--).
  tracking::TrackerOptions tracker = DefaultTrackerOptions();
  // The reference map's depth assignment.
  ReferenceMapOptions reference;
  // Decay time of the time surface whose active pixels form the semi-dense region of the first
  // reference frame, seconds. Later ones use the decay time of the tracker's last step (its
  // adaptive 1-pixel trail), so that the reference region is as thin as the edges the tracker
  // registers it to: a thicker region trails behind the edge and biases the pose along the motion.
  double mapping_decay_time_s = 0.005;
  // A pixel is in the semi-dense region when that surface exceeds this (delta).
  double mapping_empty_threshold = 0.1;
  // Keep only the front of each edge's trail in the semi-dense region (non-maximum suppression
  // of the surface along its gradient). Off: measured worse on the simulated sequences
  // (docs/accuracy.md, "Mapless odometry").
  bool thin_to_front = false;
  // Place each reference point where its edge is at the reference time: a pixel of the
  // semi-dense region is where its edge was when it last fired, up to the decay time before;
  // moving it along its image flow (the tracker's velocity, at the point's depth) by the age of
  // that event puts the points of a trail on the edge's position at the frame's time. Off: each
  // point at its pixel's centre (measured worse on every 30 s run, docs/accuracy.md, "Mapless
  // odometry", 2026-12-07; moving the frame's pose forward by the tracker's surface age as well
  // was better at 640x480 and worse at 240x180 in the dark and in hdr light, so it is not done).
  bool edges_at_reference_time = true;
  // Reference points kept at most (evenly spread, 16 px buckets).
  int max_reference_points = 20000;
  // New reference frame when the baseline to the current one exceeds this fraction of its
  // median depth...
  double reference_max_baseline_fraction = 0.1;
  // ... or the rotation this angle, degrees.
  double reference_max_rotation_deg = 10.0;
  // The tracker needs this many reference points to start or switch.
  int min_reference_points = 100;
  // The local map the tracker registers to is the union of the kept reference frames nearest
  // the camera (at most this many), each at the pose it was taken from. One reference frame holds
  // only the edges that fired around its instant (an edge parallel to the motion then is
  // missing); the union holds the edges of several motions. Nearness is the larger of the
  // baseline over reference_max_baseline_fraction of the frame's median depth and the rotation
  // over reference_max_rotation_deg; a new reference frame is taken only when no kept frame is
  // within 1 of the camera, so a camera that comes back registers to the frames it took before
  // instead of adding drift with new ones.
  int local_map_frames = 4;
  // Reference frames kept at most (the oldest is dropped).
  int max_kept_frames = 100;

  // The tracker's defaults with polarity and occlusion culling off.
  static tracking::TrackerOptions DefaultTrackerOptions();
  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// The reference map as the tracker's MapSource: the points of the current reference frame in the
// world, every point a candidate (the tracker's own selection projects them); a new generation
// per reference frame.
class ReferenceMapSource final : public tracking::MapSource {
 public:
  uint64_t generation() const override { return generation_; }
  tracking::MapPoints points() const override { return {positions_, gradients_}; }
  void VisibleCandidates(const Camera& camera, const Rigid3d& world_from_cam,
                         const VisibilityQueryOptions& options,
                         std::vector<uint32_t>* candidates) const override;
  // Replaces the points (world positions and unit gradients, one per position) and changes the
  // generation. The previous points are swapped into the arguments, so that a caller can fill
  // the same memory next time. Throws InvalidArgumentError when the sizes differ.
  void Replace(std::vector<Eigen::Vector3f>* positions, std::vector<Eigen::Vector3f>* gradients);
  // Gives its point vectors room for `points` and touches that memory, so that filling them later
  // costs no page faults; the points and the generation stay as they are.
  void Reserve(size_t points);

 private:
  uint64_t generation_ = 0;
  std::vector<Eigen::Vector3f> positions_;
  std::vector<Eigen::Vector3f> gradients_;
};

// One reference frame taken.
struct ReferenceFrameInfo {
  // Time of its depth frame, nanoseconds.
  int64_t t_ns = 0;
  // world_from_cam of the event camera at that time (the tracker's estimate).
  Rigid3d world_from_cam;
  // Points in the map.
  int points = 0;
  // Median depth of its points, metres.
  double median_depth_m = 0;
  // Decay time of the time surface that gave its semi-dense region, seconds.
  double decay_time_s = 0;
  // Time to build it (semi-dense region, warping, depth assignment, lifting), milliseconds.
  double build_ms = 0;
  // The CPU time of the building thread over the same work, milliseconds (on a loaded machine
  // the wall time above also counts the time the thread waited for a core).
  double build_cpu_ms = 0;
  // What the build did.
  ReferenceMapStats stats;
};

// Canny-DEVO over an event stream with depth frames. Not thread-safe.
class CannyDevo {
 public:
  // `event_camera` is the event camera, `depth_camera` the depth camera, `event_from_depth` the
  // extrinsic. Throws InvalidArgumentError for bad options or cameras.
  CannyDevo(const Camera& event_camera, const Camera& depth_camera, const Rigid3d& event_from_depth,
            const CannyDevoOptions& options);

  // Ingests events (time-ordered, also across calls) and returns the tracking steps that became
  // due. Before Start they only prime the time surfaces.
  std::vector<tracking::PoseEstimate> AddEvents(const EventBuffer& events);

  // Starts at the depth frame `depth_m` taken at t_ns, where the event camera is at
  // `world_from_cam`: the first reference frame, and the tracker's pose. Every event up to t_ns
  // must have been given. Throws InvalidArgumentError when the reference map has fewer than
  // min_reference_points points (too few events or no depth).
  void Start(const Rigid3d& world_from_cam, int64_t t_ns, const cv::Mat& depth_m);

  // A depth frame taken at t_ns (every event up to t_ns given, after Start): runs the steps due
  // up to t_ns and returns them, then, when the tracker is TRACKING, takes the frame as a new
  // reference frame if no kept one is near, and makes the local map the nearest kept frames.
  std::vector<tracking::PoseEstimate> AddDepthFrame(int64_t t_ns, const cv::Mat& depth_m);
  // The same without running steps (the pose at t_ns: the last step's moved by the velocity).
  // Every event up to t_ns must have been given.
  void ConsiderDepthFrame(int64_t t_ns, const cv::Mat& depth_m);

  // Starts again (or for the first time) at t_ns at `world_from_cam`, moving with `velocity`
  // (body-frame twist per second), from a depth frame taken earlier, when the event camera was at
  // `world_from_cam_at_depth` (the depth is warped into the camera at t_ns through both poses and
  // the extrinsic); the semi-dense region is the time surface's at t_ns with `decay_time_s`. The
  // kept reference frames are forgotten. Every event up to t_ns must have been given. Returns
  // false (and stays stopped) when the reference map has fewer than min_reference_points points.
  // Used by the hand-over from a map.
  bool Restart(const Rigid3d& world_from_cam, int64_t t_ns, const Vector6d& velocity,
               const cv::Mat& depth_m, const Rigid3d& world_from_cam_at_depth, double decay_time_s);
  // Stops tracking: later events only prime the time surfaces again (until Start or Restart).
  void Stop();
  // Runs the steps due up to t_ns (every event up to t_ns given), as Tracker::AdvanceTo.
  std::vector<tracking::PoseEstimate> AdvanceTo(int64_t t_ns);

  // True once Start succeeded.
  bool started() const { return started_; }
  // The reference frames taken, in order.
  const std::vector<ReferenceFrameInfo>& reference_frames() const { return references_; }
  // The tracker (for inspection).
  const tracking::Tracker& tracker() const { return *tracker_; }
  // The newest reference frame's points, in the event camera frame at its time.
  const std::vector<ReferencePoint>& reference_points() const { return reference_points_; }
  // The local map the tracker registers to (the nearest kept frames' points, in the world).
  const tracking::MapSource& local_map() const { return source_; }

 private:
  // Builds the reference map of the depth frame at t_ns with the camera at world_from_cam;
  // `event_from_depth` maps the depth camera's frame into the event camera's at t_ns.
  ReferenceFrameInfo BuildReference(const Rigid3d& world_from_cam, int64_t t_ns,
                                    const cv::Mat& depth_m, double decay_time_s,
                                    const Rigid3d& event_from_depth);

  Camera event_camera_;
  Camera depth_camera_;
  Rigid3d event_from_depth_;
  CannyDevoOptions options_;
  UndistortionTable table_;
  ReferenceMapSource source_;
  std::unique_ptr<tracking::Tracker> tracker_;
  bool started_ = false;
  int64_t last_event_t_ns_ = 0;
  tracking::PoseEstimate last_step_;
  bool has_step_ = false;
  std::vector<ReferencePoint> reference_points_;
  // The buffers of BuildReference, kept to reuse their memory in the next build (megabytes at VGA;
  // fresh allocations cost page faults on every reference frame).
  struct BuildBuffers {
    // The time surface's values, its semi-dense mask and its gradients.
    cv::Mat values;
    cv::Mat semi_dense;
    cv::Mat gradient_x;
    cv::Mat gradient_y;
    // The points with depth before selection, their camera positions and indices.
    std::vector<ReferencePoint> points;
    std::vector<Eigen::Vector3f> positions_in_cam;
    std::vector<uint32_t> candidates;
    // The points kept (swapped with reference_points_ when the frame is taken), their depths.
    std::vector<ReferencePoint> kept;
    std::vector<double> depths;
  };
  BuildBuffers build_;
  std::vector<ReferenceFrameInfo> references_;
  // A reference frame kept for the local map: its pose, median depth and world points.
  struct KeptFrame {
    uint64_t id = 0;
    Rigid3d world_from_cam;
    double median_depth_m = 0;
    std::vector<Eigen::Vector3f> positions;
    std::vector<Eigen::Vector3f> gradients;
  };
  // How far the camera at world_from_cam is from a kept frame (<= 1: the frame covers it).
  double Nearness(const KeptFrame& frame, const Rigid3d& world_from_cam) const;
  // Makes the local map the union of the local_map_frames kept frames nearest world_from_cam
  // (a new generation only when that set changed).
  void UpdateLocalMap(const Rigid3d& world_from_cam);

  std::vector<KeptFrame> kept_frames_;
  uint64_t next_frame_id_ = 0;
  // The ids of the frames in the local map, sorted.
  std::vector<uint64_t> local_map_ids_;
  // The local map's previous points, whose memory the next UpdateLocalMap fills (a VGA local map
  // is megabytes: fresh allocations cost page faults on every reference frame).
  std::vector<Eigen::Vector3f> spare_positions_;
  std::vector<Eigen::Vector3f> spare_gradients_;
};

}  // namespace evloc::odometry
