// The ROS-free half of the evloc node (docs/ros.md): events, camera and pose hints in plain
// fields, tracking with the Tracker evloc-track runs (EventStreamTracker: the same events give the
// same poses), steps out in the fields of the ROS messages. Debian's ROS 1 headers compile only
// as C++17 (they use std::allocator::rebind, gone in C++20) and evloc's only as C++20, so this
// header is the boundary: it includes the standard library only, and the ROS side
// (localizer_node.h) builds as C++17 while this half builds as C++20.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace evloc {
class EventBuffer;
struct Camera;
}  // namespace evloc

namespace evloc::ros_node {

// Where the tracker's first pose comes from.
enum class InitialPoseMode {
  // `init_pose` (the ~init_pose parameter), at `init_stamp` (or the first event).
  kParameter,
  // None: the tracker searches the map (INITIALIZING until it verifies a pose).
  kSearch,
  // The first pose hint (the `initialpose` topic, e.g. RViz's "2D Pose Estimate") at its stamp.
  kHint,
};

// The node's options (its private parameters, docs/ros.md "Parameters").
struct NodeCoreOptions {
  // Map file (.evmap) or map folder (~map). Required.
  std::string map_path;
  // Calibration file of the event camera (~calib; any format of docs/camera.md); empty: the
  // first sensor_msgs/CameraInfo.
  std::string calib_path;
  // ~init_pose: "tx ty tz qx qy qz qw" (world_from_cam), "none" (search the map) or "topic" (wait
  // for a pose hint).
  std::string init_pose = "topic";
  // ~init_stamp: the initial pose's time, seconds as an exact decimal; empty: the first event's.
  std::string init_stamp;
  // ~rate: tracking steps per second of event time; 0: the tracker's default.
  double step_rate_hz = 0;
  // ~buffer_s: while waiting for a camera or a pose, the events of this many seconds (event time)
  // are kept to prime the time surfaces; older ones are dropped.
  double buffer_s = 1.0;
  // ~max_gap_s: the longest time a message's events may span, and the longest jump forward from
  // the last event (or from ~init_stamp at the start). The tracker runs every step of a jump (a
  // jump of hours would be millions of steps): a message that spans more is rejected; after a
  // longer jump the tracker restarts at the new events from its last good pose (and a start
  // waits for no ~init_stamp that far back: it starts at the first event).
  double max_gap_s = 5.0;
  // ~max_camera_pixels: the largest camera (width x height) accepted; the tracker's memory grows
  // with it (as the server's --max-camera-pixels, same default).
  int64_t max_camera_pixels = int64_t{1} << 22;
  // ~server: a localizer server (host:port, docs/api.md) to stream the events to instead of
  // tracking in-process; empty: in-process against ~map.
  std::string server;
  // ~map_name: the map's name on the server (with ~server; then ~map is not read).
  std::string map_name;
  // ~token_file: a file with the server's bearer token (docs/api.md, "Authentication").
  std::string token_file;
  // ~tls_ca: PEM root certificates to verify a TLS server with; empty: plaintext.
  std::string tls_ca;
  // ~thin_while_searching: with ~server, while the session searches the map (its updates carry
  // no pose), send at most the events per second the server announced
  // (SessionStarted.searching_event_rate), every k-th event of a packet (docs/api.md).
  bool thin_while_searching = true;
};

// An events message's events, as columns.
struct EventColumns {
  std::vector<int64_t> t_ns;
  std::vector<uint16_t> x;
  std::vector<uint16_t> y;
  // +1 ON, -1 OFF.
  std::vector<int8_t> polarity;
};

// The fields of a sensor_msgs/CameraInfo the node reads.
struct CameraInfoFields {
  uint32_t width = 0;
  uint32_t height = 0;
  std::string distortion_model;
  std::vector<double> d;
  std::array<double, 9> k{};
};

// A pose (world_from_cam) in the fields of geometry_msgs/Pose.
struct PoseFields {
  std::array<double, 3> position{};
  // x, y, z, w.
  std::array<double, 4> orientation{0, 0, 0, 1};
};

// A tracking step in the fields of the published messages.
struct StepOutput {
  // The step's time, nanoseconds.
  int64_t t_ns = 0;
  // world_from_cam.
  PoseFields pose;
  // The covariance as geometry_msgs/PoseWithCovariance states it (row-major; position, then
  // rotation about the map's fixed axes): the tracker's body-frame (v, omega) covariance turned
  // by J = diag(R, R). LOST, INITIALIZING and RELOCALIZING steps carry 1e6 variances.
  std::array<double, 36> covariance{};
  // TRACKING, LOST, INITIALIZING or RELOCALIZING.
  std::string status;
  // True for TRACKING (the pose is an estimate).
  bool tracking = false;
  // Chance-corrected alignment and on-edge fraction of the step.
  double alignment = 0;
  double on_edge_fraction = 0;
  // Map points registered.
  uint32_t points_used = 0;
  // Wall-clock time of the step, milliseconds.
  double step_ms = 0;
};

// Counters of a run.
struct NodeCounters {
  // Event messages received, and rejected (malformed, out of order, or failed in tracking).
  uint64_t messages = 0;
  uint64_t rejected_messages = 0;
  // Events received; dropped by the decoders (outside the sensor); dropped while waiting.
  uint64_t events = 0;
  uint64_t decoder_dropped_events = 0;
  uint64_t buffer_dropped_events = 0;
  // Steps returned.
  uint64_t steps = 0;
  // Restarts after a jump forward longer than max_gap_s (and starts moved to the first event).
  uint64_t restarts = 0;
  // Service mode: events left out while the server searched (~thin_while_searching).
  uint64_t thinned_events = 0;
};

// Called with each step a localizer server sent (service mode), on the stream's reader thread.
using StepCallback = std::function<void(const StepOutput& step)>;
// Called once when the server's stream ends, with what happened ("" after a normal end).
using StreamEndCallback = std::function<void(const std::string& error)>;

// The ROS-free node. Not thread-safe (the node calls it from the thread that spins); in service
// mode the steps come on a thread of their own through the StepCallback.
class NodeCore {
 public:
  // Checks the options, loads the map (in-process) and the calibration file. Throws
  // InvalidArgumentError naming the parameter for a bad option, and what LoadMap and
  // ReadCalibrationFile throw. In service mode (options.server) the steps go to `on_step` and
  // the Add* methods return none; `on_end` hears of the stream's end.
  explicit NodeCore(const NodeCoreOptions& options, StepCallback on_step = {},
                    StreamEndCallback on_end = {});
  ~NodeCore();
  NodeCore(const NodeCore&) = delete;
  NodeCore& operator=(const NodeCore&) = delete;

  // A dvs_msgs/EventArray's events: those outside width x height (when both are non-zero) are
  // dropped. Returns the steps that became due. Throws InvalidArgumentError (nothing kept) for a
  // size over 65535, events out of time order (within the message or before the last one),
  // events spanning more than max_gap_s, or a tracking error.
  std::vector<StepOutput> AddEventArray(uint32_t width, uint32_t height, EventColumns events);
  // An event_camera_msgs/EventPacket: encoding "mono" or "evt3", little endian (core/events'
  // DecodeEventPacketEvents, as the bag reader). Throws as AddEventArray, and ParseError for a
  // malformed EVT 3.0 payload.
  std::vector<StepOutput> AddEventPacket(uint32_t width, uint32_t height, int64_t stamp_ns,
                                         const std::string& encoding, bool is_bigendian,
                                         const uint8_t* data, size_t size);
  // The first camera info (later ones are ignored: returns false); starts the tracker when it
  // can and returns its first steps in `steps`. Throws InvalidArgumentError for an unsupported
  // model or an invalid camera (the node then waits for a valid one).
  bool SetCameraInfo(const CameraInfoFields& info, std::vector<StepOutput>* steps);
  // A pose hint (initialpose) at stamp_ns (0: now): the first pose in kHint mode, else a reset of
  // a running tracker at the last event's time (or the stamp, if later). Throws
  // InvalidArgumentError for a non-finite pose or a quaternion not within 1e-3 of unit norm.
  void SetPoseHint(const PoseFields& pose, int64_t stamp_ns, std::vector<StepOutput>* steps);

  // Service mode: sends the events held back (flow control) once the server has caught up; the
  // node calls it from a timer on the spinning thread. Nothing in-process.
  void Poll();

  // True once a camera is known (from ~calib or camera info).
  bool has_camera() const;
  // What the node waits for ("" once tracking).
  std::string waiting_for() const;
  // The camera's description ("240x180 radtan"), empty before one.
  std::string camera_description() const;
  // What the calibration reader of ~calib read but did not use, one sentence each (the node logs
  // them).
  const std::vector<std::string>& calibration_notes() const;
  // A one-line description of the map.
  std::string map_description() const;
  // The mode of the initial pose.
  InitialPoseMode initial_pose_mode() const { return mode_; }
  const NodeCounters& counters() const { return counters_; }

 private:
  struct State;
  std::vector<StepOutput> HandleEvents(EventBuffer events);
  std::vector<StepOutput> TryStart();
  std::vector<StepOutput> Track(const EventBuffer& events);
  // Service mode: opens the Track stream (SessionStart, SessionStarted) and its reader thread.
  void OpenStream(int64_t initial_t_ns);
  // Service mode: sends the events (all before end_t_ns), tracked up to end_t_ns, in PACKED
  // packets; holds them back while the server is behind (flow control).
  void SendEvents(const EventBuffer& events, int64_t end_t_ns);
  // Service mode: sends what SendEvents held back.
  void FlushEvents();

  // True once tracking started (in-process, or the server's session opened).
  bool started() const;
  // Throws InvalidArgumentError for a camera over max_camera_pixels.
  void CheckCameraSize(const Camera& camera) const;

  InitialPoseMode mode_ = InitialPoseMode::kHint;
  bool service_ = false;
  int64_t max_gap_ns_ = 0;
  NodeCounters counters_;
  std::unique_ptr<State> state_;
};

}  // namespace evloc::ros_node
