#include "localizer/service/session.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "core/common/error.h"
#include "localizer/tracking/surface_picture.h"
#include "localizer/wire/packed_events.h"
#include "localizer/wire/twist.h"
#include "proto/convert/proto_convert.h"

namespace evloc::service {
namespace {

std::string PacketName(uint64_t index) { return "event packet " + std::to_string(index); }

// Throws InvalidArgumentError when |t_ns| exceeds kMaxSessionTimeNs.
void CheckSessionTime(int64_t t_ns, const std::string& what) {
  if (t_ns < -kMaxSessionTimeNs || t_ns > kMaxSessionTimeNs) {
    throw InvalidArgumentError(what + " " + std::to_string(t_ns) +
                               " ns is out of range (|t| <= 2^62 ns)");
  }
}

grpc::Status InvalidArgument(const std::string& message) {
  return {grpc::StatusCode::INVALID_ARGUMENT, message};
}

// The set fields of a session's noise filter options, over the server's defaults (checked with
// the other tracker options).
void ApplyEventFilterOptions(const api::EventFilterOptions& proto,
                             tracking::EventFilterOptions* options) {
  if (proto.has_hot_pixels()) options->hot_pixels = proto.hot_pixels();
  if (proto.has_hot_pixel_window_s()) options->hot_pixel_window_s = proto.hot_pixel_window_s();
  if (proto.has_hot_pixel_rate_factor()) {
    options->hot_pixel_rate_factor = proto.hot_pixel_rate_factor();
  }
  if (proto.has_hot_pixel_min_rate_hz()) {
    options->hot_pixel_min_rate_hz = proto.hot_pixel_min_rate_hz();
  }
  if (proto.has_refractory_period_s()) options->refractory_period_s = proto.refractory_period_s();
  if (proto.has_background_activity_window_s()) {
    options->background_activity_window_s = proto.background_activity_window_s();
  }
  if (proto.has_background_activity_include_self()) {
    options->background_activity_include_self = proto.background_activity_include_self();
  }
}

}  // namespace

api::MapDescription DescribeMap(const MapDescriptionData& map) {
  const MapInfo& info = map.summary.info;
  api::MapDescription description;
  description.set_name(map.name);
  description.set_version(map.version);
  description.set_num_points(info.num_points);
  description.set_num_keyframes(info.num_keyframes);
  auto* low = description.mutable_bounding_box_min();
  low->set_x(info.bounding_box_min.x());
  low->set_y(info.bounding_box_min.y());
  low->set_z(info.bounding_box_min.z());
  auto* high = description.mutable_bounding_box_max();
  high->set_x(info.bounding_box_max.x());
  high->set_y(info.bounding_box_max.y());
  high->set_z(info.bounding_box_max.z());
  description.set_content_crc32c(info.content_crc32c);
  description.set_file_bytes(map.summary.file_bytes);
  if (info.geo_anchor) *description.mutable_geo_anchor() = GeoAnchorToProto(*info.geo_anchor);
  return description;
}

api::MapDescription DescribeMap(const LoadedMap& map) {
  return DescribeMap(DescribeLoadedMap(map));
}

GnssPrior GnssPriorFromProto(const api::GnssFix& fix, const std::string& what) {
  GnssPrior prior;
  prior.position = {fix.latitude_deg(), fix.longitude_deg(), fix.altitude_m()};
  prior.horizontal_accuracy_m = fix.horizontal_accuracy_m();
  prior.vertical_accuracy_m = fix.vertical_accuracy_m();
  CheckGnssPrior(prior, what);
  return prior;
}

api::PoseUpdate PoseUpdateFromEstimate(const tracking::PoseEstimate& estimate,
                                       const GeoReference* geo, odometry::PoseSource source) {
  api::PoseUpdate update;
  update.set_t_ns(estimate.t_ns);
  update.set_source(source == odometry::PoseSource::kOdometry ? api::POSE_SOURCE_ODOMETRY
                                                              : api::POSE_SOURCE_MAP);
  switch (estimate.status) {
    case tracking::TrackingStatus::kTracking:
      update.set_status(api::TRACKING);
      break;
    case tracking::TrackingStatus::kLost:
      update.set_status(api::LOST);
      break;
    case tracking::TrackingStatus::kInitializing:
      update.set_status(api::INITIALIZING);
      break;
    case tracking::TrackingStatus::kRelocalizing:
      update.set_status(api::RELOCALIZING);
      break;
  }
  // A searching step has no pose to report: no invented one goes out (docs/api.md). A LOST step
  // carries the last good pose with the no-information covariance, as before.
  const bool searching = tracking::IsSearching(estimate.status);
  if (!searching) {
    *update.mutable_world_from_cam() = RigidToProto(estimate.world_from_cam);
    for (int row = 0; row < 6; ++row) {
      for (int col = 0; col < 6; ++col) update.add_covariance(estimate.covariance(row, col));
    }
    if (geo) {
      const GeoPose pose = geo->PoseFromMap(estimate.world_from_cam);
      api::GeodeticPose* geodetic = update.mutable_geodetic();
      geodetic->set_latitude_deg(pose.position.latitude_deg);
      geodetic->set_longitude_deg(pose.position.longitude_deg);
      geodetic->set_altitude_m(pose.position.altitude_m);
      geodetic->set_heading_deg(pose.heading_deg);
      geodetic->set_pitch_deg(pose.pitch_deg);
      geodetic->set_heading_from_image_up(pose.heading_from_image_up);
      geodetic->mutable_enu()->set_x(pose.enu.x());
      geodetic->mutable_enu()->set_y(pose.enu.y());
      geodetic->mutable_enu()->set_z(pose.enu.z());
    }
  }
  auto* quality = update.mutable_quality();
  quality->set_on_edge_fraction(estimate.quality.on_edge_fraction);
  quality->set_mean_residual(estimate.quality.mean_residual);
  quality->set_points_used(static_cast<uint32_t>(estimate.quality.points_used));
  quality->set_points_selected(static_cast<uint32_t>(estimate.quality.points_selected));
  quality->set_iterations(static_cast<uint32_t>(estimate.quality.iterations));
  quality->set_recovery_attempts(static_cast<uint32_t>(estimate.quality.recovery_attempts));
  update.set_step_ms(estimate.timings.total_ms);
  return update;
}

namespace {

// Checks an image message's size against the camera's and its byte count (`field` names the
// bytes, `bytes_per_pixel` their size).
void CheckImageBytes(uint32_t width, uint32_t height, const std::string& bytes,
                     const Camera& camera, const std::string& what, const char* field,
                     size_t bytes_per_pixel) {
  if (width != static_cast<uint32_t>(camera.width) ||
      height != static_cast<uint32_t>(camera.height)) {
    throw InvalidArgumentError(what + ": size " + std::to_string(width) + "x" +
                               std::to_string(height) + " differs from the camera's " +
                               std::to_string(camera.width) + "x" + std::to_string(camera.height));
  }
  const size_t expected =
      static_cast<size_t>(camera.width) * static_cast<size_t>(camera.height) * bytes_per_pixel;
  if (bytes.size() != expected) {
    throw InvalidArgumentError(
        what + ": " + field + " holds " + std::to_string(bytes.size()) + " bytes, expected " +
        (bytes_per_pixel == 1 ? "width * height = " : "2 * width * height = ") +
        std::to_string(expected));
  }
}

}  // namespace

cv::Mat GrayFromProto(uint32_t width, uint32_t height, const std::string& pixels,
                      const Camera& camera, const std::string& what) {
  CheckImageBytes(width, height, pixels, camera, what, "gray", 1);
  cv::Mat gray(camera.height, camera.width, CV_8UC1);
  std::memcpy(gray.data, pixels.data(), pixels.size());
  return gray;
}

cv::Mat DepthFromProto(const api::DepthFrame& frame, const Camera& depth_camera,
                       std::optional<int64_t> previous_t_ns) {
  CheckImageBytes(frame.width(), frame.height(), frame.depth_mm(), depth_camera, "DepthFrame",
                  "depth_mm", 2);
  if (previous_t_ns && frame.t_ns() <= *previous_t_ns) {
    throw InvalidArgumentError("DepthFrame: time " + std::to_string(frame.t_ns()) +
                               " ns is not after the previous depth frame's " +
                               std::to_string(*previous_t_ns) + " ns");
  }
  cv::Mat depth_m(depth_camera.height, depth_camera.width, CV_32FC1);
  const auto* bytes = reinterpret_cast<const unsigned char*>(frame.depth_mm().data());
  float* out = depth_m.ptr<float>(0);  // continuous
  for (size_t i = 0; i < depth_m.total(); ++i) {
    const unsigned millimetres = bytes[2 * i] | (static_cast<unsigned>(bytes[2 * i + 1]) << 8);
    out[i] = static_cast<float>(millimetres) * 1e-3f;
  }
  return depth_m;
}

cv::Mat FrameFromProto(const api::Frame& frame, const Camera& camera,
                       std::optional<int64_t> previous_t_ns) {
  cv::Mat gray = GrayFromProto(frame.width(), frame.height(), frame.gray(), camera, "Frame");
  if (previous_t_ns && frame.t_ns() <= *previous_t_ns) {
    throw InvalidArgumentError("Frame: time " + std::to_string(frame.t_ns()) +
                               " ns is not after the previous frame's " +
                               std::to_string(*previous_t_ns) + " ns");
  }
  return gray;
}

void SessionLimits::Check() const {
  tracker.Check();
  if (max_camera_pixels < 1) throw InvalidArgumentError("--max-camera-pixels must be positive");
  if (max_packet_span_ns < 1 || max_packet_span_ns > (int64_t{1} << 60)) {
    throw InvalidArgumentError("--max-packet-span must be positive and at most 2^60 ns");
  }
  if (!(max_step_rate_hz > 0)) throw InvalidArgumentError("--max-rate must be positive");
  if (tracker.step_rate_hz > max_step_rate_hz) {
    throw InvalidArgumentError("--rate " + std::to_string(tracker.step_rate_hz) +
                               " exceeds --max-rate " + std::to_string(max_step_rate_hz));
  }
  if (max_points_limit < 1) throw InvalidArgumentError("--max-points-limit must be positive");
  if (tracker.max_points > max_points_limit) {
    throw InvalidArgumentError("--max-points " + std::to_string(tracker.max_points) +
                               " exceeds --max-points-limit " + std::to_string(max_points_limit));
  }
  if (max_steps_per_request < 1) {
    throw InvalidArgumentError("--max-steps-per-request must be positive");
  }
  if (max_packet_events < 1) throw InvalidArgumentError("--max-packet-events must be positive");
}

SessionSettings SessionSettingsFromProto(const api::SessionStart& start,
                                         const SessionLimits& limits) {
  if (!start.has_camera()) throw InvalidArgumentError("SessionStart.camera is missing");
  SessionSettings settings;
  settings.camera = CameraFromProto(start.camera(), "SessionStart.camera");
  const int64_t pixels = int64_t{settings.camera.width} * settings.camera.height;
  if (pixels > limits.max_camera_pixels) {
    throw InvalidArgumentError("SessionStart.camera: " + std::to_string(settings.camera.width) +
                               "x" + std::to_string(settings.camera.height) + " = " +
                               std::to_string(pixels) + " pixels exceeds this server's limit of " +
                               std::to_string(limits.max_camera_pixels) +
                               " (evloc-localizer --max-camera-pixels)");
  }
  if (start.has_initial_world_from_cam()) {
    settings.initial_world_from_cam =
        RigidFromProto(start.initial_world_from_cam(), "SessionStart.initial_world_from_cam");
  }
  if (start.has_initial_velocity()) {
    if (!settings.initial_world_from_cam) {
      throw InvalidArgumentError(
          "SessionStart.initial_velocity needs SessionStart.initial_world_from_cam: a session "
          "without a pose starts by relocalizing, at rest");
    }
    settings.initial_velocity =
        wire::TwistFromProto(start.initial_velocity(), "SessionStart.initial_velocity");
  }
  if (start.has_depth_camera()) {
    if (start.options().frames()) {
      throw InvalidArgumentError(
          "SessionStart.depth_camera: the hand-over to odometry needs an event session (not "
          "options.frames)");
    }
    DepthCameraSettings depth;
    depth.camera = CameraFromProto(start.depth_camera().camera(), "SessionStart.depth_camera");
    const int64_t depth_pixels = int64_t{depth.camera.width} * depth.camera.height;
    if (depth_pixels > limits.max_camera_pixels) {
      throw InvalidArgumentError("SessionStart.depth_camera: " + std::to_string(depth_pixels) +
                                 " pixels exceeds this server's limit of " +
                                 std::to_string(limits.max_camera_pixels) +
                                 " (evloc-localizer --max-camera-pixels)");
    }
    if (!start.depth_camera().has_event_from_depth()) {
      throw InvalidArgumentError(
          "SessionStart.depth_camera.event_from_depth is missing: the depth camera's pose "
          "relative to the event camera");
    }
    depth.event_from_depth = RigidFromProto(start.depth_camera().event_from_depth(),
                                            "SessionStart.depth_camera.event_from_depth");
    settings.depth_camera = depth;
  }
  CheckSessionTime(start.initial_t_ns(), "SessionStart.initial_t_ns");
  CheckSessionTime(start.sensor_time_offset_ns(), "SessionStart.sensor_time_offset_ns");
  settings.initial_t_ns = start.initial_t_ns();
  settings.sensor_time_offset_ns = start.sensor_time_offset_ns();
  settings.tracker = limits.tracker;
  const api::TrackingOptions& options = start.options();
  try {
    if (!options.variant().empty()) settings.tracker.SetVariant(options.variant());
    if (options.has_use_polarity()) settings.tracker.use_polarity = options.use_polarity();
    if (options.has_use_occlusion_culling()) {
      settings.tracker.use_occlusion_culling = options.use_occlusion_culling();
    }
    if (options.step_rate_hz() != 0) settings.tracker.step_rate_hz = options.step_rate_hz();
    if (options.max_points() != 0) {
      if (options.max_points() > static_cast<uint64_t>(limits.max_points_limit)) {
        throw InvalidArgumentError("max_points " + std::to_string(options.max_points()) +
                                   " exceeds this server's limit of " +
                                   std::to_string(limits.max_points_limit) +
                                   " (evloc-localizer --max-points-limit)");
      }
      settings.tracker.max_points = static_cast<int>(options.max_points());
    }
    if (options.decay_time_s() != 0) settings.tracker.decay_time_s = options.decay_time_s();
    if (options.has_decay_trail_px()) settings.tracker.decay_trail_px = options.decay_trail_px();
    if (options.has_motion_prior_velocity_sigma_mps()) {
      settings.tracker.motion_prior_velocity_sigma_mps = options.motion_prior_velocity_sigma_mps();
    }
    if (options.has_motion_prior_angular_velocity_sigma_dps()) {
      settings.tracker.motion_prior_angular_velocity_sigma_dps =
          options.motion_prior_angular_velocity_sigma_dps();
    }
    ApplyEventFilterOptions(options.event_filter(), &settings.tracker.event_filter);
    settings.tracker.input =
        options.frames() ? tracking::TrackerInput::kFrames : tracking::TrackerInput::kEvents;
    settings.tracker.Check();
    if (settings.tracker.step_rate_hz > limits.max_step_rate_hz) {
      throw InvalidArgumentError("step_rate_hz " + std::to_string(settings.tracker.step_rate_hz) +
                                 " exceeds this server's limit of " +
                                 std::to_string(limits.max_step_rate_hz) +
                                 " Hz (evloc-localizer --max-rate)");
    }
  } catch (const InvalidArgumentError& error) {
    throw InvalidArgumentError(std::string("SessionStart.options: ") + error.what());
  }
  return settings;
}

PacketDecoder::PacketDecoder(SensorSize sensor_size, int64_t sensor_time_offset_ns,
                             int64_t max_events)
    : sensor_size_(sensor_size),
      sensor_time_offset_ns_(sensor_time_offset_ns),
      max_events_(max_events) {
  sensor_size_.Check();
  if (max_events_ < 1) throw InvalidArgumentError("PacketDecoder: max_events must be positive");
}

void PacketDecoder::Decode(const api::EventPacket& packet, EventBuffer* out) {
  uint64_t adjustments = 0;
  out->clear();
  const uint64_t index = packets_;
  const std::string& data = packet.data();
  CheckSessionTime(packet.end_t_ns(), PacketName(index) + ": end_t_ns");
  if (end_t_ns_ && packet.end_t_ns() < *end_t_ns_) {
    throw InvalidArgumentError(
        PacketName(index) + ": end_t_ns " + std::to_string(packet.end_t_ns()) +
        " ns goes back from the previous packet's " + std::to_string(*end_t_ns_) + " ns");
  }
  if (!data.empty()) {
    if (packet.encoding() == api::EVENT_ENCODING_UNSPECIFIED ||
        !api::EventEncoding_IsValid(packet.encoding())) {
      throw InvalidArgumentError(PacketName(index) + ": the encoding is not set or unknown");
    }
    if (encoding_ != api::EVENT_ENCODING_UNSPECIFIED && packet.encoding() != encoding_) {
      throw InvalidArgumentError(PacketName(index) + ": the encoding changed within the session");
    }
    encoding_ = packet.encoding();
  }
  const auto* bytes = reinterpret_cast<const uint8_t*>(data.data());
  const auto too_many_events = [&](const std::string& count) {
    return InvalidArgumentError(PacketName(index) + ": " + count +
                                " events exceed this server's limit of " +
                                std::to_string(max_events_) +
                                " per packet (evloc-localizer --max-packet-events): send shorter "
                                "packets");
  };
  if (encoding_ == api::EVENT_ENCODING_PACKED && !data.empty()) {
    if (data.size() / wire::kPackedEventBytes > static_cast<uint64_t>(max_events_)) {
      throw too_many_events(std::to_string(data.size() / wire::kPackedEventBytes));
    }
    CheckSessionTime(packet.time_base_ns(), PacketName(index) + ": time_base_ns");
    try {
      wire::DecodePackedEvents(data, packet.time_base_ns(), out);
    } catch (const InvalidArgumentError& error) {
      throw InvalidArgumentError(PacketName(index) + ": " + error.what());
    }
  } else if (encoding_ == api::EVENT_ENCODING_EVT3 || encoding_ == api::EVENT_ENCODING_EVT2) {
    if (!raw_decoder_) {
      PropheseeDecoderOptions options;
      options.source = "the session's event stream";
      if (encoding_ == api::EVENT_ENCODING_EVT3) {
        raw_decoder_ = std::make_unique<Evt3Decoder>(options);
      } else {
        raw_decoder_ = std::make_unique<Evt2Decoder>(options);
      }
    }
    try {
      for (size_t offset = 0; offset < data.size(); offset += kRawDecodeChunkBytes) {
        raw_decoder_->Decode(bytes + offset, std::min(kRawDecodeChunkBytes, data.size() - offset),
                             out);
        if (out->size() > static_cast<size_t>(max_events_)) {
          throw too_many_events("more than " + std::to_string(out->size()));
        }
      }
    } catch (const ParseError& error) {
      throw InvalidArgumentError(PacketName(index) + ": malformed raw data: " + error.what());
    }
    for (int64_t& t_ns : out->t_ns) t_ns += sensor_time_offset_ns_;
    adjustments = OrderRawTimes(index, out);
  }
  // Order and position checks.
  const size_t count = out->size();
  for (size_t i = 0; i < count; ++i) {
    if (!sensor_size_.Contains(out->x[i], out->y[i])) {
      throw InvalidArgumentError(PacketName(index) + ": event " + std::to_string(i) + " at (" +
                                 std::to_string(out->x[i]) + ", " + std::to_string(out->y[i]) +
                                 ") lies outside the " + std::to_string(sensor_size_.width) + "x" +
                                 std::to_string(sensor_size_.height) + " sensor");
    }
    const int64_t t_ns = out->t_ns[i];
    if (t_ns > packet.end_t_ns()) {
      throw InvalidArgumentError(PacketName(index) + ": event " + std::to_string(i) + " at " +
                                 std::to_string(t_ns) + " ns lies after the packet's end_t_ns " +
                                 std::to_string(packet.end_t_ns()) + " ns");
    }
    if (i > 0 ? t_ns < out->t_ns[i - 1] : (end_t_ns_ && t_ns <= *end_t_ns_)) {
      throw InvalidArgumentError(PacketName(index) + ": event " + std::to_string(i) + " at " +
                                 std::to_string(t_ns) + " ns goes back in time");
    }
  }
  end_t_ns_ = packet.end_t_ns();
  if (count > 0) last_event_t_ns_ = out->t_ns.back();
  raw_time_adjustments_ += adjustments;
  ++packets_;
}

uint64_t PacketDecoder::OrderRawTimes(uint64_t index, EventBuffer* events) const {
  uint64_t adjustments = 0;
  std::optional<int64_t> floor_ns;
  if (end_t_ns_) floor_ns = *end_t_ns_ + 1;
  if (last_event_t_ns_ && (!floor_ns || *last_event_t_ns_ > *floor_ns)) {
    floor_ns = last_event_t_ns_;
  }
  for (size_t i = 0; i < events->size(); ++i) {
    int64_t& t_ns = events->t_ns[i];
    if (floor_ns && t_ns < *floor_ns) {
      if (*floor_ns - t_ns > kMaxRawTimeAdjustmentNs) {
        throw InvalidArgumentError(PacketName(index) + ": event " + std::to_string(i) + " at " +
                                   std::to_string(t_ns) + " ns goes back in time by " +
                                   std::to_string(*floor_ns - t_ns) +
                                   " ns (raw streams may go back by at most 1 ms)");
      }
      t_ns = *floor_ns;
      ++adjustments;
    }
    floor_ns = t_ns;
  }
  return adjustments;
}

RequestValidator::RequestValidator(const SessionSettings& settings, const SessionLimits& limits)
    : camera_(settings.camera),
      takes_frames_(settings.tracker.input == tracking::TrackerInput::kFrames),
      max_packet_span_ns_(limits.max_packet_span_ns),
      step_rate_hz_(settings.tracker.step_rate_hz),
      max_steps_per_request_(limits.max_steps_per_request),
      session_t_ns_(settings.initial_t_ns),
      decoder_(SensorSize{settings.camera.width, settings.camera.height},
               settings.sensor_time_offset_ns, limits.max_packet_events) {
  if (settings.depth_camera) depth_camera_ = settings.depth_camera->camera;
}

grpc::Status RequestValidator::Accept(const api::TrackRequest& request, SessionItem* item) {
  try {
    switch (request.message_case()) {
      case api::TrackRequest::kStart:
        return {grpc::StatusCode::FAILED_PRECONDITION,
                "a second SessionStart: open a new stream for a new session"};
      case api::TrackRequest::kEvents:
        if (takes_frames_) {
          return InvalidArgument(
              "this session tracks frames (options.frames): send Frames, not events");
        }
        item->kind = SessionItem::Kind::kEvents;
        CheckSpan(request.events().end_t_ns(),
                  ("event packet " + std::to_string(decoder_.packets()) + ": end_t_ns").c_str());
        CheckSteps(request.events().end_t_ns());
        decoder_.Decode(request.events(), &item->events);
        item->t_ns = request.events().end_t_ns();
        session_t_ns_ = std::max(session_t_ns_, item->t_ns);
        break;
      case api::TrackRequest::kFrame:
        if (!takes_frames_) {
          return InvalidArgument(
              "this session tracks events: set options.frames in SessionStart to send Frames");
        }
        CheckSessionTime(request.frame().t_ns(), "Frame: t_ns");
        item->kind = SessionItem::Kind::kFrame;
        item->gray = FrameFromProto(request.frame(), camera_, last_frame_t_ns_);
        item->t_ns = request.frame().t_ns();
        last_frame_t_ns_ = item->t_ns;
        break;
      case api::TrackRequest::kPoseHint: {
        const int64_t t_ns = request.pose_hint().t_ns();
        CheckSessionTime(t_ns, "PoseHint: t_ns");
        CheckSpan(t_ns, "PoseHint: t_ns");
        const std::optional<int64_t> last = decoder_.end_t_ns();
        if (last && t_ns < *last) {
          return InvalidArgument("PoseHint at " + std::to_string(t_ns) +
                                 " ns lies before the end of the last packet (" +
                                 std::to_string(*last) + " ns)");
        }
        item->kind = SessionItem::Kind::kPoseHint;
        item->world_from_cam =
            RigidFromProto(request.pose_hint().world_from_cam(), "PoseHint.world_from_cam");
        item->t_ns = t_ns;
        session_t_ns_ = std::max(session_t_ns_, t_ns);
        break;
      }
      case api::TrackRequest::kGnssFix: {
        const api::GnssFix& fix = request.gnss_fix();
        CheckSpan(fix.t_ns(), "GnssFix: t_ns");
        const std::optional<int64_t> last = decoder_.end_t_ns();
        if (last && fix.t_ns() < *last) {
          return InvalidArgument("GnssFix at " + std::to_string(fix.t_ns()) +
                                 " ns lies before the end of the last packet (" +
                                 std::to_string(*last) + " ns)");
        }
        item->kind = SessionItem::Kind::kGnssFix;
        item->gnss = GnssPriorFromProto(fix, "GnssFix");
        item->t_ns = fix.t_ns();
        session_t_ns_ = std::max(session_t_ns_, item->t_ns);
        break;
      }
      case api::TrackRequest::kDepth: {
        if (!depth_camera_) {
          return InvalidArgument(
              "a DepthFrame needs SessionStart.depth_camera (the depth camera and its pose "
              "relative to the event camera)");
        }
        const int64_t t_ns = request.depth().t_ns();
        CheckSessionTime(t_ns, "DepthFrame: t_ns");
        const int64_t events_until = decoder_.end_t_ns().value_or(session_t_ns_);
        if (t_ns > events_until) {
          return InvalidArgument("DepthFrame at " + std::to_string(t_ns) +
                                 " ns lies after the end of the last packet (" +
                                 std::to_string(events_until) +
                                 " ns): send the events up to its time first");
        }
        item->kind = SessionItem::Kind::kDepth;
        item->depth_m = DepthFromProto(request.depth(), *depth_camera_, last_depth_t_ns_);
        item->t_ns = t_ns;
        last_depth_t_ns_ = t_ns;
        break;
      }
      default:
        return InvalidArgument(
            "an empty TrackRequest (set start, events, frame, pose_hint, gnss_fix or depth)");
    }
  } catch (const InvalidArgumentError& error) {
    return InvalidArgument(error.what());
  }
  latest_t_ns_ = item->t_ns;
  return grpc::Status::OK;
}

void RequestValidator::CheckSpan(int64_t t_ns, const char* what) const {
  // |session time| <= 2^62 ns and the span <= 2^60 ns: the sum cannot overflow.
  CheckSessionTime(t_ns, what);
  if (t_ns > session_t_ns_ + max_packet_span_ns_) {
    throw InvalidArgumentError(
        std::string(what) + " " + std::to_string(t_ns) + " ns lies " +
        std::to_string((static_cast<double>(t_ns) - static_cast<double>(session_t_ns_)) * 1e-9) +
        " s after the session time " + std::to_string(session_t_ns_) +
        " ns (initial time, previous packet end or pose hint); one request may advance the "
        "session by at most " +
        std::to_string(static_cast<double>(max_packet_span_ns_) * 1e-9) +
        " s (evloc-localizer --max-packet-span): send shorter packets, or check that "
        "initial_t_ns and the event times use the same clock");
  }
}

void RequestValidator::CheckSteps(int64_t end_t_ns) const {
  // Steps this packet completes: the session time only moves forward, and CheckSpan bounds the
  // difference (no overflow).
  if (end_t_ns <= session_t_ns_) return;
  const double steps = static_cast<double>(end_t_ns - session_t_ns_) * 1e-9 * step_rate_hz_;
  if (steps > static_cast<double>(max_steps_per_request_)) {
    throw InvalidArgumentError(
        "event packet " + std::to_string(decoder_.packets()) + ": end_t_ns " +
        std::to_string(end_t_ns) + " ns would complete " +
        std::to_string(static_cast<int64_t>(steps)) + " steps at " + std::to_string(step_rate_hz_) +
        " Hz; one request may complete at most " + std::to_string(max_steps_per_request_) +
        " (evloc-localizer --max-steps-per-request): send shorter packets");
  }
}

namespace {

// The source a session tracks against: its map with its visibility index, or a site's tiles:
// those around the initial pose, loaded now; without one, none until a GnssFix says where to
// search (docs/api.md, "Sites").
std::unique_ptr<tracking::MapSource> SessionMapSource(const LoadedMap& map,
                                                      const SessionSettings& settings) {
  if (!map.site) return std::make_unique<tracking::StaticMapSource>(map.map, map.visibility.get());
  auto tiled = std::make_unique<tracking::TiledMapSource>(map.site, map.tiles);
  if (settings.initial_world_from_cam) tiled->LoadNow(*settings.initial_world_from_cam);
  return tiled;
}

}  // namespace

SessionTracker::SessionTracker(std::shared_ptr<const LoadedMap> map,
                               const SessionSettings& settings)
    : map_(std::move(map)),
      settings_(settings),
      source_(SessionMapSource(*map_, settings)),
      tiled_(dynamic_cast<tracking::TiledMapSource*>(source_.get())),
      tracker_(*source_, settings.camera, settings.tracker),
      geo_(map_->map.geo_anchor ? std::optional<GeoReference>(std::in_place, *map_->map.geo_anchor)
                                : std::nullopt),
      takes_frames_(settings.tracker.input == tracking::TrackerInput::kFrames),
      advanced_t_ns_(settings.initial_t_ns) {
  if (!takes_frames_ && !tiled_ && map_->map.relocalization && map_->visibility) {
    image_hypotheses_.emplace(map_->map, *map_->visibility, settings.camera);
    tracker_.SetImageHypothesisSource(&*image_hypotheses_);
  }
  if (takes_frames_) StartTracker();
  if (settings.depth_camera) {
    handover_ = std::make_unique<odometry::MapOdometryHandover>(
        tracker_, *source_, settings.camera, settings.depth_camera->camera,
        settings.depth_camera->event_from_depth, odometry::HandoverOptions());
  }
}

void SessionTracker::Append(std::vector<odometry::HandoverEstimate> reported,
                            std::vector<tracking::PoseEstimate>* estimates) {
  for (odometry::HandoverEstimate& estimate : reported) {
    estimates->push_back(std::move(estimate.estimate));
    sources_.push_back(estimate.source);
  }
}

void SessionTracker::FeedEvents(const EventBuffer& events,
                                std::vector<tracking::PoseEstimate>* estimates) {
  if (handover_) {
    Append(handover_->AddEvents(events), estimates);
    return;
  }
  for (tracking::PoseEstimate& estimate : tracker_.AddEvents(events)) {
    estimates->push_back(std::move(estimate));
    sources_.push_back(odometry::PoseSource::kMap);
  }
}

void SessionTracker::Advance(int64_t t_ns, std::vector<tracking::PoseEstimate>* estimates) {
  if (handover_) {
    Append(handover_->AdvanceTo(t_ns), estimates);
    return;
  }
  for (tracking::PoseEstimate& estimate : tracker_.AdvanceTo(t_ns)) {
    estimates->push_back(std::move(estimate));
    sources_.push_back(odometry::PoseSource::kMap);
  }
}

void SessionTracker::StartTracker() {
  if (!settings_.initial_world_from_cam) {
    if (takes_frames_) {
      throw InvalidArgumentError(
          "SessionStart.initial_world_from_cam is missing: a frame session needs an initial pose "
          "(find one with the Locate RPC); event sessions may start without one");
    }
    tracker_.StartWithoutPose(settings_.initial_t_ns);
    started_ = true;
    return;
  }
  if (settings_.initial_velocity) {
    tracker_.Reset(*settings_.initial_world_from_cam, settings_.initial_t_ns,
                   *settings_.initial_velocity);
  } else {
    tracker_.Reset(*settings_.initial_world_from_cam, settings_.initial_t_ns);
  }
  started_ = true;
}

std::vector<tracking::PoseEstimate> SessionTracker::Process(
    const SessionItem& item, const StopFunction& stop, std::vector<odometry::PoseSource>* sources) {
  sources_.clear();
  std::vector<tracking::PoseEstimate> estimates = ProcessItem(item, stop);
  // Frame sessions report map poses only.
  sources_.resize(estimates.size(), odometry::PoseSource::kMap);
  if (sources != nullptr) *sources = std::move(sources_);
  return estimates;
}

std::vector<tracking::PoseEstimate> SessionTracker::ProcessItem(const SessionItem& item,
                                                                const StopFunction& stop) {
  if (stopped_) return {};
  if (gnss_prior_t_ns_ && item.t_ns - *gnss_prior_t_ns_ > kGnssPriorLifetimeNs) {
    tracker_.ClearSearchPrior();  // the fix is too old to narrow a search
    if (tiled_ != nullptr) tiled_->ClearSearchRegion();
    gnss_prior_t_ns_.reset();
  }
  switch (item.kind) {
    case SessionItem::Kind::kEvents:
      return AddEvents(item.events, item.t_ns, stop);
    case SessionItem::Kind::kFrame: {
      std::vector<tracking::PoseEstimate> estimates;
      if (stop && stop()) {
        stopped_ = true;
        return estimates;
      }
      advanced_t_ns_ = std::max(advanced_t_ns_, item.t_ns);
      if (item.t_ns <= settings_.initial_t_ns) return estimates;
      if (tiled_ != nullptr) tiled_->Follow(tracker_);
      if (auto estimate = tracker_.AddFrame(item.t_ns, item.gray)) {
        estimates.push_back(std::move(*estimate));
      }
      return estimates;
    }
    case SessionItem::Kind::kPoseHint:
      tracker_.Reset(item.world_from_cam, item.t_ns);
      started_ = true;
      advanced_t_ns_ = std::max(advanced_t_ns_, item.t_ns);
      return {};
    case SessionItem::Kind::kDepth:
      if (!handover_) throw InvalidArgumentError("DepthFrame in a session without a depth camera");
      handover_->AddDepthFrame(item.t_ns, item.depth_m);
      return {};
    case SessionItem::Kind::kGnssFix: {
      if (!geo_) throw InvalidArgumentError("GnssFix for a map without a geo anchor");
      const Eigen::Vector3d center = geo_->MapFromGeodetic(item.gnss.position);
      const double radius_m = GnssSearchRadiusM(item.gnss, geo_->anchor());
      tracker_.SetSearchPrior(center, radius_m);
      // On a site, a searching session's tiles are those near the fix (loaded in the background).
      if (tiled_ != nullptr) tiled_->SetSearchRegion(center, radius_m);
      gnss_prior_t_ns_ = item.t_ns;
      return {};
    }
  }
  return {};
}

std::vector<tracking::PoseEstimate> SessionTracker::AddEvents(const EventBuffer& events,
                                                              int64_t end_t_ns,
                                                              const StopFunction& stop) {
  std::vector<tracking::PoseEstimate> estimates;
  const EventBuffer* tracked = &events;
  if (!started_) {
    // As TrackEventStream: events up to the initial time prime the surfaces before the Reset,
    // which happens once an event after the initial time arrives or a packet end reaches it.
    size_t split = 0;
    while (split < events.size() && events.t_ns[split] <= settings_.initial_t_ns) ++split;
    const EventBuffer* priming = &events;
    if (split < events.size()) {
      head_.clear();
      tail_.clear();
      head_.Append(events.t_ns.data(), events.x.data(), events.y.data(), events.polarity.data(),
                   split);
      tail_.Append(events.t_ns.data() + split, events.x.data() + split, events.y.data() + split,
                   events.polarity.data() + split, events.size() - split);
      priming = &head_;
      tracked = &tail_;
    } else {
      tracked = nullptr;
    }
    if (!priming->empty()) FeedEvents(*priming, &estimates);
    if (!tracked && end_t_ns < settings_.initial_t_ns) {
      Advance(end_t_ns, &estimates);
      return estimates;
    }
    StartTracker();
  }
  static const EventBuffer kNoEvents;
  TrackInPeriods(tracked ? *tracked : kNoEvents, end_t_ns, stop, &estimates);
  return estimates;
}

void SessionTracker::TrackInPeriods(const EventBuffer& events, int64_t end_t_ns,
                                    const StopFunction& stop,
                                    std::vector<tracking::PoseEstimate>* estimates) {
  // One step period per slice (at least 1 ns): each slice completes at most about one step.
  const auto period_ns = static_cast<int64_t>(std::max(1.0, 1e9 / settings_.tracker.step_rate_hz));
  const size_t count = events.size();
  size_t next = 0;
  int64_t bound = advanced_t_ns_;
  while (true) {
    if (stop && stop()) {
      stopped_ = true;
      return;
    }
    // A site's tiles follow the pose between periods (never loading here: the cache's loader
    // threads load and compose, the next period after that sees the new tiles).
    if (tiled_ != nullptr) tiled_->Follow(tracker_);
    // |times| <= 2^62 and period_ns <= 1e9: no overflow.
    const int64_t slice_end = end_t_ns - bound <= period_ns ? end_t_ns : bound + period_ns;
    size_t stop_index = next;
    while (stop_index < count && events.t_ns[stop_index] <= slice_end) ++stop_index;
    if (stop_index > next) {
      const EventBuffer* slice = &events;
      if (next > 0 || stop_index < count) {
        slice_.clear();
        slice_.Append(events.t_ns.data() + next, events.x.data() + next, events.y.data() + next,
                      events.polarity.data() + next, stop_index - next);
        slice = &slice_;
      }
      FeedEvents(*slice, estimates);
      next = stop_index;
    }
    Advance(slice_end, estimates);
    bound = std::max(bound, slice_end);
    advanced_t_ns_ = bound;
    if (slice_end >= end_t_ns) return;
  }
}

void FoldEventPackets(SessionItem* earlier, const SessionItem& later) {
  const EventBuffer& first = earlier->events;
  const EventBuffer& second = later.events;
  // Every other event of the two in a row: the second packet continues the first's parity.
  EventBuffer both;
  both.AppendEvery(first, 0, first.size(), 2);
  both.AppendEvery(second, first.size() % 2, second.size(), 2);
  earlier->events = std::move(both);
  earlier->t_ns = later.t_ns;
}

void AppendThinnedEvents(SessionItem* earlier, const SessionItem& later, size_t stride) {
  earlier->events.AppendEvery(later.events, 0, later.events.size(), stride);
  earlier->t_ns = later.t_ns;
}

grpc::Status OpenSession(const api::SessionStart& start, MapRegistry& registry,
                         const SessionLimits& limits, OpenedSession* session) {
  try {
    // The request is checked before its map is loaded: a bad request costs no map load.
    session->settings = SessionSettingsFromProto(start, limits);
    session->map = registry.Get(start.map_name(), start.map_version());
    session->tracker = std::make_unique<SessionTracker>(session->map, session->settings);
  } catch (const MapNotFoundError& error) {
    return {grpc::StatusCode::NOT_FOUND, error.what()};
  } catch (const InvalidArgumentError& error) {
    return InvalidArgument(error.what());
  } catch (const Error& error) {
    return {grpc::StatusCode::FAILED_PRECONDITION,
            "map '" + start.map_name() + "' cannot be loaded: " + error.what()};
  }
  return grpc::Status::OK;
}

cv::Mat SessionTracker::SurfacePicture(const Rigid3d& world_from_cam, int64_t t_ns) const {
  if (!started_ || source_ == nullptr) return cv::Mat();
  return tracking::SurfaceWithReprojectedMap(tracker_, *source_, world_from_cam, t_ns);
}

}  // namespace evloc::service
