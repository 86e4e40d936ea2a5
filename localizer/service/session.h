// The transport-free parts of a tracking session (docs/api.md): the settings a SessionStart
// asks for, the validating decoder of EventPackets (run by the stream reader) and the tracker
// state (run by the session's tracking worker). The gRPC plumbing is in localizer_server.cc.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/events/event.h"
#include "core/events/prophesee_decoder.h"
#include "core/geometry/rigid3.h"
#include "evloc/localizer.pb.h"
#include "localizer/service/map_registry.h"
#include "localizer/tracking/tracker.h"

namespace evloc::service {

// Bytes per event of the PACKED encoding.
inline constexpr size_t kPackedEventBytes = 8;

// Encodes events [begin, end) of `events` in the PACKED layout relative to `time_base_ns`
// (for clients and tests). Throws InvalidArgumentError when an event lies before the base or
// 2^31 ns or more after it.
std::string EncodePackedEvents(const EventBuffer& events, size_t begin, size_t end,
                               int64_t time_base_ns);

// Converts a protobuf camera. Throws InvalidArgumentError naming the problem when the model is
// unset or the camera fails Camera::Check().
Camera CameraFromProto(const map_format::Camera& camera);
// Converts a camera to protobuf.
map_format::Camera CameraToProto(const Camera& camera);
// Converts a protobuf pose; throws InvalidArgumentError when a value is not finite or the
// quaternion is far from unit norm (it is normalised otherwise).
Rigid3d RigidFromProto(const map_format::Rigid3& pose, const char* what);
// Converts a pose to protobuf.
map_format::Rigid3 RigidToProto(const Rigid3d& pose);
// Describes a loaded map for clients.
api::MapDescription DescribeMap(const LoadedMap& map);
// A PoseUpdate for a tracker step (latency_us left at 0: set when handed to the transport).
api::PoseUpdate PoseUpdateFromEstimate(const tracking::PoseEstimate& estimate);

// Validates a Frame against the camera and the previous frame time and returns its pixels
// (CV_8UC1, a copy). Throws InvalidArgumentError for a size mismatch or a time not after
// `previous_t_ns`.
cv::Mat FrameFromProto(const api::Frame& frame, const Camera& camera,
                       std::optional<int64_t> previous_t_ns);

// What a session runs with, from its SessionStart.
struct SessionSettings {
  // The event (or frame) camera.
  Camera camera;
  // Pose at initial_t_ns.
  Rigid3d initial_world_from_cam;
  // Session time of the initial pose, ns.
  int64_t initial_t_ns = 0;
  // Tracker options (server defaults with the client's overrides).
  tracking::TrackerOptions tracker;
  // Session time = sensor time + this, for raw Prophesee packets, ns.
  int64_t sensor_time_offset_ns = 0;
};

// Reads the settings of a SessionStart on top of `defaults`. Throws InvalidArgumentError when
// the camera, the pose or an option is invalid (the message names the field).
SessionSettings SessionSettingsFromProto(const api::SessionStart& start,
                                         const tracking::TrackerOptions& defaults);

// Validates and decodes the EventPackets of one session, in order. Every event must lie on the
// sensor, after the previous packet's end and at or before its packet's end, in time order;
// packet ends must not decrease; the encoding must not change. Not thread-safe.
class PacketDecoder {
 public:
  // Events must lie inside `sensor_size`; raw packets get `sensor_time_offset_ns` added.
  PacketDecoder(SensorSize sensor_size, int64_t sensor_time_offset_ns);

  // Appends the events of `packet` to `out` (cleared first). Throws InvalidArgumentError (with
  // the packet number) for a malformed or out-of-order packet; the session cannot continue after
  // that.
  void Decode(const api::EventPacket& packet, EventBuffer* out);

  // End time of the last packet, ns (nullopt before the first).
  std::optional<int64_t> end_t_ns() const { return end_t_ns_; }
  // Packets decoded so far.
  uint64_t packets() const { return packets_; }

 private:
  SensorSize sensor_size_;
  int64_t sensor_time_offset_ns_;
  api::EventEncoding encoding_ = api::EVENT_ENCODING_UNSPECIFIED;
  std::unique_ptr<EventStreamDecoder> raw_decoder_;
  EventBuffer raw_events_;
  std::optional<int64_t> end_t_ns_;
  uint64_t packets_ = 0;
};

// The tracker of one session and its start-up: events up to the initial time prime the time
// surfaces, then the tracker is reset to the initial pose (exactly as the offline
// TrackEventStream does, so both give the same poses). Not thread-safe.
class SessionTracker {
 public:
  // Keeps `map` alive for the session. Throws InvalidArgumentError when the tracker rejects the
  // camera or the options.
  SessionTracker(std::shared_ptr<const LoadedMap> map, const SessionSettings& settings);

  // Ingests time-ordered events; returns the steps that became due.
  std::vector<tracking::PoseEstimate> AddEvents(const EventBuffer& events);
  // Tracks a grey frame (frame sessions); returns its step, if one ran.
  std::optional<tracking::PoseEstimate> AddFrame(int64_t t_ns, const cv::Mat& gray);
  // Resets the tracker to an external pose at t_ns.
  void Reset(const Rigid3d& world_from_cam, int64_t t_ns);

  // True when the session tracks frames.
  bool takes_frames() const { return takes_frames_; }

 private:
  std::shared_ptr<const LoadedMap> map_;
  SessionSettings settings_;
  tracking::Tracker tracker_;
  bool takes_frames_ = false;
  bool started_ = false;
  EventBuffer head_;
  EventBuffer tail_;
};

}  // namespace evloc::service
