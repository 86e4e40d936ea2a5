#include "ros/node_core.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <utility>

#include <grpcpp/grpcpp.h>

#include "core/camera/calibration_file.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/dataset/pose_text.h"
#include "core/dataset/rosbag_dataset.h"
#include "core/events/prophesee_decoder.h"
#include "core/events/rosbag_events.h"
#include "core/trajectory/tum_io.h"
#include "evloc/localizer.grpc.pb.h"
#include "localizer/offline/offline_tracking.h"
#include "localizer/wire/packed_events.h"
#include "localizer/wire/status_name.h"
#include "maps/map.h"
#include "maps/map_directory.h"
#include "maps/visibility.h"
#include "proto/convert/proto_convert.h"

namespace evloc::ros_node {
namespace {

// A copy: EventColumns (a C++17 header's plain vectors) and EventBuffer (arrays that skip the
// zero-fill on resize) have different allocators, so the arrays cannot be moved across.
EventBuffer ToBuffer(const EventColumns& columns) {
  EventBuffer events;
  events.t_ns.assign(columns.t_ns.begin(), columns.t_ns.end());
  events.x.assign(columns.x.begin(), columns.x.end());
  events.y.assign(columns.y.begin(), columns.y.end());
  events.polarity.assign(columns.polarity.begin(), columns.polarity.end());
  return events;
}

Rigid3d ToRigid(const PoseFields& pose) {
  for (const double value : pose.position) {
    if (!std::isfinite(value)) throw InvalidArgumentError("pose: a position is not finite");
  }
  for (const double value : pose.orientation) {
    if (!std::isfinite(value)) throw InvalidArgumentError("pose: an orientation is not finite");
  }
  Eigen::Quaterniond rotation(pose.orientation[3], pose.orientation[0], pose.orientation[1],
                              pose.orientation[2]);
  if (std::abs(rotation.norm() - 1.0) > kPoseQuaternionNormTolerance) {
    throw InvalidArgumentError("pose: the quaternion's norm is " + std::to_string(rotation.norm()) +
                               ", not within 1e-3 of 1");
  }
  rotation.normalize();
  return Rigid3d(rotation, Eigen::Vector3d(pose.position[0], pose.position[1], pose.position[2]));
}

// A step's fields; the covariance (body-frame (v, omega), row-major) turned into ROS's.
StepOutput ToOutput(int64_t t_ns, const Rigid3d& pose, const Matrix6d& body_covariance,
                    const std::string& status) {
  StepOutput out;
  out.t_ns = t_ns;
  out.pose.position = {pose.translation.x(), pose.translation.y(), pose.translation.z()};
  out.pose.orientation = {pose.rotation.x(), pose.rotation.y(), pose.rotation.z(),
                          pose.rotation.w()};
  // world_from_cam * Exp(v, omega): to first order the position moves by R v and the orientation
  // turns by R omega about the map's axes.
  Matrix6d rotate = Matrix6d::Zero();
  const Eigen::Matrix3d r = pose.rotation.toRotationMatrix();
  rotate.topLeftCorner<3, 3>() = r;
  rotate.bottomRightCorner<3, 3>() = r;
  const Matrix6d turned = rotate * body_covariance * rotate.transpose();
  // Exactly symmetric, as consumers of the message (robot_localization) expect.
  const Matrix6d covariance = 0.5 * (turned + turned.transpose());
  for (int row = 0; row < 6; ++row) {
    for (int col = 0; col < 6; ++col) out.covariance[6 * row + col] = covariance(row, col);
  }
  out.status = status;
  out.tracking = status == "TRACKING";
  return out;
}

StepOutput ToOutput(const tracking::PoseEstimate& step) {
  StepOutput out = ToOutput(step.t_ns, step.world_from_cam, step.covariance,
                            tracking::TrackingStatusName(step.status));
  out.alignment = step.quality.alignment;
  out.on_edge_fraction = step.quality.on_edge_fraction;
  out.points_used = static_cast<uint32_t>(std::max(0, step.quality.points_used));
  out.step_ms = step.timings.total_ms;
  return out;
}

// A PoseUpdate of the server. Throws InvalidArgumentError for a malformed one.
StepOutput ToOutput(const api::PoseUpdate& update) {
  const char* status = "LOST";
  switch (update.status()) {
    case api::TRACKING:
      status = "TRACKING";
      break;
    case api::LOST:
      status = "LOST";
      break;
    case api::INITIALIZING:
      status = "INITIALIZING";
      break;
    case api::RELOCALIZING:
      status = "RELOCALIZING";
      break;
    default:
      throw InvalidArgumentError("PoseUpdate with an unknown status");
  }
  Matrix6d covariance = Matrix6d::Identity() * 1e6;
  if (update.covariance_size() == 36) {
    for (int i = 0; i < 36; ++i) covariance(i / 6, i % 6) = update.covariance(i);
  }
  const Rigid3d pose =
      update.has_world_from_cam()
          ? RigidFromProtoExact(update.world_from_cam(), "PoseUpdate.world_from_cam")
          : Rigid3d();
  StepOutput out = ToOutput(update.t_ns(), pose, covariance, status);
  out.on_edge_fraction = update.quality().on_edge_fraction();
  out.points_used = update.quality().points_used();
  out.step_ms = update.step_ms();
  return out;
}

std::optional<SensorSize> Bounds(uint32_t width, uint32_t height) {
  if (width > 65535 || height > 65535) {
    throw InvalidArgumentError("expected a width and height of at most 65535, found " +
                               std::to_string(width) + "x" + std::to_string(height));
  }
  if (width == 0 || height == 0) return std::nullopt;
  return SensorSize{static_cast<int>(width), static_cast<int>(height)};
}

}  // namespace

struct NodeCore::State {
  NodeCoreOptions options;
  tracking::TrackerOptions tracker_options;
  Map map;
  std::unique_ptr<VisibilityIndex> visibility;
  std::unique_ptr<tracking::StaticMapSource> source;
  std::optional<Camera> camera;
  // What the calibration reader of ~calib ignored.
  std::vector<std::string> calibration_notes;
  bool initial_pose_known = false;
  std::optional<Rigid3d> initial_world_from_cam;
  std::optional<int64_t> initial_t_ns;
  std::unique_ptr<tracking::EventStreamTracker> stream;
  // Events kept before the start, one buffer per message, in order.
  std::deque<EventBuffer> pending;
  // The events at the last message's last time, given to the tracker with the next message.
  EventBuffer held;
  std::optional<int64_t> last_event_t_ns;
  // The event stream's size (first message that states one) and its EVT 3.0 decoder.
  std::optional<SensorSize> sensor_size;
  std::unique_ptr<Evt3Decoder> evt3;

  // Service mode: the Track stream and the thread that reads its responses.
  StepCallback on_step;
  StreamEndCallback on_end;
  std::unique_ptr<api::Localizer::Stub> stub;
  // The bearer token's metadata value ("Bearer T"), empty without ~token_file.
  std::string authorization;
  // The call's context: a new one for each attempt to open the stream (gRPC allows one call per
  // context).
  std::unique_ptr<grpc::ClientContext> context;
  std::unique_ptr<grpc::ClientReaderWriter<api::TrackRequest, api::TrackResponse>> track;
  std::thread reader;
  std::mutex mutex;
  std::condition_variable ended_changed;
  bool ended = false;
  // False once a write failed (the server ended the stream: the reader reports why).
  bool writable = true;
  // Flow control (docs/api.md, "Flow control and backpressure"): the end times of the packets
  // sent and not yet answered by a pose at or after them (guarded by `mutex`), the server's queue
  // capacity, and the events held back while too many packets are in flight, sent later as one
  // larger packet (the poses do not depend on how events are split into packets).
  std::deque<int64_t> in_flight_ends;
  size_t queue_capacity = 256;
  EventBuffer unsent;
  int64_t unsent_end_t_ns = 0;
  // Thinning while the server searches (docs/api.md): its announced rate (0: none, or
  // ~thin_while_searching off), whether the newest update had no pose (guarded by `mutex`), the
  // end of the last packet sent, and the buffer of a thinned packet.
  uint64_t searching_event_rate = 0;
  bool searching = false;
  std::optional<int64_t> last_sent_end_t_ns;
  EventBuffer thinned;
};

NodeCore::NodeCore(const NodeCoreOptions& options, StepCallback on_step, StreamEndCallback on_end)
    : state_(std::make_unique<State>()) {
  State& s = *state_;
  s.options = options;
  s.on_step = std::move(on_step);
  s.on_end = std::move(on_end);
  service_ = !options.server.empty();
  if (service_ && options.map_name.empty()) {
    throw InvalidArgumentError(
        "parameter ~map_name is required with ~server: the map's name on "
        "the server");
  }
  if (!service_ && options.map_path.empty()) {
    throw InvalidArgumentError(
        "parameter ~map is required: the map file (.evmap) or folder (or "
        "~server and ~map_name for a localizer server)");
  }
  if (!std::isfinite(options.buffer_s) || options.buffer_s < 0 || options.buffer_s > 60) {
    throw InvalidArgumentError("parameter ~buffer_s must be in 0..60 seconds");
  }
  if (!std::isfinite(options.max_gap_s) || options.max_gap_s <= 0 || options.max_gap_s > 3600) {
    throw InvalidArgumentError("parameter ~max_gap_s must be in (0, 3600] seconds");
  }
  max_gap_ns_ = static_cast<int64_t>(std::llround(options.max_gap_s * 1e9));
  if (options.step_rate_hz != 0) s.tracker_options.step_rate_hz = options.step_rate_hz;
  try {
    s.tracker_options.Check();
  } catch (const InvalidArgumentError& error) {
    throw InvalidArgumentError("parameter ~rate: " + std::string(error.what()));
  }
  if (options.init_pose == "none") {
    mode_ = InitialPoseMode::kSearch;
    s.initial_pose_known = true;
  } else if (options.init_pose == "topic") {
    mode_ = InitialPoseMode::kHint;
  } else {
    mode_ = InitialPoseMode::kParameter;
    s.initial_world_from_cam = ParsePoseText("parameter ~init_pose", options.init_pose);
    s.initial_pose_known = true;
  }
  if (!options.init_stamp.empty()) {
    try {
      s.initial_t_ns = ParseSecondsAsNanoseconds(options.init_stamp);
    } catch (const Error& error) {
      throw InvalidArgumentError("parameter ~init_stamp: " + std::string(error.what()) +
                                 " (seconds, e.g. 1700000000.000123456)");
    }
  }
  if (service_) {
    grpc::ChannelArguments arguments;
    std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
    if (!options.tls_ca.empty()) {
      grpc::SslCredentialsOptions ssl;
      ssl.pem_root_certs = ReadFileToString(options.tls_ca);
      credentials = grpc::SslCredentials(ssl);
    }
    s.stub =
        api::Localizer::NewStub(grpc::CreateCustomChannel(options.server, credentials, arguments));
    if (!options.token_file.empty()) {
      std::string token = ReadFileToString(options.token_file);
      while (!token.empty() && (token.back() == '\n' || token.back() == '\r')) token.pop_back();
      if (token.empty()) {
        throw InvalidArgumentError("parameter ~token_file: " + options.token_file + " is empty");
      }
      s.authorization = "Bearer " + token;
    }
  } else {
    s.map = LoadMap(ResolveMapFile(options.map_path));
    s.visibility = std::make_unique<VisibilityIndex>(s.map);
    s.source = std::make_unique<tracking::StaticMapSource>(s.map, s.visibility.get());
  }
  if (options.max_camera_pixels < 1) {
    throw InvalidArgumentError("parameter ~max_camera_pixels must be positive");
  }
  if (!options.calib_path.empty()) {
    const Camera camera = ReadCalibrationFile(options.calib_path, 0, 0, &s.calibration_notes);
    CheckCameraSize(camera);
    s.camera = camera;
  }
}

NodeCore::~NodeCore() {
  State& s = *state_;
  if (!s.track) return;
  try {
    FlushEvents();
  } catch (const std::exception&) {
    // Nothing more can be sent: end the session all the same.
  }
  // End the session: no more requests; the server answers with SessionEnd and closes. A server
  // that does not within 10 s is cancelled.
  s.track->WritesDone();
  {
    std::unique_lock<std::mutex> lock(s.mutex);
    if (!s.ended_changed.wait_for(lock, std::chrono::seconds(10), [&] { return s.ended; })) {
      s.context->TryCancel();
    }
  }
  s.reader.join();
}

void NodeCore::OpenStream(int64_t initial_t_ns) {
  State& s = *state_;
  s.context = std::make_unique<grpc::ClientContext>();
  if (!s.authorization.empty()) s.context->AddMetadata("authorization", s.authorization);
  s.track = s.stub->Track(s.context.get());
  api::TrackRequest request;
  api::SessionStart* start = request.mutable_start();
  start->set_map_name(s.options.map_name);
  *start->mutable_camera() = CameraToProto(*s.camera);
  if (s.initial_world_from_cam) {
    *start->mutable_initial_world_from_cam() = RigidToProto(*s.initial_world_from_cam);
  }
  start->set_initial_t_ns(initial_t_ns);
  if (s.options.step_rate_hz != 0)
    start->mutable_options()->set_step_rate_hz(s.options.step_rate_hz);
  start->set_client_name("evloc_ros_node");
  api::TrackResponse response;
  if (!s.track->Write(request) || !s.track->Read(&response) || !response.has_started()) {
    const grpc::Status status = s.track->Finish();
    s.track.reset();
    throw IoError("localizer server " + s.options.server + ": the session did not start: " +
                  wire::StatusCodeName(status.error_code()) + ": " + status.error_message());
  }
  if (response.started().queue_capacity() > 0) {
    s.queue_capacity = response.started().queue_capacity();
  }
  s.searching_event_rate =
      s.options.thin_while_searching ? response.started().searching_event_rate() : 0;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    s.searching = !s.initial_world_from_cam.has_value();
  }
  s.last_sent_end_t_ns.reset();
  s.reader = std::thread([&s] {
    api::TrackResponse message;
    std::string error;
    while (s.track->Read(&message)) {
      if (!message.has_pose()) continue;
      {
        std::lock_guard<std::mutex> lock(s.mutex);
        while (!s.in_flight_ends.empty() && s.in_flight_ends.front() <= message.pose().t_ns()) {
          s.in_flight_ends.pop_front();
        }
        s.searching = !message.pose().has_world_from_cam();
      }
      if (!s.on_step) continue;
      try {
        s.on_step(ToOutput(message.pose()));
      } catch (const Error& failure) {
        error = failure.what();
      }
    }
    const grpc::Status status = s.track->Finish();
    if (!status.ok()) {
      error =
          std::string(wire::StatusCodeName(status.error_code())) + ": " + status.error_message();
    }
    {
      std::lock_guard<std::mutex> lock(s.mutex);
      s.ended = true;
    }
    s.ended_changed.notify_all();
    if (s.on_end) s.on_end(error);
  });
}

void NodeCore::SendEvents(const EventBuffer& events, int64_t end_t_ns) {
  State& s = *state_;
  if (!s.writable) return;
  s.unsent.Append(events);
  s.unsent_end_t_ns = end_t_ns;
  // Hold the events back while a quarter of the server's queue is in flight (it is behind), up to
  // half a second or 500,000 events: then they go anyway (a server that stays behind ends the
  // session with RESOURCE_EXHAUSTED, which the node logs).
  size_t in_flight = 0;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    in_flight = s.in_flight_ends.size();
  }
  const bool held_long =
      !s.unsent.empty() &&
      (s.unsent.t_ns.back() - s.unsent.t_ns.front() > 500'000'000 || s.unsent.size() >= 500'000);
  if (in_flight >= std::max<size_t>(1, s.queue_capacity / 4) && !held_long) return;
  FlushEvents();
}

void NodeCore::Poll() {
  State& s = *state_;
  if (!s.track || (s.unsent.empty() && s.unsent_end_t_ns == 0)) return;
  size_t in_flight = 0;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    in_flight = s.in_flight_ends.size();
  }
  if (in_flight < std::max<size_t>(1, s.queue_capacity / 4)) FlushEvents();
}

void NodeCore::FlushEvents() {
  State& s = *state_;
  if (!s.writable || (s.unsent.empty() && s.unsent_end_t_ns == 0)) return;
  const EventBuffer& events = s.unsent;
  const int64_t end_t_ns = s.unsent_end_t_ns;
  // PACKED offsets reach 2^31 - 1 ns from a packet's base: longer spans go in several packets,
  // each ending at its last event (its window), the last one at end_t_ns.
  size_t begin = 0;
  do {
    const int64_t base = begin < events.size() ? events.t_ns[begin] : end_t_ns;
    const size_t end =
        static_cast<size_t>(std::upper_bound(events.t_ns.begin() + begin, events.t_ns.end(),
                                             base + wire::kMaxPackedOffsetNs) -
                            events.t_ns.begin());
    api::TrackRequest request;
    api::EventPacket* packet = request.mutable_events();
    packet->set_encoding(api::EVENT_ENCODING_PACKED);
    packet->set_time_base_ns(base);
    const int64_t packet_end_t_ns = end == events.size() ? end_t_ns : events.t_ns[end - 1];
    bool searching = false;
    if (s.searching_event_rate > 0) {
      std::lock_guard<std::mutex> lock(s.mutex);
      searching = s.searching;
    }
    // While the server searches, what its search needs: the packet's events over the time since
    // the last packet's end (or its first event).
    const size_t stride =
        searching ? wire::ThinEvents(events, begin, end,
                                     packet_end_t_ns - s.last_sent_end_t_ns.value_or(base),
                                     s.searching_event_rate, &s.thinned)
                  : 1;
    if (stride > 1) {
      counters_.thinned_events += (end - begin) - s.thinned.size();
      packet->set_data(wire::EncodePackedEvents(s.thinned, 0, s.thinned.size(), base));
    } else {
      packet->set_data(wire::EncodePackedEvents(events, begin, end, base));
    }
    packet->set_end_t_ns(packet_end_t_ns);
    s.last_sent_end_t_ns = packet_end_t_ns;
    {
      std::lock_guard<std::mutex> lock(s.mutex);
      s.in_flight_ends.push_back(packet_end_t_ns);
    }
    if (!s.track->Write(request)) {
      s.writable = false;
      break;
    }
    begin = end;
  } while (begin < events.size());
  s.unsent.clear();
  s.unsent_end_t_ns = 0;
}

bool NodeCore::has_camera() const { return state_->camera.has_value(); }

bool NodeCore::started() const { return state_->stream || state_->track; }

std::string NodeCore::waiting_for() const {
  if (started()) return "";
  if (!state_->camera) return "camera_info";
  if (!state_->initial_pose_known) return "a pose on initialpose";
  return "events";
}

const std::vector<std::string>& NodeCore::calibration_notes() const {
  return state_->calibration_notes;
}

std::string NodeCore::camera_description() const {
  if (!state_->camera) return "";
  return std::to_string(state_->camera->width) + "x" + std::to_string(state_->camera->height) +
         " " + CameraModelName(state_->camera->model);
}

std::string NodeCore::map_description() const {
  if (service_) {
    return "'" + state_->options.map_name + "' on the localizer server " + state_->options.server;
  }
  return state_->options.map_path + " (" + std::to_string(state_->map.size()) + " points, " +
         std::to_string(state_->map.keyframes.size()) + " keyframes)";
}

std::vector<StepOutput> NodeCore::AddEventArray(uint32_t width, uint32_t height,
                                                EventColumns events) {
  ++counters_.messages;
  try {
    const std::optional<SensorSize> bounds = Bounds(width, height);
    if (bounds && !state_->sensor_size) state_->sensor_size = bounds;
    const size_t count = events.t_ns.size();
    if (events.x.size() != count || events.y.size() != count || events.polarity.size() != count) {
      throw InvalidArgumentError("event columns of different lengths");
    }
    if (bounds) {
      size_t kept = 0;
      for (size_t i = 0; i < count; ++i) {
        if (events.x[i] >= bounds->width || events.y[i] >= bounds->height) continue;
        events.t_ns[kept] = events.t_ns[i];
        events.x[kept] = events.x[i];
        events.y[kept] = events.y[i];
        events.polarity[kept] = events.polarity[i];
        ++kept;
      }
      counters_.decoder_dropped_events += count - kept;
      events.t_ns.resize(kept);
      events.x.resize(kept);
      events.y.resize(kept);
      events.polarity.resize(kept);
    }
    return HandleEvents(ToBuffer(events));
  } catch (...) {
    ++counters_.rejected_messages;
    throw;
  }
}

std::vector<StepOutput> NodeCore::AddEventPacket(uint32_t width, uint32_t height, int64_t stamp_ns,
                                                 const std::string& encoding, bool is_bigendian,
                                                 const uint8_t* data, size_t size) {
  ++counters_.messages;
  try {
    const std::optional<SensorSize> bounds = Bounds(width, height);
    if (bounds && !state_->sensor_size) state_->sensor_size = bounds;
    if (is_bigendian) throw InvalidArgumentError("big-endian event packets are not supported");
    EventBuffer events;
    uint64_t dropped = 0;
    // As the bag reader: mono events bounded by this packet's size, EVT 3.0 by the stream's.
    DecodeEventPacketEvents(encoding, stamp_ns, data, size,
                            encoding == "mono" ? bounds : state_->sensor_size,
                            "event packets (EVT 3.0)", &events, &dropped, &state_->evt3);
    counters_.decoder_dropped_events += dropped;
    return HandleEvents(std::move(events));
  } catch (...) {
    ++counters_.rejected_messages;
    throw;
  }
}

std::vector<StepOutput> NodeCore::HandleEvents(EventBuffer events) {
  State& s = *state_;
  if (events.empty()) return {};
  if (!std::is_sorted(events.t_ns.begin(), events.t_ns.end())) {
    throw InvalidArgumentError("the message's events are not in time order");
  }
  if (s.last_event_t_ns && events.t_ns.front() < *s.last_event_t_ns) {
    throw InvalidArgumentError(
        "the message goes back in time (" +
        std::to_string((*s.last_event_t_ns - events.t_ns.front()) * 1e-9) +
        " s before the last event): publish one event stream, in time order");
  }
  if (events.t_ns.back() - events.t_ns.front() > max_gap_ns_) {
    throw InvalidArgumentError("the message's events span " +
                               std::to_string((events.t_ns.back() - events.t_ns.front()) * 1e-9) +
                               " s, more than ~max_gap_s (" + std::to_string(s.options.max_gap_s) +
                               " s): publish shorter packets");
  }
  counters_.events += events.size();
  const bool jumped = s.last_event_t_ns && events.t_ns.front() - *s.last_event_t_ns > max_gap_ns_;
  s.last_event_t_ns = events.t_ns.back();
  if (s.stream && s.stream->started() && jumped) {
    // Restart at the new events from the last good pose instead of stepping through the jump.
    s.held.clear();
    tracking::Tracker& tracker = s.stream->mutable_tracker();
    if (tracking::IsSearching(tracker.status())) {
      tracker.StartWithoutPose(events.t_ns.front());
    } else {
      tracker.Reset(tracker.last_good_world_from_cam(), events.t_ns.front());
    }
    ++counters_.restarts;
  }
  if (started()) return Track(events);
  s.pending.push_back(std::move(events));
  // Keep buffer_s of event time (the time surfaces forget older events).
  const int64_t keep_from_ns =
      *s.last_event_t_ns - static_cast<int64_t>(std::llround(s.options.buffer_s * 1e9));
  while (s.pending.size() > 1 && s.pending.front().t_ns.back() < keep_from_ns) {
    counters_.buffer_dropped_events += s.pending.front().size();
    s.pending.pop_front();
  }
  return TryStart();
}

void NodeCore::CheckCameraSize(const Camera& camera) const {
  const int64_t pixels = int64_t{camera.width} * camera.height;
  if (pixels > state_->options.max_camera_pixels) {
    throw InvalidArgumentError("camera " + std::to_string(camera.width) + "x" +
                               std::to_string(camera.height) + " has " + std::to_string(pixels) +
                               " pixels, more than ~max_camera_pixels (" +
                               std::to_string(state_->options.max_camera_pixels) + ")");
  }
}

bool NodeCore::SetCameraInfo(const CameraInfoFields& info, std::vector<StepOutput>* steps) {
  if (state_->camera) return false;
  const Camera camera =
      CameraFromRosCameraInfo(info.width, info.height, info.distortion_model, info.d, info.k);
  CheckCameraSize(camera);
  state_->camera = camera;
  *steps = TryStart();
  return true;
}

void NodeCore::SetPoseHint(const PoseFields& pose, int64_t stamp_ns,
                           std::vector<StepOutput>* steps) {
  State& s = *state_;
  const Rigid3d world_from_cam = ToRigid(pose);
  if (s.track && s.writable) {
    FlushEvents();
    // The server resets its tracker at the hint (PoseHint: at or after the session time).
    api::TrackRequest request;
    *request.mutable_pose_hint()->mutable_world_from_cam() = RigidToProto(world_from_cam);
    request.mutable_pose_hint()->set_t_ns(std::max(stamp_ns, s.last_event_t_ns.value_or(stamp_ns)));
    if (!s.track->Write(request)) s.writable = false;
    return;
  }
  if (s.stream && s.stream->started()) {
    const int64_t t_ns = std::max(stamp_ns, s.last_event_t_ns.value_or(stamp_ns));
    s.stream->mutable_tracker().Reset(world_from_cam, t_ns);
    return;
  }
  if (mode_ != InitialPoseMode::kHint) return;
  s.initial_world_from_cam = world_from_cam;
  if (stamp_ns > 0) s.initial_t_ns = stamp_ns;
  s.initial_pose_known = true;
  *steps = TryStart();
}

std::vector<StepOutput> NodeCore::TryStart() {
  State& s = *state_;
  if (started() || !s.camera || !s.initial_pose_known || s.pending.empty()) return {};
  const int64_t first_t_ns = s.pending.front().t_ns.front();
  int64_t initial_t_ns = s.initial_t_ns.value_or(first_t_ns);
  if (first_t_ns - initial_t_ns > max_gap_ns_) {
    // The initial time lies far before the events: start at the first event, not after
    // stepping through the gap.
    initial_t_ns = first_t_ns;
    ++counters_.restarts;
  }
  if (service_) {
    OpenStream(initial_t_ns);
  } else {
    s.stream = std::make_unique<tracking::EventStreamTracker>(
        *s.source, *s.camera, s.tracker_options, s.initial_world_from_cam, initial_t_ns);
  }
  std::vector<StepOutput> steps;
  std::deque<EventBuffer> pending = std::move(s.pending);
  s.pending.clear();
  for (const EventBuffer& events : pending) {
    for (StepOutput& step : Track(events)) steps.push_back(std::move(step));
  }
  return steps;
}

std::vector<StepOutput> NodeCore::Track(const EventBuffer& events) {
  State& s = *state_;
  // Every later event is at or after this message's last time t: the steps before t are due now
  // (Tracker::AdvanceTo(t - 1) runs them: the same steps and poses as when the next message
  // triggers them). The events at t itself wait for the next message, as AdvanceTo needs.
  EventBuffer& held = s.held;
  const int64_t last_t_ns = events.t_ns.back();
  // The events are sorted: those at last_t_ns are the tail.
  const size_t split = static_cast<size_t>(
      std::lower_bound(events.t_ns.begin(), events.t_ns.end(), last_t_ns) - events.t_ns.begin());
  EventBuffer now;
  if (held.empty()) {
    now.Append(events, 0, split);
  } else {
    now = std::move(held);
    now.Append(events, 0, split);
  }
  held.clear();
  held.Append(events, split, events.size() - split);
  if (service_) {
    SendEvents(now, last_t_ns - 1);
    return {};
  }
  std::vector<tracking::PoseEstimate> estimates;
  if (!now.empty()) estimates = s.stream->AddEvents(now);
  for (tracking::PoseEstimate& step : s.stream->AdvanceTo(last_t_ns - 1)) {
    estimates.push_back(std::move(step));
  }
  std::vector<StepOutput> steps;
  steps.reserve(estimates.size());
  for (const tracking::PoseEstimate& step : estimates) steps.push_back(ToOutput(step));
  counters_.steps += steps.size();
  return steps;
}

}  // namespace evloc::ros_node
