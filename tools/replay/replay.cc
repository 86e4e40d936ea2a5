#include "tools/replay/replay.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <future>
#include <limits>
#include <mutex>
#include <random>
#include <sstream>
#include <thread>

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "core/common/cli.h"
#include "core/common/cli_app.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/dataset/dataset.h"
#include "core/dataset/pose_text.h"
#include "core/events/event_reader.h"
#include "core/events/evt3_encoder.h"
#include "core/geo/geo_trajectory.h"
#include "core/geo/geodetic.h"
#include "core/trajectory/tum_io.h"
#include "evloc/localizer.grpc.pb.h"
#include "localizer/wire/packed_events.h"
#include "localizer/wire/percentile.h"
#include "localizer/wire/twist.h"
#include "proto/convert/proto_convert.h"
#include "tools/replay/reconnect.h"

namespace evloc::replay {
namespace {

using Clock = std::chrono::steady_clock;

using wire::Percentile;
using wire::TwistToProto;

// Floor division for possibly negative numerators.
int64_t FloorDiv(int64_t numerator, int64_t denominator) {
  int64_t quotient = numerator / denominator;
  if ((numerator % denominator != 0) && ((numerator < 0) != (denominator < 0))) --quotient;
  return quotient;
}

double MillisecondsOf(Clock::duration duration) {
  return std::chrono::duration<double, std::milli>(duration).count();
}

std::string StatusText(const grpc::Status& status) {
  return std::to_string(status.error_code()) + " " + status.error_message();
}

// Throws unless the deadline of a health check is positive.
void CheckHealthTimeout(double timeout_s) {
  if (!(timeout_s > 0)) throw InvalidArgumentError("--health-timeout must be positive");
}

// The checks of the fields a health check uses too.
void CheckServerOptions(const ReplayOptions& options) {
  if (options.server.empty()) {
    throw InvalidArgumentError("--server is required: the localizer's host:port");
  }
  if (options.tls_server_name && !options.tls_ca_file) {
    throw InvalidArgumentError("--tls-server-name needs --tls-ca");
  }
  if (options.token && options.token_file) {
    throw InvalidArgumentError("--token and --token-file exclude each other");
  }
  if (options.tls_cert_file.has_value() != options.tls_key_file.has_value()) {
    throw InvalidArgumentError("--tls-cert and --tls-key go together (the client certificate)");
  }
  if (options.tls_cert_file && !options.tls_ca_file) {
    throw InvalidArgumentError("--tls-cert needs --tls-ca (a client certificate is sent over TLS)");
  }
  if (!options.lb_policy.empty() && options.lb_policy != "pick_first" &&
      options.lb_policy != "round_robin") {
    throw InvalidArgumentError("--lb expects pick_first or round_robin, got '" + options.lb_policy +
                               "'");
  }
}

// A channel to options.server with its credentials, load-balancing policy and, for a client
// that reconnects, the reconnect backoff.
std::shared_ptr<grpc::Channel> MakeChannel(const ReplayOptions& options) {
  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(64 << 20);
  if (!options.lb_policy.empty()) arguments.SetLoadBalancingPolicyName(options.lb_policy);
  // Not GRPC_ARG_MIN_RECONNECT_BACKOFF_MS: gRPC also takes it as the shortest connect timeout,
  // and a short one fails connections on a busy host.
  if (options.reconnect > 0) {
    const int backoff_ms = static_cast<int>(options.reconnect_backoff_ms);
    arguments.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, backoff_ms);
    arguments.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS,
                     static_cast<int>(options.reconnect_backoff_max_ms));
  }
  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
  if (options.tls_ca_file) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = ReadFileToString(*options.tls_ca_file);
    if (options.tls_cert_file) {
      ssl.pem_cert_chain = ReadFileToString(*options.tls_cert_file);
      ssl.pem_private_key = ReadFileToString(*options.tls_key_file);
    }
    credentials = grpc::SslCredentials(ssl);
    if (options.tls_server_name) arguments.SetSslTargetNameOverride(*options.tls_server_name);
  }
  return grpc::CreateCustomChannel(options.server, credentials, arguments);
}

// A status a new session may get past: the server went away or restarts, the connection broke,
// the stream ended without a status (UNKNOWN: an HTTP/2 proxy cut it when its backend died; the
// evloc server never sends UNKNOWN itself), or the replica is overloaded (RESOURCE_EXHAUSTED:
// full at admission, or the session's queue overflowed): another replica, or the same one once
// it caught up, may take the new session, which catches up paced by the poses.
bool IsTransient(const grpc::Status& status) {
  switch (status.error_code()) {
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::CANCELLED:
    case grpc::StatusCode::ABORTED:
    case grpc::StatusCode::UNKNOWN:
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return true;
    default:
      return false;
  }
}

// The reconnect backoff's options of a replay.
ReconnectOptions ReconnectOptionsOf(const ReplayOptions& options) {
  ReconnectOptions reconnect;
  reconnect.max_attempts = options.reconnect;
  reconnect.base_ms = options.reconnect_backoff_ms;
  reconnect.cap_ms = options.reconnect_backoff_max_ms;
  reconnect.max_total_s = options.reconnect_max_s;
  reconnect.stable_s = options.reconnect_stable_s;
  reconnect.seed = options.reconnect_seed;
  return reconnect;
}

// The value of trailing-metadata `key` of a finished call, empty when absent.
std::string TrailingValue(const grpc::ClientContext& context, const std::string& key) {
  const auto& trailers = context.GetServerTrailingMetadata();
  const auto found = trailers.find(key);
  return found == trailers.end() ? std::string()
                                 : std::string(found->second.data(), found->second.size());
}

// How a Track call went, beyond its status.
struct SessionOutcome {
  // The server admitted the session (SessionStarted).
  bool started = false;
  // The client sent everything and half-closed; false when the server ended the stream first.
  bool complete = false;
  // The retry delay the server asked for in the call's trailers (ServerRetryDelay).
  std::optional<Clock::duration> server_delay;
};

// Reads events from a file one at a time, in batches underneath.
class EventSource {
 public:
  explicit EventSource(EventReader& reader) : reader_(reader) { Refill(); }
  bool has_event() const { return index_ < batch_.size(); }
  Event event() const { return batch_[index_]; }
  void Advance() {
    if (++index_ >= batch_.size()) Refill();
  }

 private:
  void Refill() {
    batch_.clear();
    index_ = 0;
    reader_.Read(1 << 16, &batch_);
  }
  EventReader& reader_;
  EventBuffer batch_;
  size_t index_ = 0;
};

// Most events in one merged priming packet of a resumed session (1 MiB in PACKED).
constexpr size_t kMaxPrimingPacketEvents = 131072;

// The events of the session-time window (start_ns, end_ns]: one packet.
struct Window {
  int64_t start_ns = 0;
  int64_t end_ns = 0;
  // Event times on the session clock (EVT 3.0: rounded up to whole microseconds).
  EventBuffer events;
};

// A packet as sent: the end of its time window and when it was sent. The server runs the step
// at time t once it has the packet whose window end reaches t (docs/api.md), so that packet is
// the one a pose's client latency is measured from.
struct SentPacket {
  int64_t end_t_ns = 0;
  Clock::time_point sent;
};

// The geodetic pose of an update that carries one.
TimedGeoPose GeoPoseFromProto(const api::PoseUpdate& update) {
  const api::GeodeticPose& geodetic = update.geodetic();
  TimedGeoPose timed;
  timed.t_ns = update.t_ns();
  timed.pose.position = {geodetic.latitude_deg(), geodetic.longitude_deg(), geodetic.altitude_m()};
  timed.pose.heading_deg = geodetic.heading_deg();
  timed.pose.pitch_deg = geodetic.pitch_deg();
  timed.pose.heading_from_image_up = geodetic.heading_from_image_up();
  timed.pose.enu = {geodetic.enu().x(), geodetic.enu().y(), geodetic.enu().z()};
  return timed;
}

// State shared between the sending loop and the response reader: the figures of every session,
// and the flow control of the current one.
struct SharedState {
  std::mutex mutex;
  std::condition_variable pose_arrived;
  std::vector<TimedPose> poses;
  // The poses' geodetic forms (PoseUpdate.geodetic), and the map's anchor (SessionStarted).
  std::vector<TimedGeoPose> geo_poses;
  std::optional<GeoAnchor> geo_anchor;
  std::vector<bool> tracking;
  std::vector<double> client_latency_us;
  std::vector<double> server_latency_us;
  std::vector<double> server_overhead_us;
  std::vector<double> step_ms;
  int64_t lost = 0;
  int64_t backpressure = 0;
  // Updates without a pose (the server searching), the session time of the newest update, and
  // that of the first TRACKING pose.
  int64_t searching = 0;
  // Whether the newest update had no pose (the server searching); at the start, whether the
  // session started without one.
  bool searching_now = false;
  int64_t last_update_t_ns = 0;
  std::optional<int64_t> first_tracking_t_ns;
  // The last pose received (the initial pose before the first), and when it arrived.
  TimedPose last_pose;
  Clock::time_point last_pose_wall;
  // Current session: packets sent and not yet passed by a pose (for the client latency).
  std::deque<SentPacket> sent;
  // Current session: window ends of the packets sent whose tracking no pose has confirmed yet.
  std::deque<int64_t> unconfirmed_window_ends;
  // Current session: poses received, and when the first one arrived.
  int64_t session_poses = 0;
  Clock::time_point first_session_pose_wall;
  bool ended = false;
  api::SessionEnd end;
};

// One replay: the dataset, the windows that a new session may need again, and the sessions.
class Replayer {
 public:
  Replayer(const ReplayOptions& options, std::ostream& log)
      : options_(options), log_(log), backoff_(ReconnectOptionsOf(options)) {
    DatasetReaderOptions reader_options;
    reader_options.ecd_width = options.ecd_width;
    reader_options.ecd_height = options.ecd_height;
    reader_options.bag_topics = options.bag_topics;
    reader_options.aedat4 = options.aedat4;
    dataset_ = ReadDataset(options.dataset, reader_options);
    for (const std::string& note : dataset_.calibration_notes) {
      log_ << "evloc-replay: note: " << note << "\n";
    }
    reader_ = OpenDatasetEvents(dataset_);
    source_ = std::make_unique<EventSource>(*reader_);
    if (!source_->has_event()) {
      throw InvalidArgumentError("dataset '" + options.dataset.string() + "' has no events");
    }
    evt3_ = options.encoding == WireEncoding::kEvt3;
    const int64_t first_t_ns = source_->event().t_ns;
    // Without a pose the session starts at the first event, which only primes the surfaces.
    initial_ = options.start_without_pose
                   ? TimedPose{SessionTime(first_t_ns), Rigid3d()}
                   : ResolveInitialPose(dataset_, options.initial_world_from_cam, first_t_ns);
    if (options.initial_velocity_from_truth) {
      initial_velocity_ = dataset_.ground_truth ? dataset_.ground_truth->Velocity(
                                                      initial_.t_ns, wire::kClientVelocityWindowNs)
                                                : std::nullopt;
      if (!initial_velocity_) {
        throw InvalidArgumentError("--initial-velocity truth: dataset '" +
                                   options.dataset.string() +
                                   "' has no ground truth around its start");
      }
    }
    next_window_start_ns_ = SessionTime(first_t_ns) - 1;
    dataset_start_ns_ = next_window_start_ns_;
    packet_ns_ = options.packet_us * 1000;
    prime_ns_ = static_cast<int64_t>(std::llround(options.resume_prime_ms * 1e6));
    stop_ns_ = options.duration_s
                   ? initial_.t_ns + static_cast<int64_t>(std::llround(*options.duration_s * 1e9))
                   : std::numeric_limits<int64_t>::max();
    channel_ = MakeChannel(options);
    stub_ = api::Localizer::NewStub(channel_);
    shared_.last_pose = initial_;
  }

  ReplayResult Run();

 private:
  // Session time of a dataset event time: EVT 3.0 carries whole microseconds.
  int64_t SessionTime(int64_t t_ns) const {
    return evt3_ ? FloorDiv(t_ns + 999, 1000) * 1000 : t_ns;
  }
  // Reads the next window of the dataset into history_; false at the end of the events or of
  // --duration.
  bool ProduceWindow();
  // Drops the sent windows that no new session can need again, shifting `next`.
  void Prune(size_t* next);
  // Runs one Track call from `start`: resends the windows of history_ from `start` minus the
  // priming time (all of them before the first pose), then the rest of the dataset; `outcome`:
  // whether the server admitted it, whether the client got to its end, the server's retry delay.
  grpc::Status RunSession(const TimedPose& start, bool resumed, SessionOutcome* outcome);
  // Completes the pending outage once the new session delivered a pose (or ended).
  void FinishOutage(Clock::time_point resumed_wall);

  const ReplayOptions& options_;
  std::ostream& log_;
  Dataset dataset_;
  std::unique_ptr<EventReader> reader_;
  std::unique_ptr<EventSource> source_;
  bool evt3_ = false;
  TimedPose initial_;
  // The first session's velocity (--initial-velocity truth); nullopt: at rest.
  std::optional<Vector6d> initial_velocity_;
  int64_t next_window_start_ns_ = 0;
  // Start of the first window: real-time pacing counts from it.
  int64_t dataset_start_ns_ = 0;
  int64_t packet_ns_ = 0;
  int64_t prime_ns_ = 0;
  int64_t stop_ns_ = 0;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<api::Localizer::Stub> stub_;
  // Windows read from the dataset and not yet pruned, in time order.
  std::deque<Window> history_;
  SharedState shared_;
  ReplayResult result_;
  Clock::time_point wall_start_;
  // Origin of the real-time schedule (--speed S): when the first session had started, so that
  // connecting and the server's session set-up do not count as lateness (a burst of packets
  // "due" during the set-up would start the session behind, with a full queue).
  std::optional<Clock::time_point> schedule_start_;
  // Track calls opened so far.
  int sessions_ = 0;
  // The stream failure being recovered from, with the wall times of the failure and of the
  // last pose before it.
  std::optional<Outage> outage_;
  Clock::time_point failure_wall_;
  Clock::time_point last_pose_wall_before_failure_;
  // When to reconnect, and when to give up.
  ReconnectBackoff backoff_;
};

bool Replayer::ProduceWindow() {
  if (!source_->has_event() || next_window_start_ns_ >= stop_ns_) return false;
  Window window;
  window.start_ns = next_window_start_ns_;
  window.end_ns = window.start_ns + packet_ns_;
  while (source_->has_event() && SessionTime(source_->event().t_ns) <= window.end_ns) {
    Event event = source_->event();
    event.t_ns = SessionTime(event.t_ns);
    window.events.push_back(event);
    source_->Advance();
  }
  next_window_start_ns_ = window.end_ns;
  history_.push_back(std::move(window));
  return true;
}

void Replayer::Prune(size_t* next) {
  int64_t keep_after_ns = 0;
  {
    std::lock_guard<std::mutex> lock(shared_.mutex);
    if (!shared_.poses.empty()) {
      keep_after_ns = shared_.last_pose.t_ns - prime_ns_;
    } else if (options_.start_without_pose) {
      // A new session searches again from the newest events: keep only what primes it.
      keep_after_ns = shared_.last_update_t_ns - prime_ns_;
    } else {
      // Before the first pose a new session starts from the initial pose again.
      return;
    }
  }
  while (*next > 0 && history_.front().end_ns <= keep_after_ns) {
    history_.pop_front();
    --*next;
  }
}

void Replayer::FinishOutage(Clock::time_point resumed_wall) {
  if (!outage_) return;
  outage_->resume_ms = MillisecondsOf(resumed_wall - failure_wall_);
  outage_->interruption_ms = MillisecondsOf(resumed_wall - last_pose_wall_before_failure_);
  log_ << "evloc-replay: resumed after " << outage_->resume_ms << " ms (" << outage_->attempts
       << (outage_->attempts == 1 ? " attempt" : " attempts") << ", " << outage_->interruption_ms
       << " ms without poses)" << std::endl;
  result_.outages.push_back(*outage_);
  outage_.reset();
}

grpc::Status Replayer::RunSession(const TimedPose& start, bool resumed, SessionOutcome* outcome) {
  *outcome = SessionOutcome();
  // A later session sends what it must send again as fast as the poses confirm it.
  const bool catching_up = ++sessions_ > 1;
  // The first window of this session.
  size_t next = 0;
  if (resumed) {
    while (next < history_.size() && history_[next].end_ns <= start.t_ns - prime_ns_) ++next;
  }
  const int64_t first_start_ns =
      next < history_.size() ? history_[next].start_ns : next_window_start_ns_;
  // EVT 3.0 carries microseconds from a sensor origin: sensor time = session time - offset.
  const int64_t sensor_offset_ns = FloorDiv(first_start_ns, 1000) * 1000;

  grpc::ClientContext context;
  if (options_.token) context.AddMetadata("authorization", "Bearer " + *options_.token);
  auto stream = stub_->Track(&context);
  // Finishes the call and reads the retry delay the server may have sent with its status.
  const auto finish = [&] {
    grpc::Status status = stream->Finish();
    if (!status.ok()) {
      std::string details = status.error_details();
      if (details.empty()) details = TrailingValue(context, "grpc-status-details-bin");
      outcome->server_delay =
          ServerRetryDelay(TrailingValue(context, "grpc-retry-pushback-ms"), details);
    }
    return status;
  };

  api::TrackRequest start_request;
  api::SessionStart* session_start = start_request.mutable_start();
  session_start->set_map_name(options_.map_name);
  *session_start->mutable_camera() = CameraToProto(dataset_.camera);
  // Until a first pose arrives, a session --init-pose none starts without one again.
  if (!options_.start_without_pose || resumed) {
    *session_start->mutable_initial_world_from_cam() = RigidToProto(start.world_from_cam);
  }
  if (!resumed && initial_velocity_) {
    *session_start->mutable_initial_velocity() = TwistToProto(*initial_velocity_);
  }
  if (resumed && options_.resume_velocity_ms > 0) {
    std::optional<Vector6d> velocity;
    {
      std::lock_guard<std::mutex> lock(shared_.mutex);
      velocity = ResumeVelocity(shared_.poses, shared_.tracking,
                                std::llround(options_.resume_velocity_ms * 1e6));
    }
    if (velocity) *session_start->mutable_initial_velocity() = TwistToProto(*velocity);
  }
  session_start->set_initial_t_ns(start.t_ns);
  if (options_.step_rate_hz) {
    session_start->mutable_options()->set_step_rate_hz(*options_.step_rate_hz);
  }
  if (options_.motion_prior) {
    session_start->mutable_options()->set_motion_prior_velocity_sigma_mps(
        options_.motion_prior->first);
    session_start->mutable_options()->set_motion_prior_angular_velocity_sigma_dps(
        options_.motion_prior->second);
  }
  session_start->set_sensor_time_offset_ns(sensor_offset_ns);
  session_start->set_client_name("evloc-replay " + options_.dataset.filename().string());

  api::TrackResponse response;
  if (!stream->Write(start_request) || !stream->Read(&response) || !response.has_started()) {
    return finish();
  }
  outcome->started = true;
  if (response.started().map().has_geo_anchor()) {
    std::lock_guard<std::mutex> lock(shared_.mutex);
    shared_.geo_anchor =
        GeoAnchorFromProto(response.started().map().geo_anchor(), "SessionStarted.map.geo_anchor");
  }
  // The simulated GNSS receiver (--gnss-sigma): a fix at the session's start, then one every
  // --gnss-period of session time before the packet that reaches it (docs/geo.md, "GNSS prior").
  std::optional<GeoReference> gnss_reference;
  int64_t next_fix_t_ns = start.t_ns;
  std::mt19937 gnss_noise(options_.gnss_seed);
  const auto send_fix = [&](int64_t t_ns) {
    const std::optional<Rigid3d> truth =
        dataset_.ground_truth ? dataset_.ground_truth->Lookup(t_ns) : std::nullopt;
    if (!truth) {
      throw InvalidArgumentError("--gnss-sigma: the dataset has no ground truth at t = " +
                                 std::to_string(static_cast<double>(t_ns) * 1e-9) + " s");
    }
    std::normal_distribution<double> normal(0.0, *options_.gnss_sigma_m);
    Eigen::Vector3d position = truth->translation;
    for (int axis = 0; axis < 3; ++axis) position[axis] += normal(gnss_noise);
    const GeodeticPoint fix = gnss_reference->GeodeticFromMap(position);
    api::TrackRequest gnss;
    gnss.mutable_gnss_fix()->set_latitude_deg(fix.latitude_deg);
    gnss.mutable_gnss_fix()->set_longitude_deg(fix.longitude_deg);
    gnss.mutable_gnss_fix()->set_altitude_m(fix.altitude_m);
    gnss.mutable_gnss_fix()->set_horizontal_accuracy_m(*options_.gnss_sigma_m);
    gnss.mutable_gnss_fix()->set_vertical_accuracy_m(*options_.gnss_sigma_m);
    gnss.mutable_gnss_fix()->set_t_ns(t_ns);
    ++result_.gnss_fixes_sent;
    next_fix_t_ns = t_ns + std::llround(options_.gnss_period_s * 1e9);
    return stream->Write(gnss);
  };
  if (options_.gnss_sigma_m) {
    if (!response.started().map().has_geo_anchor()) {
      throw InvalidArgumentError("--gnss-sigma: " +
                                 MissingGeoAnchorMessage(response.started().map().name()));
    }
    gnss_reference.emplace(GeoAnchorFromProto(response.started().map().geo_anchor(), "geo_anchor"));
    if (!send_fix(start.t_ns)) return finish();
  }
  backoff_.SessionStarted(Clock::now());
  if (!schedule_start_) schedule_start_ = Clock::now();
  log_ << "evloc-replay: session " << response.started().session_id() << " on map "
       << response.started().map().name() << " version " << response.started().map().version()
       << ", " << response.started().variant() << " at " << response.started().step_rate_hz()
       << " Hz, " << (evt3_ ? "EVT 3.0" : "PACKED") << " packets of " << options_.packet_us
       << " us, speed " << (options_.speed ? std::to_string(*options_.speed) : std::string("max"));
  if (resumed) {
    log_ << ", resuming at t = " << static_cast<double>(start.t_ns) * 1e-9 << " s";
  }
  log_ << std::endl;

  {
    std::lock_guard<std::mutex> lock(shared_.mutex);
    shared_.sent.clear();
    shared_.unconfirmed_window_ends.clear();
    shared_.ended = false;
    shared_.searching_now = !session_start->has_initial_world_from_cam();
  }
  const uint64_t searching_event_rate =
      options_.thin_while_searching ? response.started().searching_event_rate() : 0;
  std::thread response_reader([&] {
    api::TrackResponse message;
    while (stream->Read(&message)) {
      const auto now = Clock::now();
      std::lock_guard<std::mutex> lock(shared_.mutex);
      if (message.has_pose()) {
        const api::PoseUpdate& pose = message.pose();
        while (!shared_.sent.empty() && shared_.sent.front().end_t_ns < pose.t_ns()) {
          shared_.sent.pop_front();
        }
        if (!shared_.sent.empty()) {
          shared_.client_latency_us.push_back(
              std::chrono::duration<double, std::micro>(now - shared_.sent.front().sent).count());
        }
        shared_.server_latency_us.push_back(pose.latency_us());
        shared_.server_overhead_us.push_back(pose.latency_us() - pose.step_ms() * 1e3);
        shared_.step_ms.push_back(pose.step_ms());
        shared_.last_update_t_ns = pose.t_ns();
        shared_.searching_now = !pose.has_world_from_cam();
        if (!pose.has_world_from_cam()) {
          // INITIALIZING / RELOCALIZING: the server is searching and has no pose to give.
          ++shared_.searching;
        } else {
          const TimedPose timed{pose.t_ns(), RigidFromProto(pose.world_from_cam(), "PoseUpdate")};
          shared_.poses.push_back(timed);
          if (pose.has_geodetic()) shared_.geo_poses.push_back(GeoPoseFromProto(pose));
          shared_.tracking.push_back(pose.status() == api::TRACKING);
          if (pose.status() == api::LOST) ++shared_.lost;
          if (pose.status() == api::TRACKING && !shared_.first_tracking_t_ns) {
            shared_.first_tracking_t_ns = pose.t_ns();
          }
          shared_.last_pose = timed;
          shared_.last_pose_wall = now;
          if (shared_.session_poses++ == 0) shared_.first_session_pose_wall = now;
        }
        // The step at t ran after every event up to t was ingested.
        while (!shared_.unconfirmed_window_ends.empty() &&
               shared_.unconfirmed_window_ends.front() <= pose.t_ns()) {
          shared_.unconfirmed_window_ends.pop_front();
        }
        shared_.pose_arrived.notify_all();
      } else if (message.has_backpressure()) {
        ++shared_.backpressure;
      } else if (message.has_end()) {
        shared_.end = message.end();
      }
    }
    std::lock_guard<std::mutex> lock(shared_.mutex);
    shared_.ended = true;
    shared_.pose_arrived.notify_all();
  });

  // Packets in flight when pacing by the poses: at most half the server's queue and
  // max_lead_ms of session time.
  const size_t max_in_flight = static_cast<size_t>(std::max<int64_t>(
      1, std::min<int64_t>(response.started().queue_capacity() / 2,
                           static_cast<int64_t>(options_.max_lead_ms * 1e3) / options_.packet_us)));
  const auto wait_for_poses = [&] {
    std::unique_lock<std::mutex> lock(shared_.mutex);
    // A pose confirms packets; without one for 20 ms (e.g. while the first events only prime
    // the time surfaces) one more packet goes out.
    shared_.pose_arrived.wait_for(lock, std::chrono::milliseconds(20), [&] {
      return shared_.ended || shared_.unconfirmed_window_ends.size() < max_in_flight;
    });
  };
  Evt3Encoder encoder;
  EventBuffer sensor_events;
  bool stream_open = true;
  EventBuffer merged;
  EventBuffer thinned;
  while (stream_open) {
    const bool resend = next < history_.size();
    if (!resend && !ProduceWindow()) break;
    // One window per packet; on a resumed session the windows up to the resume pose, which
    // only prime the time surfaces, go out merged into few packets.
    size_t last = next;
    const EventBuffer* events = &history_[next].events;
    if (resumed && history_[next].end_ns <= start.t_ns) {
      size_t count = events->size();
      while (last + 1 < history_.size() && history_[last + 1].end_ns <= start.t_ns &&
             count + history_[last + 1].events.size() <= kMaxPrimingPacketEvents) {
        count += history_[++last].events.size();
      }
      if (last > next) {
        merged.clear();
        for (size_t i = next; i <= last; ++i) merged.Append(history_[i].events);
        events = &merged;
      }
    }
    const int64_t packet_start_ns = history_[next].start_ns;
    const int64_t packet_end_ns = history_[last].end_ns;
    // While the server searches, only what its search needs (SessionStarted.searching_event_rate).
    bool searching_now = false;
    if (searching_event_rate > 0) {
      std::lock_guard<std::mutex> lock(shared_.mutex);
      searching_now = shared_.searching_now;
    }
    const size_t stride = searching_now ? wire::ThinEvents(*events, 0, events->size(),
                                                           packet_end_ns - packet_start_ns,
                                                           searching_event_rate, &thinned)
                                        : 1;
    if (stride > 1) {
      result_.events_thinned += static_cast<int64_t>(events->size() - thinned.size());
      events = &thinned;
    }
    api::TrackRequest request;
    api::EventPacket* packet = request.mutable_events();
    packet->set_end_t_ns(packet_end_ns);
    if (evt3_) {
      packet->set_encoding(api::EVENT_ENCODING_EVT3);
      sensor_events = *events;
      for (int64_t& t_ns : sensor_events.t_ns) t_ns -= sensor_offset_ns;
      encoder.Encode(sensor_events, packet->mutable_data());
    } else {
      packet->set_encoding(api::EVENT_ENCODING_PACKED);
      packet->set_time_base_ns(packet_start_ns);
      packet->set_data(wire::EncodePackedEvents(*events, 0, events->size(), packet_start_ns));
    }
    // Pacing: real time from the replay's start, or by the poses. A later session that is
    // behind the real-time schedule catches up paced by the poses, so that it does not
    // overflow the new server's queue.
    if (options_.speed) {
      const auto due =
          *schedule_start_ +
          std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(
              static_cast<double>(packet_end_ns - dataset_start_ns_) * 1e-9 / *options_.speed));
      if (catching_up && due < Clock::now()) {
        wait_for_poses();
      } else {
        std::this_thread::sleep_until(due);
      }
    } else {
      wait_for_poses();
    }
    {
      std::lock_guard<std::mutex> lock(shared_.mutex);
      shared_.sent.push_back({packet_end_ns, Clock::now()});
      shared_.unconfirmed_window_ends.push_back(packet_end_ns);
    }
    if (gnss_reference && packet_start_ns >= next_fix_t_ns && !send_fix(packet_start_ns)) break;
    stream_open = stream->Write(request);
    if (resend) {
      ++result_.packets_resent;
    } else {
      result_.events_sent += static_cast<int64_t>(events->size());
      ++result_.packets_sent;
    }
    next = last + 1;
    Prune(&next);
    if (outage_) {
      std::optional<Clock::time_point> resumed_wall;
      {
        std::lock_guard<std::mutex> lock(shared_.mutex);
        if (shared_.session_poses > 0) resumed_wall = shared_.first_session_pose_wall;
      }
      if (resumed_wall) FinishOutage(*resumed_wall);
    }
  }
  outcome->complete = stream_open;
  stream->WritesDone();
  response_reader.join();
  return finish();
}

ReplayResult Replayer::Run() {
  wall_start_ = Clock::now();
  // Attempt number of the next Track call in the current outage (0: not reconnecting).
  int attempt = 0;
  Clock::duration last_delay{};
  for (;;) {
    TimedPose start;
    bool resumed = false;
    {
      std::lock_guard<std::mutex> lock(shared_.mutex);
      start = shared_.last_pose;
      resumed = !shared_.poses.empty();
      shared_.session_poses = 0;
    }
    SessionOutcome outcome;
    grpc::Status status;
    // A reconnect attempt waits for a connection (its delay, at least --reconnect-backoff-ms:
    // a full-jitter delay may be near zero), so that it does not fail at once while the channel
    // is still moving to another address.
    const Clock::duration connect_wait = std::max(
        last_delay, std::chrono::duration_cast<Clock::duration>(
                        std::chrono::duration<double, std::milli>(options_.reconnect_backoff_ms)));
    if (attempt > 0 &&
        !channel_->WaitForConnected(
            std::chrono::system_clock::now() +
            std::chrono::duration_cast<std::chrono::system_clock::duration>(connect_wait))) {
      status = grpc::Status(grpc::StatusCode::UNAVAILABLE,
                            "no connection to '" + options_.server + "' within " +
                                std::to_string(MillisecondsOf(connect_wait)) + " ms");
    } else {
      status = RunSession(start, resumed, &outcome);
    }
    // A server that ends the stream before the client's end without an error (a draining
    // replica sends its SessionEnd and OK) has not finished the replay: resume elsewhere.
    if (status.ok() && outcome.started && !outcome.complete) {
      status = grpc::Status(grpc::StatusCode::UNAVAILABLE,
                            "the server ended the session before the end of the stream");
    }
    int64_t session_poses = 0;
    Clock::time_point first_pose_wall;
    {
      std::lock_guard<std::mutex> lock(shared_.mutex);
      session_poses = shared_.session_poses;
      first_pose_wall = shared_.first_session_pose_wall;
    }
    if (outage_ && (session_poses > 0 || status.ok())) {
      FinishOutage(session_poses > 0 ? first_pose_wall : Clock::now());
    }
    if (status.ok()) break;
    const std::string sent = std::to_string(result_.packets_sent) + " packets";
    if (options_.reconnect == 0 || !IsTransient(status)) {
      if (!outcome.started) {
        throw Error("the server refused the session (status code, message): " + StatusText(status));
      }
      throw Error("the session failed after " + sent + ": " + StatusText(status));
    }
    if (!outage_) {
      std::lock_guard<std::mutex> lock(shared_.mutex);
      outage_ =
          Outage{static_cast<int>(status.error_code()), status.error_message(),
                 std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
                     .count(),
                 shared_.last_pose.t_ns};
      failure_wall_ = Clock::now();
      last_pose_wall_before_failure_ =
          shared_.poses.empty() ? failure_wall_ : shared_.last_pose_wall;
    }
    // RESOURCE_EXHAUSTED: the replica is full or this session overflowed its queue: slow down.
    const FailureKind kind = status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED
                                 ? FailureKind::kOverloaded
                                 : FailureKind::kTransient;
    const ReconnectDecision decision = backoff_.OnFailure(Clock::now(), kind, outcome.server_delay);
    if (!decision.retry) {
      throw Error(decision.reason + "; the last one ended with " + StatusText(status) +
                  " (the stream first failed after " + sent + " with " +
                  std::to_string(outage_->status_code) + " " + outage_->status_message + ")");
    }
    attempt = decision.attempt;
    last_delay = decision.delay;
    outage_->attempts = attempt;
    int64_t resume_t_ns = 0;
    {
      std::lock_guard<std::mutex> lock(shared_.mutex);
      resume_t_ns = shared_.last_pose.t_ns;
    }
    log_ << "evloc-replay: stream " << (outcome.started ? "failed" : "refused") << " ("
         << StatusText(status) << "); reconnect " << attempt << "/" << options_.reconnect << " in "
         << MillisecondsOf(last_delay) << " ms"
         << (outcome.server_delay
                 ? " (the server asked for " +
                       std::to_string(MillisecondsOf(*outcome.server_delay)) + " ms)"
                 : std::string())
         << " from the pose at t = " << static_cast<double>(resume_t_ns) * 1e-9 << " s"
         << std::endl;
    std::this_thread::sleep_for(last_delay);
  }

  ReplayResult& result = result_;
  result.wall_s = std::chrono::duration<double>(Clock::now() - wall_start_).count();
  std::lock_guard<std::mutex> lock(shared_.mutex);
  result.trajectory = Trajectory(shared_.poses);
  result.tracking = shared_.tracking;
  result.lost_poses = shared_.lost;
  result.searching_updates = shared_.searching;
  result.packets_shed = static_cast<int64_t>(shared_.end.packets_shed());
  if (shared_.first_tracking_t_ns) {
    result.first_tracking_s =
        static_cast<double>(*shared_.first_tracking_t_ns - initial_.t_ns) * 1e-9;
  }
  result.backpressure_notices = shared_.backpressure;
  result.client_latency_p50_us = Percentile(shared_.client_latency_us, 0.5);
  result.client_latency_p99_us = Percentile(shared_.client_latency_us, 0.99);
  result.server_latency_p50_us = Percentile(shared_.server_latency_us, 0.5);
  result.server_latency_p99_us = Percentile(shared_.server_latency_us, 0.99);
  result.server_overhead_p50_us = Percentile(shared_.server_overhead_us, 0.5);
  result.server_overhead_p99_us = Percentile(shared_.server_overhead_us, 0.99);
  result.step_p50_ms = Percentile(shared_.step_ms, 0.5);
  WriteTumTrajectory(options_.output, result.trajectory);
  if (options_.geo_output) {
    if (!shared_.geo_anchor) {
      throw InvalidArgumentError(MissingGeoAnchorMessage(options_.map_name) +
                                 " (the TUM trajectory " + options_.output.string() +
                                 " was written)");
    }
    WriteGeoTrajectory(*options_.geo_output, *shared_.geo_anchor, shared_.geo_poses);
  }
  if (options_.report) WriteReplayReport(*options_.report, result);
  log_ << "evloc-replay: sent " << result.events_sent << " events in " << result.packets_sent
       << " packets, received " << result.trajectory.size() << " poses (" << result.lost_poses
       << " LOST), " << result.backpressure_notices << " backpressure notices, in " << result.wall_s
       << " s\n";
  if (options_.start_without_pose) {
    log_ << "evloc-replay: started without a pose: " << result.searching_updates
         << " updates while the server searched; ";
    if (result.first_tracking_s) {
      log_ << "first TRACKING pose " << *result.first_tracking_s << " s after the first event\n";
    } else {
      log_ << "no TRACKING pose\n";
    }
  }
  if (!result.outages.empty()) {
    std::vector<double> resume_ms;
    for (const Outage& outage : result.outages) resume_ms.push_back(outage.resume_ms);
    log_ << "evloc-replay: " << result.outages.size() << " stream failures recovered, "
         << result.packets_resent << " packets sent again; resume p50 "
         << Percentile(resume_ms, 0.5) << " ms, max "
         << *std::max_element(resume_ms.begin(), resume_ms.end()) << " ms\n";
  }
  log_ << "evloc-replay: latency client p50 " << result.client_latency_p50_us << " us p99 "
       << result.client_latency_p99_us << " us; server p50 " << result.server_latency_p50_us
       << " us p99 " << result.server_latency_p99_us << " us (of which outside the step: p50 "
       << result.server_overhead_p50_us << " us p99 " << result.server_overhead_p99_us
       << " us); median step " << result.step_p50_ms << " ms\n"
       << "evloc-replay: server totals" << (result.outages.empty() ? "" : " (last session)") << ": "
       << shared_.end.events() << " events, " << shared_.end.poses()
       << " poses; trajectory written to " << options_.output.string() << "\n";
  if (result.packets_shed > 0) {
    log_ << "evloc-replay: the server shed " << result.packets_shed
         << " event packets (thinned into another or dropped; " << shared_.end.events_shed()
         << " events left out) while it searched and the session was behind its stream\n";
  }
  if (result_.events_thinned > 0) {
    log_ << "evloc-replay: " << result_.events_thinned
         << " events left out while the server searched (at most its "
            "SessionStarted.searching_event_rate; --thin-while-searching off sends them all)\n";
  }
  return result;
}

}  // namespace

void ReplayOptions::Check() const {
  CheckServerOptions(*this);
  if (map_name.empty()) throw InvalidArgumentError("--map is required: a map name (ListMaps)");
  if (start_without_pose && initial_world_from_cam) {
    throw InvalidArgumentError("--init-pose none and a pose exclude each other");
  }
  if (start_without_pose && initial_velocity_from_truth) {
    throw InvalidArgumentError("--initial-velocity needs a pose: not with --init-pose none");
  }
  if (dataset.empty()) throw InvalidArgumentError("--dataset is required: a dataset folder");
  if (output.empty()) throw InvalidArgumentError("--out is required: the TUM trajectory to write");
  if (speed && !(*speed > 0)) throw InvalidArgumentError("--speed must be positive or 'max'");
  if (packet_us < 1 || packet_us > 1'000'000) {
    throw InvalidArgumentError("--packet-us must be in 1..1000000");
  }
  if (!(max_lead_ms > 0)) throw InvalidArgumentError("--max-lead-ms must be positive");
  if (duration_s && !(*duration_s > 0)) throw InvalidArgumentError("--duration must be positive");
  if (step_rate_hz && !(*step_rate_hz > 0)) throw InvalidArgumentError("--rate must be positive");
  if (ecd_width <= 0 || ecd_height <= 0) {
    throw InvalidArgumentError("--ecd-size must be WIDTHxHEIGHT with positive sizes");
  }
  ReconnectOptionsOf(*this).Check();
  // A merged priming packet spans at most this (PACKED offsets are below 2^31 ns).
  if (!(resume_prime_ms >= 0 && resume_prime_ms <= 1000)) {
    throw InvalidArgumentError("--resume-prime-ms must be in 0..1000");
  }
  if (!(resume_velocity_ms >= 0 && resume_velocity_ms <= 1000)) {
    throw InvalidArgumentError("--resume-velocity-ms must be in 0..1000");
  }
}

ReplayResult RunReplay(const ReplayOptions& options, std::ostream& log) {
  options.Check();
  ReplayOptions resolved = options;
  if (options.token_file) resolved.token = ReadTokenFile(*options.token_file);
  Replayer replayer(resolved, log);
  return replayer.Run();
}

std::string ReadTokenFile(const std::filesystem::path& path) {
  std::string text;
  try {
    text = ReadFileToString(path);
  } catch (const IoError&) {
    throw IoError("cannot read the token file '" + path.string() + "' (--token-file)");
  }
  std::istringstream lines(text);
  std::string line;
  std::string token;
  int64_t line_number = 0;
  while (std::getline(lines, line)) {
    ++line_number;
    const size_t begin = line.find_first_not_of(" \t\r");
    if (begin == std::string::npos) continue;
    const size_t end = line.find_last_not_of(" \t\r");
    if (!token.empty()) {
      throw ParseError::AtLine(path.string(), line_number,
                               "a token file holds one token on one line");
    }
    token = line.substr(begin, end - begin + 1);
    if (token.find_first_of(" \t") != std::string::npos) {
      throw ParseError::AtLine(path.string(), line_number, "the token has white space inside");
    }
  }
  if (token.empty()) throw ParseError(path.string(), "line 1", "the token file is empty");
  return token;
}

void WriteReplayReport(const std::filesystem::path& path, const ReplayResult& result) {
  nlohmann::json outages = nlohmann::json::array();
  for (const Outage& outage : result.outages) {
    outages.push_back({{"status_code", outage.status_code},
                       {"status_message", outage.status_message},
                       {"failed_at_unix_s", outage.failed_at_unix_s},
                       {"resume_t_ns", outage.resume_t_ns},
                       {"attempts", outage.attempts},
                       {"resume_ms", outage.resume_ms},
                       {"interruption_ms", outage.interruption_ms}});
  }
  const nlohmann::json report = {
      {"events_sent", result.events_sent},
      {"packets_sent", result.packets_sent},
      {"packets_resent", result.packets_resent},
      {"gnss_fixes_sent", result.gnss_fixes_sent},
      {"poses", result.trajectory.size()},
      {"lost_poses", result.lost_poses},
      {"searching_updates", result.searching_updates},
      {"packets_shed", result.packets_shed},
      {"events_thinned", result.events_thinned},
      {"first_tracking_s", result.first_tracking_s ? nlohmann::json(*result.first_tracking_s)
                                                   : nlohmann::json(nullptr)},
      {"backpressure_notices", result.backpressure_notices},
      {"outages", outages},
      {"client_latency_p50_us", result.client_latency_p50_us},
      {"client_latency_p99_us", result.client_latency_p99_us},
      {"server_latency_p50_us", result.server_latency_p50_us},
      {"server_latency_p99_us", result.server_latency_p99_us},
      {"step_p50_ms", result.step_p50_ms},
      {"wall_s", result.wall_s}};
  WriteFileAtomically(path, report.dump(2) + "\n");
}

std::string CheckHealth(const ReplayOptions& options, double timeout_s,
                        const std::string& service) {
  CheckServerOptions(options);
  CheckHealthTimeout(timeout_s);
  grpc::GenericStub generic(MakeChannel(options));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::duration_cast<std::chrono::system_clock::duration>(
                           std::chrono::duration<double>(timeout_s)));
  // HealthCheckRequest{string service = 1}: the tag 0x0a, the length as a varint, the name.
  std::string request_bytes;
  if (!service.empty()) {
    request_bytes.push_back('\x0a');
    for (size_t length = service.size();; length >>= 7) {
      request_bytes.push_back(static_cast<char>((length & 0x7f) | (length > 0x7f ? 0x80 : 0)));
      if (length <= 0x7f) break;
    }
    request_bytes += service;
  }
  const grpc::Slice request_slice(request_bytes);
  const grpc::ByteBuffer request(&request_slice, 1);
  grpc::ByteBuffer response;
  std::promise<grpc::Status> done;
  generic.UnaryCall(&context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request,
                    &response, [&done](grpc::Status status) { done.set_value(status); });
  const grpc::Status status = done.get_future().get();
  if (!status.ok()) {
    throw Error("health check of '" + options.server + "' failed: " + StatusText(status));
  }
  std::vector<grpc::Slice> slices;
  std::string bytes;
  if (response.Dump(&slices).ok()) {
    for (const auto& slice : slices) {
      bytes.append(reinterpret_cast<const char*>(slice.begin()), slice.size());
    }
  }
  // HealthCheckResponse{ServingStatus status = 1}: absent means UNKNOWN (0); the values fit
  // one varint byte.
  int value = 0;
  if (bytes.size() == 2 && bytes[0] == '\x08') {
    value = static_cast<unsigned char>(bytes[1]);
  } else if (!bytes.empty()) {
    throw Error("health check of '" + options.server + "': unexpected response of " +
                std::to_string(bytes.size()) + " bytes");
  }
  static const char* const kNames[] = {"UNKNOWN", "SERVING", "NOT_SERVING", "SERVICE_UNKNOWN"};
  if (value > 3) {
    throw Error("health check of '" + options.server + "': unknown status " +
                std::to_string(value));
  }
  return kNames[value];
}

namespace {

// The command line of evloc-replay over `command`.
std::unique_ptr<CommandLine> DeclareReplayCommandLine(ReplayCommand* command) {
  ReplayOptions* options = &command->options;
  auto line = std::make_unique<CommandLine>(
      "evloc-replay",
      "--server HOST:PORT --map NAME --dataset DIR --out TRAJ.txt [options]\n"
      "--health-check --server HOST:PORT [--tls-ca PEM [--tls-cert PEM --tls-key PEM]] "
      "[--health-timeout S] [--health-service NAME]",
      "Streams a dataset's events to an evloc localizer (docs/api.md) as a live camera would, "
      "writes the poses it gets back as a TUM trajectory, and prints events sent, poses received "
      "and the packet-to-pose latency (p50, p99). With --reconnect N, a stream that fails because "
      "its server went away, drains or is overloaded (UNAVAILABLE, CANCELLED, ABORTED, "
      "RESOURCE_EXHAUSTED, or UNKNOWN: ended without a status, as a proxy does when its backend "
      "dies) is started again as a new session at the last pose received, and the trajectory "
      "continues (docs/deploy.md). Attempt k of an outage waits a random time in [0, min(max, "
      "backoff * 2^(k-1))] (full jitter; at least half of it after RESOURCE_EXHAUSTED, and at "
      "least the server's grpc-retry-pushback-ms or RetryInfo delay); the outage ends only when a "
      "new session stayed up --reconnect-stable-s.");
  line->Add("--server", "TARGET",
            "localizer address: HOST:PORT, or a gRPC target such as ipv4:HOST:PORT,HOST:PORT or "
            "dns:///NAME:PORT (required)",
            &options->server)
      .Add("--map", "NAME", "map name on the server (required)", &options->map_name)
      .Add("--dataset", "DIR|FILE",
           "dataset folder, evloc or Event Camera Dataset layout, a ROS1 bag (.bag) or an AEDAT4 "
           "file (.aedat4) (required)",
           &options->dataset)
      .Add("--out", "PATH", "output TUM trajectory (required)", &options->output)
      .Add("--speed", "S|max",
           "playback speed relative to real time (default 1), or max: as fast as the server "
           "keeps up",
           [options](const std::string& flag, const std::string& value) {
             options->speed = ParseDoubleOrWordFlag(flag, value, "max");
           })
      .Add("--encoding", "packed|evt3",
           "wire encoding (default packed; evt3 rounds times up to microseconds)",
           [options](const std::string&, const std::string& value) {
             if (value == "packed") {
               options->encoding = WireEncoding::kPacked;
             } else if (value == "evt3") {
               options->encoding = WireEncoding::kEvt3;
             } else {
               throw InvalidArgumentError("--encoding expects packed or evt3, got '" + value + "'");
             }
           })
      .Add("--packet-us", "N", "time window per packet, microseconds (default 1000)",
           &options->packet_us)
      .Add("--init-pose", "\"tx ty tz qx qy qz qw\"|none",
           "initial world_from_cam (default: first ground-truth pose); none: start without a "
           "pose, the server finds the camera in the map (updates INITIALIZING until then; "
           "docs/relocalization.md)",
           [options](const std::string& flag, const std::string& value) {
             if (value == "none") {
               options->start_without_pose = true;
             } else {
               options->initial_world_from_cam = ParsePoseText(flag, value);
             }
           })
      .Add("--initial-velocity", "rest|truth",
           "how the session starts: at rest (default), or moving with the ground truth's "
           "velocity at its start (SessionStart.initial_velocity), as a vehicle client that knows "
           "its speed can",
           [options](const std::string& flag, const std::string& value) {
             options->initial_velocity_from_truth = ParseTwoWordFlag(flag, value, "rest", "truth");
           })
      .Add("--rate", "HZ", "tracking steps per second (default: the server's)",
           &options->step_rate_hz)
      .Add("--motion-prior", "V,W",
           "ask the server for the motion prior of a vehicle, the velocity trusted to V m/s and "
           "W deg/s (default: the server's; docs/tracking.md, \"Motion prior\")",
           [options](const std::string& flag, const std::string& value) {
             options->motion_prior = ParseDoublePairFlag(flag, value);
           })
      .Add("--gnss-sigma", "M",
           "simulate a GNSS receiver: send fixes at the true position moved by Gaussian noise of "
           "M metres on each axis, with accuracy M, from the start and every --gnss-period "
           "(needs ground truth and a map with a geo anchor; docs/geo.md)",
           [options](const std::string& flag, const std::string& value) {
             const double sigma = ParseDoubleFlag(flag, value);
             if (!(sigma > 0) || !std::isfinite(sigma)) {
               throw InvalidArgumentError(flag + " must be a positive distance in metres");
             }
             options->gnss_sigma_m = sigma;
           })
      .Add("--gnss-period", "S",
           "with --gnss-sigma: seconds of session time between fixes (default 1: a 1 Hz receiver)",
           [options](const std::string& flag, const std::string& value) {
             const double period = ParseDoubleFlag(flag, value);
             if (!(period > 0) || !std::isfinite(period)) {
               throw InvalidArgumentError(flag + " must be a positive number of seconds");
             }
             options->gnss_period_s = period;
           })
      .Add("--gnss-seed", "N", "seed of the simulated GNSS noise (default 1)",
           [options](const std::string& flag, const std::string& value) {
             const int64_t seed = ParseIntegerFlag(flag, value);
             if (seed < 0 || seed > 0xffffffffLL) {
               throw InvalidArgumentError(flag + " must be in [0, 4294967295]");
             }
             options->gnss_seed = static_cast<uint32_t>(seed);
           })
      .Add("--thin-while-searching", "on|off",
           "while the server searches the map, send at most the events per second it announced "
           "(SessionStarted.searching_event_rate; default on)",
           [options](const std::string& flag, const std::string& value) {
             options->thin_while_searching = ParseSwitchFlag(flag, value);
           })
      .Add("--max-lead-ms", "MS",
           "with --speed max: session time sent ahead of the last pose (default 50)",
           &options->max_lead_ms)
      .Add("--duration", "S", "stop after S seconds of session time after the initial pose",
           &options->duration_s)
      .Add("--ecd-size", "WxH", "sensor size for ECD folders with calib.txt only (default 240x180)",
           [options](const std::string& flag, const std::string& value) {
             ParseSizeFlag(flag, value, &options->ecd_width, &options->ecd_height);
           })
      .AddFlagsOfUsage(kRecordingFlagsUsage,
                       [options](const std::string& flag, const std::string& value) {
                         return ApplyRecordingFlag(flag, value, &options->bag_topics,
                                                   &options->aedat4);
                       })
      .Add("--report", "FILE", "write the figures as JSON (events, poses, outages, latency)",
           &options->report)
      .Add("--geo", "FILE",
           "also write the poses in WGS84 as the server sends them (time, latitude, longitude, "
           "altitude, heading, pitch, ENU; docs/geo.md); the map needs a geo anchor",
           &options->geo_output)
      .Group("Security")
      .Add("--token-file", "FILE",
           "file holding the bearer token (sent as 'authorization: Bearer T')",
           &options->token_file)
      .Add("--token", "T",
           "the bearer token itself: visible to every user in the process list; deprecated, use "
           "--token-file",
           &options->token)
      .Add("--tls-ca", "PEM", "use TLS, trusting these root certificates (default plaintext)",
           &options->tls_ca_file)
      .Add("--tls-cert", "PEM",
           "client certificate chain, for a server that requires one (mutual TLS; with "
           "--tls-key and --tls-ca)",
           &options->tls_cert_file)
      .Add("--tls-key", "PEM", "private key of --tls-cert", &options->tls_key_file)
      .Add("--tls-server-name", "NAME",
           "host name in the server's certificate, when not --server's host",
           &options->tls_server_name)
      .Group("Reconnecting")
      .Add("--reconnect", "N", "reconnect attempts of one outage (default 0: fail at once)",
           &options->reconnect)
      .Add("--reconnect-backoff-ms", "MS",
           "delay ceiling of the first attempt, doubled per attempt (default 100)",
           &options->reconnect_backoff_ms)
      .Add("--reconnect-backoff-max-ms", "MS", "largest delay ceiling (default 2000)",
           &options->reconnect_backoff_max_ms)
      .Add("--reconnect-max-s", "S",
           "no attempt starts later than S after the outage began (default 60)",
           &options->reconnect_max_s)
      .Add("--reconnect-stable-s", "S",
           "a session that stays up S seconds ends the outage and resets the backoff; one that "
           "fails sooner continues it (default 10)",
           &options->reconnect_stable_s)
      .Add("--reconnect-seed", "N", "seed of the jitter (default random)", &options->reconnect_seed)
      .Add("--resume-prime-ms", "MS",
           "events before the resume pose sent again to prime the new session (default 100)",
           &options->resume_prime_ms)
      .Add("--resume-velocity-ms", "MS",
           "a resumed session starts with the velocity of the last TRACKING poses within MS "
           "(default 100; 0: at rest)",
           &options->resume_velocity_ms)
      .Add("--lb", "pick_first|round_robin",
           "gRPC load balancing over the addresses of --server (default pick_first)",
           &options->lb_policy)
      .Group("Health check")
      .Switch("--health-check", "only ask the server's grpc.health.v1 service; exit 0 when SERVING",
              &command->health_check)
      .Add("--health-timeout", "S", "deadline of --health-check (default 5)",
           &command->health_timeout_s)
      .Add("--health-service", "NAME",
           "the service --health-check asks for: \"\" (default) the server's overall health "
           "(liveness), evloc.api.Localizer whether it admits new sessions (readiness: "
           "NOT_SERVING while full or draining)",
           &command->health_service)
      .Footer(
          "Exit codes: 0 success (or SERVING), 1 failure (a session the server ended with an "
          "error, a failure past --reconnect attempts, or not SERVING), 2 bad command line.");
  return line;
}

}  // namespace

std::string ReplayUsage() { return HelpOfDeclaredCommandLine(&DeclareReplayCommandLine); }

ReplayCommand ParseReplayCommandLine(const std::vector<std::string>& arguments) {
  ReplayCommand command = ParseDeclaredCommandLine(&DeclareReplayCommandLine, arguments);
  if (command.help) return command;
  if (command.health_check) {
    CheckServerOptions(command.options);
    CheckHealthTimeout(command.health_timeout_s);
  } else {
    command.options.Check();
  }
  return command;
}

}  // namespace evloc::replay
