// The transport-free parts of a tracking session (docs/api.md): the admission of a SessionStart,
// the validation of every later request with the gRPC status of each refusal (run by the stream
// reader), and the tracker state (run by the session's tracking worker). The threads, queues and
// the stream itself are in localizer_server.cc; the byte-level codec shared with the clients is in
// localizer/wire, the camera and pose conversions in proto/convert; the fuzz targets in fuzz/
// drive this code without a network.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <grpcpp/support/status.h>
#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/events/event.h"
#include "core/events/prophesee_decoder.h"
#include "core/geo/geo_anchor.h"
#include "core/geo/gnss_prior.h"
#include "core/geometry/rigid3.h"
#include "evloc/localizer.pb.h"
#include "localizer/odometry/handover.h"
#include "localizer/relocalization/event_image_hypotheses.h"
#include "localizer/service/map_registry.h"
#include "localizer/tracking/tiled_map_source.h"
#include "localizer/tracking/tracker.h"

namespace evloc::service {

// Checks a GnssFix (CheckGnssPrior); throws InvalidArgumentError naming `what` and the field.
GnssPrior GnssPriorFromProto(const api::GnssFix& fix, const std::string& what);

// Describes a loaded map for clients.
api::MapDescription DescribeMap(const LoadedMap& map);
// Describes a map from what the registry read of it (ListMaps, without loading it).
api::MapDescription DescribeMap(const MapDescriptionData& map);
// A PoseUpdate for a tracker step (latency_us left at 0: set when handed to the transport), from
// `source` (the map tracker, or odometry during a hand-over).
api::PoseUpdate PoseUpdateFromEstimate(const tracking::PoseEstimate& estimate,
                                       const GeoReference* geo = nullptr,
                                       odometry::PoseSource source = odometry::PoseSource::kMap);

// The depth camera of a session (SessionStart.depth_camera).
struct DepthCameraSettings {
  // The depth camera.
  Camera camera;
  // p_event = event_from_depth * p_depth.
  Rigid3d event_from_depth;
};

// Validates a DepthFrame against the depth camera and the previous depth frame time and returns
// its depth in metres (CV_32FC1, 0 = none). Throws InvalidArgumentError for a size mismatch, a
// wrong byte count or a time not after `previous_t_ns`.
cv::Mat DepthFromProto(const api::DepthFrame& frame, const Camera& depth_camera,
                       std::optional<int64_t> previous_t_ns);

// Validates raw grey pixels (`what` names them in errors) against the camera's size and returns
// them (CV_8UC1, a copy). Throws InvalidArgumentError for a size mismatch or a wrong byte count.
cv::Mat GrayFromProto(uint32_t width, uint32_t height, const std::string& pixels,
                      const Camera& camera, const std::string& what);

// Validates a Frame against the camera and the previous frame time and returns its pixels
// (CV_8UC1, a copy). Throws InvalidArgumentError for a size mismatch or a time not after
// `previous_t_ns`.
cv::Mat FrameFromProto(const api::Frame& frame, const Camera& camera,
                       std::optional<int64_t> previous_t_ns);

// What a session runs with, from its SessionStart.
struct SessionSettings {
  // The event (or frame) camera.
  Camera camera;
  // Pose at initial_t_ns; nullopt: the session starts without a pose and relocalizes first (event
  // sessions only; docs/api.md, "Starting without a pose").
  std::optional<Rigid3d> initial_world_from_cam;
  // Session time of the initial pose, ns.
  int64_t initial_t_ns = 0;
  // Velocity at the initial pose (body-frame twist per second); nullopt: at rest.
  std::optional<Vector6d> initial_velocity;
  // Tracker options (server defaults with the client's overrides).
  tracking::TrackerOptions tracker;
  // Session time = sensor time + this, for raw Prophesee packets, ns.
  int64_t sensor_time_offset_ns = 0;
  // The depth camera of a session that streams DepthFrames (the hand-over to odometry).
  std::optional<DepthCameraSettings> depth_camera;
};

// Largest |time| a session accepts (initial time, packet ends, frame and hint times, event
// times after the sensor offset), ns: 2^62 ns is 146 years, and the bound keeps every time
// computation far from int64 overflow.
inline constexpr int64_t kMaxSessionTimeNs = int64_t{1} << 62;

// What the server allows a session (server options, the same for every session).
struct SessionLimits {
  // Tracker options of a session that sets none (SessionStart.options override them).
  tracking::TrackerOptions tracker;
  // Largest camera, width * height pixels: a session's memory grows with the sensor size
  // (time surfaces, fields, undistortion table) (--max-camera-pixels).
  int64_t max_camera_pixels = int64_t{1} << 22;
  // Most an EventPacket's end_t_ns or a PoseHint's time may lie after the session time (the latest
  // of the initial time, the previous packet's end and the last hint), ns: one request can then
  // make the tracker run at most max_packet_span_ns * max_step_rate_hz / 1e9 steps
  // (--max-packet-span).
  int64_t max_packet_span_ns = 1'000'000'000;
  // Highest step rate a session may ask for, Hz (--max-rate).
  double max_step_rate_hz = 2'000;
  // Most map points per step a session may ask for (TrackingOptions.max_points); the cost of a
  // step grows with it (--max-points-limit).
  int max_points_limit = 10'000;
  // Most tracking steps one EventPacket may complete: (end_t_ns - session time) * step rate is
  // refused above this, so one request costs at most this many steps (--max-steps-per-request).
  int64_t max_steps_per_request = 1'000;
  // Most events one EventPacket may decode to: EVT 3.0 vector words expand about 75x in memory
  // (a 4 MiB message would be ~24M events); raw packets are decoded in chunks and refused once
  // they pass this (--max-packet-events).
  int64_t max_packet_events = int64_t{1} << 20;

  // Throws InvalidArgumentError naming the first invalid field.
  void Check() const;
};

// Reads the settings of a SessionStart on top of `limits.tracker`. Throws InvalidArgumentError
// when the camera (also when it exceeds limits.max_camera_pixels), the pose, a time or an option
// (also a step rate above limits.max_step_rate_hz) is invalid (the message names the field).
SessionSettings SessionSettingsFromProto(const api::SessionStart& start,
                                         const SessionLimits& limits);

// Most a raw (EVT3 / EVT2) event time may lie before the previous event or the previous packet's
// end and still be taken (raised to the earliest time allowed), ns. Real sensors emit events a
// few microseconds out of order (readout order; the EVT 3.0 sample has steps back of 3-11 us),
// and a client passing raw bytes through cannot know whether more events of the last
// microsecond will follow a packet.
inline constexpr int64_t kMaxRawTimeAdjustmentNs = 1'000'000;

// Raw (EVT3 / EVT2) packets are decoded this many bytes at a time, the event cap checked after
// each chunk (at most ~6 events per byte: 400k events, ~5 MB, past the cap).
inline constexpr size_t kRawDecodeChunkBytes = 64 << 10;

// Bytes a decoded event takes in an EventBuffer (time, x, y, polarity): what the server's memory
// accounting charges per queued event.
inline constexpr int64_t kDecodedEventBytes = 8 + 2 + 2 + 1;

// Validates and decodes the EventPackets of one session, in order. Every event must lie on the
// sensor, after the previous packet's end and at or before its packet's end, in time order;
// packet ends must not decrease; the encoding must not change. Raw (EVT3 / EVT2) events up to
// kMaxRawTimeAdjustmentNs out of that order are raised to the earliest time allowed (the
// previous event's time, or the previous end + 1 ns) and counted. Not thread-safe.
class PacketDecoder {
 public:
  // Events must lie inside `sensor_size`; raw packets get `sensor_time_offset_ns` added; a packet
  // may hold at most `max_events` events.
  PacketDecoder(SensorSize sensor_size, int64_t sensor_time_offset_ns,
                int64_t max_events = SessionLimits{}.max_packet_events);

  // Appends the events of `packet` to `out` (cleared first). Throws InvalidArgumentError (with
  // the packet number) for a malformed or out-of-order packet, or one of more than `max_events`
  // events (raw data is decoded in chunks of kRawDecodeChunkBytes and refused as soon as the
  // count passes the cap, so a packet never holds more than the cap plus one chunk's events);
  // the session cannot continue after that.
  void Decode(const api::EventPacket& packet, EventBuffer* out);

  // End time of the last packet, ns (nullopt before the first).
  std::optional<int64_t> end_t_ns() const { return end_t_ns_; }
  // Packets decoded so far.
  uint64_t packets() const { return packets_; }
  // Raw events of the accepted packets whose time was raised to keep the stream in order.
  uint64_t raw_time_adjustments() const { return raw_time_adjustments_; }

 private:
  // Raises raw event times that go back by at most kMaxRawTimeAdjustmentNs and returns how many
  // it raised; throws InvalidArgumentError for a larger step back.
  uint64_t OrderRawTimes(uint64_t index, EventBuffer* events) const;

  SensorSize sensor_size_;
  int64_t sensor_time_offset_ns_;
  int64_t max_events_;
  api::EventEncoding encoding_ = api::EVENT_ENCODING_UNSPECIFIED;
  std::unique_ptr<EventStreamDecoder> raw_decoder_;
  EventBuffer raw_events_;
  std::optional<int64_t> end_t_ns_;
  std::optional<int64_t> last_event_t_ns_;
  uint64_t packets_ = 0;
  uint64_t raw_time_adjustments_ = 0;
};

// One request of a running session after validation: what the tracking worker runs.
struct SessionItem {
  // What the request was.
  enum class Kind {
    // An EventPacket: `events`, then every step up to `t_ns` (its end_t_ns) runs.
    kEvents,
    // A Frame: `gray` taken at `t_ns`.
    kFrame,
    // A PoseHint: reset to `world_from_cam` at `t_ns`.
    kPoseHint,
    // A GnssFix: `gnss` at `t_ns`, a prior for the next relocalizations.
    kGnssFix,
    // A DepthFrame: `depth_m` taken at `t_ns`.
    kDepth,
  };
  // The kind of request.
  Kind kind = Kind::kEvents;
  // kEvents: the decoded events of the packet.
  EventBuffer events;
  // kFrame: the grey pixels (CV_8UC1, the camera's size).
  cv::Mat gray;
  // kDepth: the depth in metres (CV_32FC1, the depth camera's size).
  cv::Mat depth_m;
  // kPoseHint: the pose.
  Rigid3d world_from_cam;
  // kGnssFix: the fix.
  GnssPrior gnss;
  // kEvents: the packet's end_t_ns; kFrame: the frame time; kPoseHint: the hint time; ns.
  int64_t t_ns = 0;
};

// Folds the event packet `later` into `earlier`, the packet just before it: every other event
// of the two, in order (the first of `earlier` kept), and the end time of `later`. A searching
// session behind its stream thins its queue so (docs/api.md, "Flow control and backpressure"):
// fewer events, but no gap in time. Both must be kEvents items.
void FoldEventPackets(SessionItem* earlier, const SessionItem& later);

// Appends every `stride`-th event of the event packet `later` (its first event first) to
// `earlier`, the packet just before it, and gives `earlier` the end time of `later`. A searching
// session behind its stream thins its newest packets into its queue so (docs/api.md, "Flow
// control and backpressure"): fewer events, but no gap in time. Both must be kEvents items;
// stride >= 1.
void AppendThinnedEvents(SessionItem* earlier, const SessionItem& later, size_t stride);

// Validates the requests that follow the SessionStart, in order (the stream reader's side of a
// session): decodes EventPackets (PacketDecoder), checks Frames and PoseHints, and refuses what
// docs/api.md refuses. Not thread-safe.
class RequestValidator {
 public:
  // For a session with these settings and limits.
  RequestValidator(const SessionSettings& settings, const SessionLimits& limits);

  // Validates `request` and fills `item` for SessionTracker::Process. Returns OK, or the status
  // that ends the session: FAILED_PRECONDITION for a second SessionStart, INVALID_ARGUMENT for
  // anything else that is wrong (malformed or out-of-order packet, event outside the sensor, time
  // going back, a Frame in an event session or events in a frame session, a bad pose, an empty
  // request, a packet end or hint time more than limits.max_packet_span_ns after the session
  // time, a packet that would complete more than limits.max_steps_per_request steps or decodes to
  // more than limits.max_packet_events events). The session cannot continue after an error.
  grpc::Status Accept(const api::TrackRequest& request, SessionItem* item);

  // The packet decoder (packet count and last end time).
  const PacketDecoder& decoder() const { return decoder_; }
  // Session time of the latest request accepted (packet end, frame or hint time), ns.
  std::optional<int64_t> latest_t_ns() const { return latest_t_ns_; }

 private:
  // Throws InvalidArgumentError when `t_ns` lies more than the span limit after the session time.
  void CheckSpan(int64_t t_ns, const char* what) const;
  // Throws InvalidArgumentError when a packet ending at `end_t_ns` would complete more than
  // max_steps_per_request_ steps.
  void CheckSteps(int64_t end_t_ns) const;

  Camera camera_;
  bool takes_frames_ = false;
  int64_t max_packet_span_ns_;
  // The session's step rate, Hz, and the most steps one packet may complete.
  double step_rate_hz_;
  int64_t max_steps_per_request_;
  // The latest of the initial time, the packet ends and the hint times, ns.
  int64_t session_t_ns_;
  PacketDecoder decoder_;
  std::optional<int64_t> last_frame_t_ns_;
  std::optional<Camera> depth_camera_;
  std::optional<int64_t> last_depth_t_ns_;
  std::optional<int64_t> latest_t_ns_;
};

// A fix stops narrowing the search this long after its time (session time), ns: a vehicle at
// 10 m/s has moved 300 m.
inline constexpr int64_t kGnssPriorLifetimeNs = 30'000'000'000;

// The tracker of one session and its start-up: events up to the initial time prime the time
// surfaces, then the tracker is reset to the initial pose (exactly as the offline
// TrackEventStream does, so both give the same poses). Not thread-safe.
class SessionTracker {
 public:
  // Keeps `map` alive for the session. For a site, the tiles needed at the initial pose are
  // loaded here (the only tile loads a session waits for; later ones run on the tile cache's
  // loader threads) and the tiles follow the tracker between step periods. Throws
  // InvalidArgumentError when the tracker rejects the camera or the options, or a site session
  // has no initial pose; IoError or ParseError when a tile needed at the start cannot be loaded.
  SessionTracker(std::shared_ptr<const LoadedMap> map, const SessionSettings& settings);

  // Asked between steps whether to stop (cancellation, shutdown, CPU budget): true makes Process
  // return the poses of the steps run so far and the session end.
  using StopFunction = std::function<bool()>;

  // Tracks one item that RequestValidator accepted and returns the steps that ran. An EventPacket
  // runs every step up to its end_t_ns (Tracker::AdvanceTo), so the pose of step t is ready after
  // the packet whose end_t_ns >= t, without waiting for a later packet. The packet is fed one
  // step period at a time (the tracker's poses do not depend on how events are split), and
  // `stop` (when set) is asked before each period: a stop takes effect within one step. After a
  // stop, stopped() is true and the tracker must not be used again. Throws only on a bug (the
  // server reports INTERNAL).
  // `sources`, when not null, receives where each returned pose came from (the map tracker, or
  // odometry in a session with a depth camera).
  std::vector<tracking::PoseEstimate> Process(const SessionItem& item,
                                              const StopFunction& stop = {},
                                              std::vector<odometry::PoseSource>* sources = nullptr);

  // True when the session tracks frames.
  bool takes_frames() const { return takes_frames_; }
  // The map's geo reference, or null when the map has no geo anchor (GnssFix items are then
  // refused before Process: the server answers FAILED_PRECONDITION).
  const GeoReference* geo() const { return geo_ ? &*geo_ : nullptr; }
  // True once `stop` ended a Process call early.
  bool stopped() const { return stopped_; }
  // Session time the tracker has been advanced to (steps ran up to it), ns.
  int64_t advanced_t_ns() const { return advanced_t_ns_; }
  // The live viewer's picture (docs/viewer.md): the unsigned time surface at `t_ns` with the
  // map points that may be visible from `world_from_cam` reprojected onto it (CV_8UC3; green on
  // an active pixel, red not). Empty before the tracker started.
  cv::Mat SurfacePicture(const Rigid3d& world_from_cam, int64_t t_ns) const;
  // The hand-over to odometry (sessions with a depth camera), else null.
  const odometry::MapOdometryHandover* handover() const { return handover_.get(); }

 private:
  std::vector<tracking::PoseEstimate> AddEvents(const EventBuffer& events, int64_t end_t_ns,
                                                const StopFunction& stop);
  // Feeds `events` (all after advanced_t_ns_) and advances to `end_t_ns`, one step period at a
  // time, asking `stop` before each period; appends the poses to `estimates`.
  void TrackInPeriods(const EventBuffer& events, int64_t end_t_ns, const StopFunction& stop,
                      std::vector<tracking::PoseEstimate>* estimates);
  // Starts the tracker at the initial pose and time, or without a pose (it searches the map);
  // throws InvalidArgumentError for a frame session without a pose.
  void StartTracker();
  // Process without the sources.
  std::vector<tracking::PoseEstimate> ProcessItem(const SessionItem& item,
                                                  const StopFunction& stop);
  // Feeds events to the tracker (through the hand-over when there is one) and appends the steps.
  void FeedEvents(const EventBuffer& events, std::vector<tracking::PoseEstimate>* estimates);
  // Advances the tracker (through the hand-over when there is one) and appends the steps.
  void Advance(int64_t t_ns, std::vector<tracking::PoseEstimate>* estimates);
  // Appends hand-over poses to `estimates` and their sources to sources_.
  void Append(std::vector<odometry::HandoverEstimate> reported,
              std::vector<tracking::PoseEstimate>* estimates);

  std::shared_ptr<const LoadedMap> map_;
  SessionSettings settings_;
  // What the tracker reads the map through: the whole map, or a site's tiles near the pose
  // (`tiled_`, the same object, followed between step periods).
  std::unique_ptr<tracking::MapSource> source_;
  tracking::TiledMapSource* tiled_ = nullptr;
  // Hypotheses from images of the events for the search (a whole map with relocalization data,
  // an event session); declared before the tracker, whose request thread may use it until the
  // tracker is destroyed.
  std::optional<relocalization::EventImageHypotheses> image_hypotheses_;
  tracking::Tracker tracker_;
  // The hand-over to Canny-DEVO (sessions with a depth camera).
  std::unique_ptr<odometry::MapOdometryHandover> handover_;
  // The sources of the poses of the current Process call.
  std::vector<odometry::PoseSource> sources_;
  std::optional<GeoReference> geo_;
  // Session time of the GNSS fix behind the tracker's search prior, ns.
  std::optional<int64_t> gnss_prior_t_ns_;
  bool takes_frames_ = false;
  bool started_ = false;
  bool stopped_ = false;
  int64_t advanced_t_ns_ = 0;
  EventBuffer head_;
  EventBuffer tail_;
  EventBuffer slice_;
};

// A session admitted from its SessionStart: the map version it tracks against, its settings and
// its tracker.
struct OpenedSession {
  // The map (kept alive by the session).
  std::shared_ptr<const LoadedMap> map;
  // The settings.
  SessionSettings settings;
  // The tracker.
  std::unique_ptr<SessionTracker> tracker;
};

// Admits a session: gets the map from `registry` and validates the SessionStart against
// `limits`. Returns OK with `session` filled, or NOT_FOUND (unknown map or version),
// INVALID_ARGUMENT (camera, pose, time or options; a camera above limits.max_camera_pixels), or
// FAILED_PRECONDITION (the map exists but cannot be loaded).
grpc::Status OpenSession(const api::SessionStart& start, MapRegistry& registry,
                         const SessionLimits& limits, OpenedSession* session);

}  // namespace evloc::service
