#include "localizer/service/localizer_server.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>
#include <variant>
#include <vector>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "evloc/localizer.grpc.pb.h"
#include "localizer/service/bounded_queue.h"
#include "localizer/service/locate_rpc.h"
#include "localizer/service/metrics_http.h"
#include "localizer/service/session.h"
#include "localizer/wire/percentile.h"
#include "localizer/wire/status_name.h"

namespace evloc::service {
namespace {

using Clock = std::chrono::steady_clock;
using wire::Percentile;
using TrackServerStream = grpc::ServerReaderWriter<api::TrackResponse, api::TrackRequest>;

double MicrosecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::micro>(Clock::now() - start).count();
}

std::string Trim(const std::string& text) {
  const size_t begin = text.find_first_not_of(" \t\r");
  if (begin == std::string::npos) return "";
  const size_t end = text.find_last_not_of(" \t\r");
  return text.substr(begin, end - begin + 1);
}

// An item from the stream reader to the tracking worker.
struct InboundItem {
  // The validated request.
  SessionItem item;
  // When the reader received the message.
  Clock::time_point received;
};

}  // namespace

// ---------------------------------------------------------------------------------------------
// Options and tokens.

void LocalizerServerOptions::Check() const {
  MapRegistryOptions{maps_dir, max_map_memory_bytes}.Check();
  if (listen_address.empty()) throw InvalidArgumentError("--listen: the address is empty");
  if (max_sessions < 1) throw InvalidArgumentError("--max-sessions must be at least 1");
  if (threads != 0 && threads < max_sessions + 2) {
    throw InvalidArgumentError("--threads must be 0 (automatic) or at least --max-sessions + 2 (" +
                               std::to_string(max_sessions + 2) +
                               "): every running session holds one gRPC thread");
  }
  if (max_message_bytes < 1024) {
    throw InvalidArgumentError("--max-message-bytes must be at least 1024");
  }
  if (!(idle_timeout_s > 0)) throw InvalidArgumentError("--idle-timeout must be positive");
  if (queue_packets < 2) throw InvalidArgumentError("--queue-packets must be at least 2");
  if (!(backpressure_fraction > 0 && backpressure_fraction <= 1)) {
    throw InvalidArgumentError("--backpressure-fraction must be in (0, 1]");
  }
  if (tls_cert_file.has_value() != tls_key_file.has_value()) {
    throw InvalidArgumentError("--tls-cert and --tls-key go together");
  }
  session_limits().Check();
}

SessionLimits LocalizerServerOptions::session_limits() const {
  SessionLimits limits;
  limits.tracker = tracker;
  limits.max_camera_pixels = max_camera_pixels;
  limits.max_packet_span_ns = std::isfinite(max_packet_span_s) && max_packet_span_s > 0
                                  ? std::llround(std::min(max_packet_span_s, 1e9) * 1e9)
                                  : 0;
  limits.max_step_rate_hz = max_step_rate_hz;
  return limits;
}

void ServerCounters::RecordLatency(double latency_us) {
  size_t bucket = 0;
  while (bucket < kLatencyBucketsUs.size() && latency_us > kLatencyBucketsUs[bucket]) ++bucket;
  ++latency_bucket_counts[bucket];
  double sum = latency_sum_us.load();
  while (!latency_sum_us.compare_exchange_weak(sum, sum + latency_us)) {
  }
}

std::string ServerCounters::PrometheusText() const {
  std::ostringstream text;
  const auto metric = [&text](const char* name, const char* type, const char* help, int64_t value) {
    text << "# HELP " << name << " " << help << "\n# TYPE " << name << " " << type << "\n"
         << name << " " << value << "\n";
  };
  metric("evloc_sessions_active", "gauge", "Track sessions running now.", sessions_active);
  metric("evloc_sessions_started_total", "counter", "Track sessions accepted.", sessions_started);
  metric("evloc_requests_rejected_total", "counter", "Requests ended with an error status.",
         rejected);
  metric("evloc_events_total", "counter", "Events tracked (rate() gives events/s).", events);
  metric("evloc_poses_total", "counter", "PoseUpdates sent (rate() gives poses/s).", poses);
  metric("evloc_lost_poses_total", "counter",
         "PoseUpdates without a trusted pose (LOST, INITIALIZING, RELOCALIZING).", lost_poses);
  text << "# HELP evloc_pose_latency_microseconds Packet received to PoseUpdate sent.\n"
       << "# TYPE evloc_pose_latency_microseconds histogram\n";
  int64_t cumulative = 0;
  for (size_t i = 0; i <= kLatencyBucketsUs.size(); ++i) {
    cumulative += latency_bucket_counts[i];
    text << "evloc_pose_latency_microseconds_bucket{le=\""
         << (i < kLatencyBucketsUs.size()
                 ? std::to_string(static_cast<int64_t>(kLatencyBucketsUs[i]))
                 : std::string("+Inf"))
         << "\"} " << cumulative << "\n";
  }
  text << "evloc_pose_latency_microseconds_sum " << latency_sum_us.load() << "\n"
       << "evloc_pose_latency_microseconds_count " << cumulative << "\n";
  return text.str();
}

std::string LocalizerServerOptions::Describe() const {
  std::ostringstream text;
  text << "maps: " << maps_dir.string() << "\n"
       << "listen: " << listen_address << "\n"
       << "max-sessions: " << max_sessions << "\n"
       << "threads: " << (threads == 0 ? max_sessions + 8 : threads)
       << (threads == 0 ? " (automatic)" : "") << "\n"
       << "max-message-bytes: " << max_message_bytes << "\n"
       << "idle-timeout: " << idle_timeout_s << " s\n"
       << "queue-packets: " << queue_packets << "\n"
       << "backpressure-fraction: " << backpressure_fraction << "\n"
       << "max-map-memory: " << (max_map_memory_bytes >> 20) << " MiB\n"
       << "max-camera-pixels: " << max_camera_pixels << "\n"
       << "max-packet-span: " << max_packet_span_s << " s\n"
       << "max-rate: " << max_step_rate_hz << " Hz\n"
       << "metrics: " << metrics_address.value_or("none") << "\n"
       << "tls: "
       << (tls_cert_file ? tls_cert_file->string() + " + " + tls_key_file->string()
                         : std::string("off (plaintext)"))
       << "\n"
       << "auth-tokens: " << (auth_tokens_file ? auth_tokens_file->string() : "none (open)") << "\n"
       << "tracker: variant " << tracker.VariantName() << ", " << tracker.step_rate_hz
       << " Hz, max-points " << tracker.max_points << ", tau " << tracker.decay_time_s << " s\n";
  return text.str();
}

TokenTable TokenTable::Read(const std::filesystem::path& path) {
  std::ifstream file(path);
  if (!file) {
    throw IoError("cannot read the token file '" + path.string() +
                  "' (check the path given to --auth-tokens)");
  }
  TokenTable table;
  std::string line;
  int64_t line_number = 0;
  while (std::getline(file, line)) {
    ++line_number;
    const size_t comment = line.find('#');
    if (comment != std::string::npos) line.resize(comment);
    line = Trim(line);
    if (line.empty()) continue;
    std::istringstream fields(line);
    std::string token;
    std::string maps;
    std::string extra;
    fields >> token >> maps >> extra;
    if (!extra.empty()) {
      throw ParseError::AtLine(path.string(), line_number,
                               "expected `TOKEN [map1,map2,...]`, got more fields");
    }
    std::set<std::string> allowed;
    std::istringstream names(maps);
    std::string name;
    while (std::getline(names, name, ',')) {
      if (!name.empty()) allowed.insert(name);
    }
    if (!table.maps_.emplace(token, std::move(allowed)).second) {
      throw ParseError::AtLine(path.string(), line_number, "token listed twice");
    }
  }
  return table;
}

bool TokenTable::Allows(const std::string& token, const std::string& map_name) const {
  const auto found = maps_.find(token);
  if (found == maps_.end()) return false;
  return found->second.empty() || found->second.count(map_name) > 0;
}

// ---------------------------------------------------------------------------------------------
// The service.

class LocalizerServer::Service final : public api::Localizer::Service {
 public:
  Service(const LocalizerServerOptions& options, LogFunction log)
      : options_(options),
        session_limits_(options.session_limits()),
        log_(std::move(log)),
        registry_(MapRegistryOptions{options.maps_dir, options.max_map_memory_bytes}) {
    if (options.auth_tokens_file) tokens_ = TokenTable::Read(*options.auth_tokens_file);
  }

  grpc::Status ListMaps(grpc::ServerContext* context, const api::ListMapsRequest*,
                        api::ListMapsResponse* response) override {
    std::optional<std::string> token;
    if (grpc::Status status = Authenticate(*context, &token); !status.ok()) return Reject(status);
    for (const std::string& name : registry_.ListNames()) {
      if (tokens_ && !tokens_->Allows(*token, name)) continue;
      try {
        *response->add_maps() = DescribeMap(registry_.Describe(name));
      } catch (const Error& error) {
        Log("ListMaps: skipping map '" + name + "': " + error.what());
      }
    }
    return grpc::Status::OK;
  }

  grpc::Status GetMap(grpc::ServerContext* context, const api::GetMapRequest* request,
                      api::MapDescription* response) override {
    std::optional<std::string> token;
    if (grpc::Status status = Authenticate(*context, &token); !status.ok()) return Reject(status);
    if (grpc::Status status = Authorize(token, request->name()); !status.ok()) {
      return Reject(status);
    }
    try {
      *response = DescribeMap(*registry_.Get(request->name(), request->version()));
    } catch (const MapNotFoundError& error) {
      return Reject({grpc::StatusCode::NOT_FOUND, error.what()});
    } catch (const Error& error) {
      return Reject({grpc::StatusCode::FAILED_PRECONDITION,
                     std::string("the map cannot be loaded: ") + error.what()});
    }
    return grpc::Status::OK;
  }

  grpc::Status Track(grpc::ServerContext* context, TrackServerStream* stream) override;

  // Runs on the gRPC handler thread; bounded by --max-camera-pixels (HandleLocate).
  grpc::Status Locate(grpc::ServerContext* context, const api::LocateRequest* request,
                      api::LocateResponse* response) override {
    std::optional<std::string> token;
    if (grpc::Status status = Authenticate(*context, &token); !status.ok()) return Reject(status);
    if (grpc::Status status = Authorize(token, request->map_name()); !status.ok()) {
      return Reject(status);
    }
    grpc::Status status = HandleLocate(*request, registry_, options_.max_camera_pixels,
                                       relocalization::LocateOptions(), response);
    if (!status.ok()) {
      Log("Locate on map '" + request->map_name() + "' rejected: " + status.error_message());
      return Reject(status);
    }
    Log("Locate on map '" + request->map_name() +
        "': " + (response->status() == api::FOUND ? "FOUND" : "NOT_FOUND") + " in " +
        std::to_string(response->locate_ms()) + " ms");
    return status;
  }

  // Counts a rejected request and passes its status through.
  grpc::Status Reject(grpc::Status status) {
    ++counters_.rejected;
    return status;
  }

  // Checks the bearer token when tokens are configured; `token` receives it.
  grpc::Status Authenticate(const grpc::ServerContext& context,
                            std::optional<std::string>* token) const {
    if (!tokens_) return grpc::Status::OK;
    const auto& metadata = context.client_metadata();
    const auto found = metadata.find("authorization");
    const std::string prefix = "Bearer ";
    if (found == metadata.end()) {
      return {grpc::StatusCode::UNAUTHENTICATED,
              "this server needs a token: send metadata 'authorization: Bearer TOKEN'"};
    }
    const std::string value(found->second.data(), found->second.size());
    if (value.rfind(prefix, 0) != 0 || !tokens_->Knows(value.substr(prefix.size()))) {
      return {grpc::StatusCode::UNAUTHENTICATED, "unknown or malformed bearer token"};
    }
    *token = value.substr(prefix.size());
    return grpc::Status::OK;
  }

  // Checks that the token (if tokens are configured) may use `map_name`.
  grpc::Status Authorize(const std::optional<std::string>& token,
                         const std::string& map_name) const {
    if (!tokens_ || tokens_->Allows(*token, map_name)) return grpc::Status::OK;
    return {grpc::StatusCode::PERMISSION_DENIED, "this token may not use map '" + map_name + "'"};
  }

  // Writes a log line.
  void Log(const std::string& line) const {
    if (log_) log_(line);
  }

  const LocalizerServerOptions& options() const { return options_; }
  MapRegistry& registry() { return registry_; }
  ServerCounters& counters() { return counters_; }
  const SessionLimits& session_limits() const { return session_limits_; }
  uint64_t NextSessionId() { return ++last_session_id_; }

 private:
  LocalizerServerOptions options_;
  SessionLimits session_limits_;
  LogFunction log_;
  MapRegistry registry_;
  std::optional<TokenTable> tokens_;
  ServerCounters counters_;
  std::atomic<uint64_t> last_session_id_{0};
};

namespace {

// The state of one Track call: its reader (the gRPC handler thread) and its tracking worker,
// joined by a bounded queue, and a watchdog. The worker writes each pose to the stream itself, as
// soon as its step has run (no further thread hand-off: on a busy machine every hand-off waits
// for a core); it is the only writer while the session runs, so the reader never waits for a
// write (it leaves a Backpressure notice for the worker, which sends it after the item it is
// tracking). The watchdog cancels the call when nothing moves (no message read, no item tracked,
// no response written) for the idle timeout: a client that sends nothing, or that stops reading
// its responses so that a write blocks, cannot hold a session forever.
class TrackStream {
 public:
  TrackStream(LocalizerServer::Service& service, grpc::ServerContext* context,
              TrackServerStream* stream)
      : service_(service),
        options_(service.options()),
        context_(context),
        stream_(stream),
        inbound_(static_cast<size_t>(options_.queue_packets)),
        backpressure_threshold_(std::max<size_t>(
            1, static_cast<size_t>(options_.backpressure_fraction *
                                   static_cast<double>(options_.queue_packets)))) {}

  // True once the session was accepted (it then logs its own start and end).
  bool started() const { return id_ != 0; }

  // Runs the session to its end and returns its status.
  grpc::Status Run() {
    std::optional<std::string> token;
    if (grpc::Status status = service_.Authenticate(*context_, &token); !status.ok()) {
      return status;
    }
    api::TrackRequest request;
    if (!stream_->Read(&request)) {
      return {grpc::StatusCode::CANCELLED, "the stream ended before a SessionStart"};
    }
    if (!request.has_start()) {
      return {grpc::StatusCode::FAILED_PRECONDITION,
              "the first message of a Track stream must be a SessionStart"};
    }
    const api::SessionStart& start = request.start();
    if (grpc::Status status = service_.Authorize(token, start.map_name()); !status.ok()) {
      return status;
    }
    // Admission.
    ServerCounters& counters = service_.counters();
    if (++counters.sessions_active > options_.max_sessions) {
      --counters.sessions_active;
      return {grpc::StatusCode::RESOURCE_EXHAUSTED,
              "the server runs its maximum of " + std::to_string(options_.max_sessions) +
                  " sessions; retry later or use another server"};
    }
    struct ActiveSlot {
      ServerCounters& counters;
      ~ActiveSlot() { --counters.sessions_active; }
    } slot{counters};

    const auto open_start = Clock::now();
    OpenedSession opened;
    if (grpc::Status status =
            OpenSession(start, service_.registry(), service_.session_limits(), &opened);
        !status.ok()) {
      return status;
    }
    const std::shared_ptr<const LoadedMap>& map = opened.map;
    const SessionSettings& settings = opened.settings;
    tracker_ = std::move(opened.tracker);
    validator_ = std::make_unique<RequestValidator>(settings, service_.session_limits());
    id_ = service_.NextSessionId();
    ++counters.sessions_started;
    const auto session_start = Clock::now();
    service_.Log(
        "session " + std::to_string(id_) + " start: map " + map->name + " version " + map->version +
        " (" + std::to_string(map->map.size()) + " points), client '" + start.client_name() + "' " +
        context_->peer() + ", camera " + std::to_string(settings.camera.width) + "x" +
        std::to_string(settings.camera.height) + ", " +
        (tracker_->takes_frames() ? "frames" : "events") + ", " + settings.tracker.VariantName() +
        " at " + std::to_string(settings.tracker.step_rate_hz) + " Hz, opened in " +
        std::to_string(static_cast<int64_t>(MicrosecondsSince(open_start) / 1000)) + " ms");

    api::TrackResponse started;
    started.mutable_started()->set_session_id(id_);
    *started.mutable_started()->mutable_map() = DescribeMap(*map);
    started.mutable_started()->set_step_rate_hz(settings.tracker.step_rate_hz);
    started.mutable_started()->set_variant(settings.tracker.VariantName());
    started.mutable_started()->set_queue_capacity(static_cast<uint32_t>(inbound_.capacity()));
    if (!stream_->Write(started)) {
      return {grpc::StatusCode::CANCELLED, "the client went away"};
    }

    std::thread watchdog([this] { WatchdogLoop(); });
    std::thread worker([this] { WorkerLoop(); });
    grpc::Status status = ReadLoop();
    // Let the worker track and send what is queued (after an error: nothing more; the watchdog
    // ends a drain that makes no progress).
    if (status.ok()) {
      inbound_.Close();
    } else {
      inbound_.Abort();
    }
    worker.join();
    // A notice left by the reader goes out also when the session ends with an error (an
    // overflow follows its notice).
    WritePendingNotice();
    if (status.ok()) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!worker_status_.ok()) status = worker_status_;
    }
    if (status.ok()) {
      api::TrackResponse end;
      api::SessionEnd* totals = end.mutable_end();
      totals->set_packets(validator_->decoder().packets());
      totals->set_events(events_);
      totals->set_frames(frames_);
      totals->set_poses(poses_);
      totals->set_lost_poses(lost_poses_);
      totals->set_backpressure_notices(backpressure_notices_);
      totals->set_raw_time_adjustments(validator_->decoder().raw_time_adjustments());
      totals->set_duration_s(std::chrono::duration<double>(Clock::now() - session_start).count());
      totals->set_latency_p50_us(Percentile(latencies_us_, 0.5));
      totals->set_latency_p99_us(Percentile(latencies_us_, 0.99));
      Write(end);
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      session_over_ = true;
    }
    watchdog_cv_.notify_all();
    watchdog.join();
    if (status.ok() && idle_) status = IdleStatus();
    if (status.ok() && write_failed_) {
      status = grpc::Status(grpc::StatusCode::CANCELLED, "the client went away");
    }
    service_.Log(
        "session " + std::to_string(id_) +
        " end: " + (status.ok() ? std::string("OK") : status.error_message()) + "; " +
        std::to_string(validator_->decoder().packets()) + " packets, " + std::to_string(events_) +
        " events, " + std::to_string(frames_) + " frames, " + std::to_string(poses_) + " poses (" +
        std::to_string(lost_poses_) + " LOST), latency p50 " +
        std::to_string(static_cast<int64_t>(Percentile(latencies_us_, 0.5))) + " us p99 " +
        std::to_string(static_cast<int64_t>(Percentile(latencies_us_, 0.99))) +
        " us (in the queue p50 " +
        std::to_string(static_cast<int64_t>(Percentile(queue_us_, 0.5))) + " p99 " +
        std::to_string(static_cast<int64_t>(Percentile(queue_us_, 0.99))) +
        " us; stream write p50 " +
        std::to_string(static_cast<int64_t>(Percentile(write_us_, 0.5))) + " p99 " +
        std::to_string(static_cast<int64_t>(Percentile(write_us_, 0.99))) + " us), " +
        std::to_string(backpressure_notices_) + " backpressure notices, " +
        std::to_string(std::chrono::duration<double>(Clock::now() - session_start).count()) + " s");
    return status;
  }

 private:
  // The status of a session the watchdog cancelled.
  grpc::Status IdleStatus() const {
    return {grpc::StatusCode::CANCELLED,
            "nothing received, tracked or sent for " + std::to_string(options_.idle_timeout_s) +
                " s (idle timeout: the client sent nothing or stopped reading its responses)"};
  }

  // Until the session is over: cancels the call (once) when progress_ did not change for the
  // idle timeout.
  void WatchdogLoop() {
    const auto limit = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(options_.idle_timeout_s));
    const auto poll = std::min<Clock::duration>(limit / 10, std::chrono::milliseconds(100));
    uint64_t last_progress = progress_.load();
    auto last_change = Clock::now();
    std::unique_lock<std::mutex> lock(mutex_);
    while (!watchdog_cv_.wait_for(lock, poll, [&] { return session_over_; })) {
      const uint64_t progress = progress_.load();
      if (progress != last_progress) {
        last_progress = progress;
        last_change = Clock::now();
      } else if (!idle_ && Clock::now() - last_change > limit) {
        idle_ = true;
        context_->TryCancel();
      }
    }
  }

  // Reads messages until the client half-closes (OK) or something is wrong (its status).
  grpc::Status ReadLoop() {
    api::TrackRequest request;
    while (stream_->Read(&request)) {
      ++progress_;
      InboundItem item;
      item.received = Clock::now();
      if (grpc::Status status = validator_->Accept(request, &item.item); !status.ok()) {
        return status;
      }
      latest_end_t_ns_ = item.item.t_ns;
      const PushResult pushed = inbound_.TryPush(std::move(item));
      if (pushed == PushResult::kFull) {
        return {grpc::StatusCode::RESOURCE_EXHAUSTED,
                "the session's queue of " + std::to_string(inbound_.capacity()) +
                    " packets overflowed: the tracker is slower than the stream; send at real "
                    "time, lower the step rate or max_points, or wait for Backpressure to clear"};
      }
      if (pushed == PushResult::kClosed) break;  // The worker stopped; its status follows.
      NoteQueueLevel();
    }
    if (context_->IsCancelled()) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!worker_status_.ok()) return worker_status_;
      if (idle_) return IdleStatus();
      return {grpc::StatusCode::CANCELLED, "the client cancelled or went away"};
    }
    std::lock_guard<std::mutex> lock(mutex_);
    return worker_status_;
  }

  // Sends a Backpressure notice when the queue crosses the threshold (again once it fell below
  // half of it).
  void NoteQueueLevel() {
    const size_t queued = inbound_.size();
    if (queued >= backpressure_threshold_ && !backpressure_armed_) return;
    if (queued < backpressure_threshold_) {
      if (queued < backpressure_threshold_ / 2) backpressure_armed_ = true;
      return;
    }
    backpressure_armed_ = false;
    api::TrackResponse notice;
    notice.mutable_backpressure()->set_queued_packets(static_cast<uint32_t>(queued));
    notice.mutable_backpressure()->set_queue_capacity(static_cast<uint32_t>(inbound_.capacity()));
    notice.mutable_backpressure()->set_behind_ns(latest_end_t_ns_ - tracked_end_t_ns_.load());
    ++backpressure_notices_;
    // The reader must keep reading: the worker sends the notice after the item it is tracking.
    std::lock_guard<std::mutex> lock(notice_mutex_);
    pending_notice_ = std::move(notice);  // A newer notice replaces one not sent yet.
  }

  // Writes a pending Backpressure notice, if any; false when the client is gone. Only one thread
  // writes at a time: Run before the worker starts and after it joined, the worker in between.
  bool WritePendingNotice() {
    std::optional<api::TrackResponse> notice;
    {
      std::lock_guard<std::mutex> lock(notice_mutex_);
      notice.swap(pending_notice_);
    }
    return !notice || WriteNow(*notice);
  }

  // Writes a pending notice, then `response`; false when the client is gone (same thread rule).
  bool Write(const api::TrackResponse& response) {
    return WritePendingNotice() && WriteNow(response);
  }

  // Writes `response` to the stream; false when the client is gone.
  bool WriteNow(const api::TrackResponse& response) {
    if (write_failed_) return false;
    if (!stream_->Write(response)) {
      write_failed_ = true;
      return false;
    }
    ++progress_;
    return true;
  }

  // Tracks the queued items in order and writes each pose as soon as its step has run.
  void WorkerLoop() {
    ServerCounters& counters = service_.counters();
    api::TrackResponse response;
    while (true) {
      bool timed_out = false;
      std::optional<InboundItem> item = inbound_.Pop(std::chrono::seconds(1), &timed_out);
      if (!item) {
        if (timed_out) continue;  // The watchdog handles an idle session.
        return;
      }
      const auto dequeued = Clock::now();
      std::vector<tracking::PoseEstimate> estimates;
      try {
        estimates = tracker_->Process(item->item);
      } catch (const std::exception& error) {
        {
          std::lock_guard<std::mutex> lock(mutex_);
          worker_status_ = grpc::Status(grpc::StatusCode::INTERNAL,
                                        std::string("tracking failed: ") + error.what());
        }
        inbound_.Abort();
        context_->TryCancel();
        return;
      }
      if (item->item.kind == SessionItem::Kind::kFrame) ++frames_;
      events_ += item->item.events.size();
      counters.events += static_cast<int64_t>(item->item.events.size());
      tracked_end_t_ns_ = item->item.t_ns;
      ++progress_;
      if (!WritePendingNotice()) {
        inbound_.Abort();
        return;
      }
      for (const tracking::PoseEstimate& estimate : estimates) {
        *response.mutable_pose() = PoseUpdateFromEstimate(estimate);
        ++poses_;
        ++counters.poses;
        if (tracking::HasNoEstimate(estimate.status)) {
          ++lost_poses_;
          ++counters.lost_poses;
        }
        queue_us_.push_back(
            std::chrono::duration<double, std::micro>(dequeued - item->received).count());
        const auto write_start = Clock::now();
        const double latency_us =
            std::chrono::duration<double, std::micro>(write_start - item->received).count();
        response.mutable_pose()->set_latency_us(latency_us);
        latencies_us_.push_back(latency_us);
        counters.RecordLatency(latency_us);
        if (!Write(response)) {
          inbound_.Abort();
          return;
        }
        write_us_.push_back(MicrosecondsSince(write_start));
      }
    }
  }

  LocalizerServer::Service& service_;
  const LocalizerServerOptions& options_;
  grpc::ServerContext* context_;
  TrackServerStream* stream_;
  uint64_t id_ = 0;
  std::unique_ptr<SessionTracker> tracker_;
  std::unique_ptr<RequestValidator> validator_;
  BoundedQueue<InboundItem> inbound_;

  // Reader state.
  size_t backpressure_threshold_;
  bool backpressure_armed_ = true;
  int64_t latest_end_t_ns_ = 0;
  uint64_t backpressure_notices_ = 0;

  // Worker state (read by the reader after the worker joined, except tracked_end_t_ns_).
  std::atomic<int64_t> tracked_end_t_ns_{0};
  uint64_t events_ = 0;
  uint64_t frames_ = 0;
  uint64_t poses_ = 0;
  uint64_t lost_poses_ = 0;

  // Per pose: latency (received to handed to gRPC), time the packet waited in the queue, time
  // of the stream write; microseconds (written by the worker, read after it joined).
  std::vector<double> latencies_us_;
  std::vector<double> queue_us_;
  std::vector<double> write_us_;

  // Set when a stream write failed (the client is gone).
  std::atomic<bool> write_failed_{false};
  // A Backpressure notice from the reader that the worker has not sent yet (guarded by
  // notice_mutex_).
  std::mutex notice_mutex_;
  std::optional<api::TrackResponse> pending_notice_;

  // Shared between threads: messages read + items tracked + responses written (the watchdog's
  // sign of life); the rest is guarded by mutex_.
  std::atomic<uint64_t> progress_{0};
  std::mutex mutex_;
  std::condition_variable watchdog_cv_;
  grpc::Status worker_status_;
  // Set by the watchdog when it cancelled the call.
  bool idle_ = false;
  // Set by Run when the session is over (stops the watchdog).
  bool session_over_ = false;
};

}  // namespace

grpc::Status LocalizerServer::Service::Track(grpc::ServerContext* context,
                                             TrackServerStream* stream) {
  TrackStream session(*this, context, stream);
  grpc::Status status = session.Run();
  if (!status.ok()) {
    ++counters_.rejected;
    if (!session.started()) {
      Log("Track from " + context->peer() +
          " refused: " + wire::StatusCodeName(status.error_code()) + ": " + status.error_message());
    }
  }
  return status;
}

// ---------------------------------------------------------------------------------------------
// The server.

LocalizerServer::LocalizerServer(const LocalizerServerOptions& options, LogFunction log) {
  options.Check();
  service_ = std::make_unique<Service>(options, std::move(log));
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  std::shared_ptr<grpc::ServerCredentials> credentials = grpc::InsecureServerCredentials();
  if (options.tls_cert_file) {
    grpc::SslServerCredentialsOptions ssl;
    ssl.pem_key_cert_pairs.push_back(
        {ReadFileToString(*options.tls_key_file), ReadFileToString(*options.tls_cert_file)});
    credentials = grpc::SslServerCredentials(ssl);
  }
  builder.AddListeningPort(options.listen_address, credentials, &port_);
  builder.RegisterService(service_.get());
  builder.SetMaxReceiveMessageSize(options.max_message_bytes);
  grpc::ResourceQuota quota("evloc-localizer");
  quota.SetMaxThreads(options.threads == 0 ? options.max_sessions + 8 : options.threads);
  builder.SetResourceQuota(quota);
  server_ = builder.BuildAndStart();
  if (!server_ || port_ == 0) {
    throw IoError("cannot listen on '" + options.listen_address +
                  "' (address in use, or not a host:port this machine has)");
  }
  if (auto* health = server_->GetHealthCheckService()) health->SetServingStatus(true);
  if (options.metrics_address) {
    const ServerCounters* counters = &service_->counters();
    metrics_ = std::make_unique<MetricsHttpServer>(
        *options.metrics_address, [counters] { return counters->PrometheusText(); });
  }
}

LocalizerServer::~LocalizerServer() { Shutdown(); }

int LocalizerServer::metrics_port() const { return metrics_ ? metrics_->port() : 0; }

void LocalizerServer::Shutdown() {
  if (shut_down_.exchange(true)) return;
  metrics_.reset();
  if (auto* health = server_->GetHealthCheckService()) health->SetServingStatus(false);
  server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(1));
  server_->Wait();
}

void LocalizerServer::Wait() { server_->Wait(); }

const ServerCounters& LocalizerServer::counters() const { return service_->counters(); }

MapRegistry& LocalizerServer::registry() { return service_->registry(); }

}  // namespace evloc::service
