#include "localizer/service/localizer_server.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <ctime>
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
#include "localizer/service/client_text.h"
#include "localizer/service/locate_rpc.h"
#include "localizer/service/metrics_http.h"
#include "localizer/service/session.h"
#include "localizer/wire/percentile.h"
#include "localizer/wire/status_name.h"

namespace evloc::service {
namespace {

using Clock = std::chrono::steady_clock;
using TrackServerStream = grpc::ServerReaderWriter<api::TrackResponse, api::TrackRequest>;

double MicrosecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::micro>(Clock::now() - start).count();
}

// An item from the stream reader to the tracking worker.
struct InboundItem {
  // The validated request.
  SessionItem item;
  // When the reader received the message.
  Clock::time_point received;
  // Its share of the server's memory budget (released once tracked, or when dropped).
  MemoryBudget::Reservation reservation;
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
  if (queue_events > (int64_t{1} << 40)) throw InvalidArgumentError("--queue-events is too large");
  if (queue_events < max_packet_events) {
    throw InvalidArgumentError("--queue-events must be at least --max-packet-events (" +
                               std::to_string(max_packet_events) + ")");
  }
  if (max_memory_bytes < queue_events * kDecodedEventBytes) {
    throw InvalidArgumentError("--max-memory must hold at least one full session queue, " +
                               std::to_string(queue_events * kDecodedEventBytes) +
                               " bytes (--queue-events x 13)");
  }
  if (!(session_cpu_per_second > 0)) {
    throw InvalidArgumentError("--session-cpu-budget must be positive");
  }
  if (!(session_cpu_grace_s >= 0)) {
    throw InvalidArgumentError("--session-cpu-grace must not be negative");
  }
  if (!(handshake_timeout_s > 0))
    throw InvalidArgumentError("--handshake-timeout must be positive");
  if (max_streams_per_peer < 0 || max_sessions_per_peer < 0 || max_sessions_per_token < 0) {
    throw InvalidArgumentError(
        "--max-streams-per-peer, --max-sessions-per-peer and --max-sessions-per-token must not be "
        "negative");
  }
  if (max_streams_per_connection < 1) {
    throw InvalidArgumentError("--max-streams-per-connection must be at least 1");
  }
  if (!(max_connection_age_s >= 0) || !(max_connection_age_grace_s >= 0) ||
      max_connection_age_s > 1e6 || max_connection_age_grace_s > 1e6) {
    throw InvalidArgumentError(
        "--max-connection-age and --max-connection-age-grace must be in [0, 1e6] s");
  }
  if (!(drain_timeout_s >= 0) || drain_timeout_s > 3600) {
    throw InvalidArgumentError("--drain-timeout must be in [0, 3600] s");
  }
  if (tls_client_ca_file && !tls_cert_file) {
    throw InvalidArgumentError(
        "--tls-client-ca needs --tls-cert and --tls-key (client "
        "certificates are checked in the TLS handshake)");
  }
  if (reload_interval_s < 1) throw InvalidArgumentError("--reload-interval must be at least 1 s");
  CheckListenSecurity(listen_address, listen_security());
  session_limits().Check();
}

ListenSecurity LocalizerServerOptions::listen_security() const {
  return {tls_cert_file.has_value(), auth_tokens_file.has_value(), tls_client_ca_file.has_value(),
          insecure};
}

SessionLimits LocalizerServerOptions::session_limits() const {
  SessionLimits limits;
  limits.tracker = tracker;
  limits.max_camera_pixels = max_camera_pixels;
  limits.max_packet_span_ns = std::isfinite(max_packet_span_s) && max_packet_span_s > 0
                                  ? std::llround(std::min(max_packet_span_s, 1e9) * 1e9)
                                  : 0;
  limits.max_step_rate_hz = max_step_rate_hz;
  limits.max_points_limit = max_points_limit;
  limits.max_steps_per_request = max_steps_per_request;
  limits.max_packet_events = max_packet_events;
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
  metric("evloc_requests_limited_total", "counter",
         "Requests refused or ended by a server limit (sessions, per peer or token, memory, "
         "handshake timeout, CPU budget, events or steps per packet).",
         limited);
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
       << "max-points-limit: " << max_points_limit << "\n"
       << "max-steps-per-request: " << max_steps_per_request << "\n"
       << "max-packet-events: " << max_packet_events << "\n"
       << "queue-events: " << queue_events << "\n"
       << "max-memory: " << max_memory_bytes << " bytes\n"
       << "session-cpu-budget: " << session_cpu_per_second << " CPU s per session s (grace "
       << session_cpu_grace_s << " s)\n"
       << "handshake-timeout: " << handshake_timeout_s << " s\n"
       << "max-streams-per-peer: "
       << (max_streams_per_peer == 0 ? max_sessions : max_streams_per_peer) << "\n"
       << "max-sessions-per-peer: "
       << (max_sessions_per_peer == 0 ? max_sessions : max_sessions_per_peer) << "\n"
       << "max-sessions-per-token: "
       << (max_sessions_per_token == 0 ? std::string("no limit")
                                       : std::to_string(max_sessions_per_token))
       << "\n"
       << "max-streams-per-connection: " << max_streams_per_connection << "\n"
       << "max-connection-age: " << max_connection_age_s << " s (grace "
       << max_connection_age_grace_s << " s)\n"
       << "drain-timeout: " << drain_timeout_s << " s\n"
       << "metrics: " << metrics_address.value_or("none") << "\n"
       << "tls: "
       << (tls_cert_file ? tls_cert_file->string() + " + " + tls_key_file->string()
                         : std::string("off (plaintext)"))
       << "\n"
       << "auth-tokens: " << (auth_tokens_file ? auth_tokens_file->string() : "none (open)") << "\n"
       << "tls-client-ca: "
       << (tls_client_ca_file ? tls_client_ca_file->string() : std::string("none")) << "\n"
       << "reload-interval: " << reload_interval_s << " s\n"
       << "security: " << DescribeListenSecurity(listen_address, listen_security()) << "\n"
       << "tracker: variant " << tracker.VariantName() << ", " << tracker.step_rate_hz
       << " Hz, max-points " << tracker.max_points << ", tau " << tracker.decay_time_s << " s\n";
  return text.str();
}

// ---------------------------------------------------------------------------------------------
// The service.

class LocalizerServer::Service final : public api::Localizer::Service {
 public:
  Service(const LocalizerServerOptions& options, LogFunction log)
      : options_(options),
        session_limits_(options.session_limits()),
        log_(std::move(log)),
        registry_(MapRegistryOptions{options.maps_dir, options.max_map_memory_bytes}),
        memory_(options.max_memory_bytes) {
    if (options.auth_tokens_file) {
      tokens_ = std::make_unique<TokenFile>(*options.auth_tokens_file,
                                            std::chrono::seconds(options.reload_interval_s),
                                            [this](const std::string& line) { Log(line); });
    }
  }

  // The health service to keep up to date (set once the server runs).
  void SetHealth(grpc::HealthCheckServiceInterface* health) {
    health_ = health;
    UpdateHealth();
  }

  // True when a new session would be admitted now (no drain, a free session slot, memory
  // budget below 3/4).
  bool CanAdmit() const {
    return !draining_ && counters_.sessions_active.load() < options_.max_sessions &&
           memory_.used() < memory_.limit() / 4 * 3;
  }

  // Sets the health of the Localizer service (what readiness checks should ask for) to SERVING
  // when CanAdmit(), else NOT_SERVING; the overall health ("") stays SERVING until the drain
  // (liveness). Calls gRPC only when the answer changes.
  void UpdateHealth() {
    grpc::HealthCheckServiceInterface* health = health_.load();
    if (!health) return;
    const int serving = CanAdmit() ? 1 : 0;
    if (health_state_.exchange(serving) == serving) return;
    health->SetServingStatus(api::Localizer::service_full_name(), serving == 1);
  }

  // Starts the drain: health NOT_SERVING (overall too), sessions stop (TrackStream polls
  // draining()).
  void StartDraining() {
    draining_ = true;
    if (grpc::HealthCheckServiceInterface* health = health_.load()) {
      health->SetServingStatus(false);
      health_state_ = 0;
    }
  }
  bool draining() const { return draining_; }

  // Registers a Track stream from `peer` (a host, see PeerHost); RESOURCE_EXHAUSTED when the peer
  // has max_streams_per_peer open.
  grpc::Status OpenStream(const std::string& peer) {
    const int limit =
        options_.max_streams_per_peer == 0 ? options_.max_sessions : options_.max_streams_per_peer;
    std::lock_guard<std::mutex> lock(admission_mutex_);
    int& open = streams_per_peer_[peer];
    if (open >= limit) {
      if (open == 0) streams_per_peer_.erase(peer);
      ++counters_.limited;
      return {grpc::StatusCode::RESOURCE_EXHAUSTED,
              "this address has " + std::to_string(limit) +
                  " Track streams open, the most this server allows per peer "
                  "(evloc-localizer --max-streams-per-peer); end one first"};
    }
    ++open;
    return grpc::Status::OK;
  }
  // Unregisters a stream OpenStream admitted.
  void CloseStream(const std::string& peer) {
    std::lock_guard<std::mutex> lock(admission_mutex_);
    if (--streams_per_peer_[peer] <= 0) streams_per_peer_.erase(peer);
  }

  // The most sessions `token` (an authenticated token or identity) may run at once; 0: no
  // limit. The hook for per-token limits (today the same for every token).
  int SessionLimitOfToken(const std::string& /*token*/) const {
    return options_.max_sessions_per_token;
  }

  // Admits a session from `peer` with `token` (nullopt without tokens): RESOURCE_EXHAUSTED when
  // the server runs max_sessions, the peer max_sessions_per_peer, the token its limit, or 3/4 of
  // the memory budget is in use; UNAVAILABLE while draining. Admitted sessions end with
  // EndSession.
  grpc::Status AdmitSession(const std::string& peer, const std::optional<std::string>& token) {
    const auto refuse = [this](const std::string& message) {
      ++counters_.limited;
      return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED, message);
    };
    {
      std::lock_guard<std::mutex> lock(admission_mutex_);
      if (draining_) {
        return {grpc::StatusCode::UNAVAILABLE,
                "draining: the server is shutting down; start the session on another server"};
      }
      if (counters_.sessions_active >= options_.max_sessions) {
        return refuse("the server runs its maximum of " + std::to_string(options_.max_sessions) +
                      " sessions; retry later or use another server");
      }
      const int peer_limit = options_.max_sessions_per_peer == 0 ? options_.max_sessions
                                                                 : options_.max_sessions_per_peer;
      if (sessions_per_peer_[peer] >= peer_limit) {
        if (sessions_per_peer_[peer] == 0) sessions_per_peer_.erase(peer);
        return refuse("this address runs " + std::to_string(peer_limit) +
                      " sessions, the most this server allows per peer "
                      "(evloc-localizer --max-sessions-per-peer)");
      }
      if (token) {
        const int token_limit = SessionLimitOfToken(*token);
        if (token_limit > 0 && sessions_per_token_[*token] >= token_limit) {
          if (sessions_per_token_[*token] == 0) sessions_per_token_.erase(*token);
          return refuse("this token runs " + std::to_string(token_limit) +
                        " sessions, the most this server allows per token "
                        "(evloc-localizer --max-sessions-per-token)");
        }
      }
      if (memory_.used() >= memory_.limit() / 4 * 3) {
        return refuse(
            "the server's memory budget for queued events is 3/4 used (evloc-localizer "
            "--max-memory); retry later or use another server");
      }
      ++counters_.sessions_active;
      ++sessions_per_peer_[peer];
      if (token) ++sessions_per_token_[*token];
    }
    UpdateHealth();
    return grpc::Status::OK;
  }
  // Ends a session AdmitSession admitted.
  void EndSession(const std::string& peer, const std::optional<std::string>& token) {
    {
      std::lock_guard<std::mutex> lock(admission_mutex_);
      --counters_.sessions_active;
      if (--sessions_per_peer_[peer] <= 0) sessions_per_peer_.erase(peer);
      if (token && --sessions_per_token_[*token] <= 0) sessions_per_token_.erase(*token);
    }
    UpdateHealth();
  }

  // The server-wide budget of queued decoded requests.
  MemoryBudget& memory() { return memory_; }

  // `status` as a client may see it: no server paths in the message.
  grpc::Status ForClient(const grpc::Status& status) const {
    if (status.ok()) return status;
    return {status.error_code(), ScrubServerPaths(status.error_message(), options_.maps_dir)};
  }

  // Metrics of the service beyond ServerCounters (Prometheus text).
  std::string ServiceMetricsText() const {
    std::ostringstream text;
    text
        << "# HELP evloc_queued_bytes Decoded requests waiting in the sessions' queues, bytes "
           "(the --max-memory budget in use).\n# TYPE evloc_queued_bytes gauge\nevloc_queued_bytes "
        << memory_.used() << "\n# HELP evloc_memory_budget_bytes The --max-memory budget.\n"
        << "# TYPE evloc_memory_budget_bytes gauge\nevloc_memory_budget_bytes " << memory_.limit()
        << "\n";
    return text.str();
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
        Log("ListMaps: skipping map '" + EscapeForLog(name) +
            "': " + EscapeForLog(error.what(), 1024));
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
      return Reject(ForClient({grpc::StatusCode::NOT_FOUND, error.what()}));
    } catch (const Error& error) {
      Log("GetMap '" + EscapeForLog(request->name()) +
          "': cannot load: " + EscapeForLog(error.what(), 1024));
      return Reject(ForClient({grpc::StatusCode::FAILED_PRECONDITION,
                               std::string("the map cannot be loaded: ") + error.what()}));
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
      Log("Locate on map '" + EscapeForLog(request->map_name()) +
          "' rejected: " + EscapeForLog(status.error_message(), 1024));
      return Reject(ForClient(status));
    }
    Log("Locate on map '" + EscapeForLog(request->map_name()) +
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
  const ServerCounters& counters() const { return counters_; }
  const SessionLimits& session_limits() const { return session_limits_; }
  uint64_t NextSessionId() { return ++last_session_id_; }

 private:
  LocalizerServerOptions options_;
  SessionLimits session_limits_;
  LogFunction log_;
  MapRegistry registry_;
  std::unique_ptr<TokenFile> tokens_;
  ServerCounters counters_;
  std::atomic<uint64_t> last_session_id_{0};
  MemoryBudget memory_;
  std::atomic<grpc::HealthCheckServiceInterface*> health_{nullptr};
  // Last Localizer health set: -1 none yet, 0 NOT_SERVING, 1 SERVING.
  std::atomic<int> health_state_{-1};
  std::atomic<bool> draining_{false};
  // Open streams and running sessions per peer host and per token (guarded by
  // admission_mutex_; counters_.sessions_active is changed under it too).
  std::mutex admission_mutex_;
  std::map<std::string, int> streams_per_peer_;
  std::map<std::string, int> sessions_per_peer_;
  std::map<std::string, int> sessions_per_token_;
};

namespace {

// The state of one Track call: its reader (the gRPC handler thread) and its tracking worker,
// joined by a bounded queue, and a watchdog. The worker writes each pose to the stream itself, as
// soon as its step has run (no further thread hand-off: on a busy machine every hand-off waits
// for a core); it is the only writer while the session runs, so the reader never waits for a
// write (it leaves a Backpressure notice for the worker, which sends it after the item it is
// tracking). The watchdog cancels the call when the first message does not arrive within the
// handshake timeout, and when nothing moves (no message read, no item tracked, no response
// written) for the idle timeout: a client that sends nothing, or that stops reading its responses
// so that a write blocks, cannot hold a thread or a session forever. The worker asks between
// steps whether to stop (the reader ended, the drain, the CPU budget), so no request keeps a core
// busy after its session ended.
class TrackStream {
 public:
  TrackStream(LocalizerServer::Service& service, grpc::ServerContext* context,
              TrackServerStream* stream)
      : service_(service),
        options_(service.options()),
        context_(context),
        stream_(stream),
        inbound_(static_cast<size_t>(options_.queue_packets),
                 static_cast<uint64_t>(options_.queue_events)),
        backpressure_threshold_(
            std::max<size_t>(1, static_cast<size_t>(options_.backpressure_fraction *
                                                    static_cast<double>(options_.queue_packets)))),
        backpressure_event_threshold_(std::max<uint64_t>(
            1, static_cast<uint64_t>(options_.backpressure_fraction *
                                     static_cast<double>(options_.queue_events)))) {}

  // True once the session was accepted (it then logs its own start and end).
  bool started() const { return id_ != 0; }

  // Runs the call to its end and returns its status.
  grpc::Status Run() {
    std::optional<std::string> token;
    if (grpc::Status status = service_.Authenticate(*context_, &token); !status.ok()) {
      return status;
    }
    peer_ = PeerHost(context_->peer());
    if (grpc::Status status = service_.OpenStream(peer_); !status.ok()) return status;
    struct StreamSlot {
      LocalizerServer::Service& service;
      const std::string& peer;
      ~StreamSlot() { service.CloseStream(peer); }
    } stream_slot{service_, peer_};
    std::thread watchdog([this] { WatchdogLoop(); });
    struct WatchdogStop {
      TrackStream& stream;
      std::thread& thread;
      ~WatchdogStop() {
        {
          std::lock_guard<std::mutex> lock(stream.mutex_);
          stream.session_over_ = true;
        }
        stream.watchdog_cv_.notify_all();
        thread.join();
      }
    } watchdog_stop{*this, watchdog};
    grpc::Status status = RunSession(token);
    if (handshake_expired_) {
      status = {grpc::StatusCode::CANCELLED,
                "no SessionStart within " + std::to_string(options_.handshake_timeout_s) +
                    " s of the call (evloc-localizer --handshake-timeout)"};
    }
    return status;
  }

 private:
  // "ipv4:1.2.3.4:5678" -> "ipv4:1.2.3.4", "ipv6:[::1]:5678" -> "ipv6:[::1]": what the per-peer
  // limits count (a client opens each connection from another port).
  static std::string PeerHost(const std::string& peer) {
    if (peer.rfind("ipv4:", 0) != 0 && peer.rfind("ipv6:", 0) != 0) return peer;
    const size_t colon = peer.rfind(':');
    return colon > 5 ? peer.substr(0, colon) : peer;
  }

  // CPU time of the calling thread, seconds.
  static double ThreadCpuSeconds() {
    timespec now{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
    return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
  }

  // How long a draining session waits for its client's next message before it is cancelled.
  static constexpr auto kDrainReadWait = std::chrono::seconds(1);

  // The status of a session stopped by the drain.
  static grpc::Status DrainingStatus() {
    return {grpc::StatusCode::UNAVAILABLE,
            "draining: the server is shutting down; start a new session on another server (from "
            "the last pose received)"};
  }

  // From the first message to the end of the session.
  grpc::Status RunSession(const std::optional<std::string>& token) {
    api::TrackRequest request;
    const bool received = stream_->Read(&request);
    handshake_done_ = true;
    ++progress_;
    if (!received) return {grpc::StatusCode::CANCELLED, "the stream ended before a SessionStart"};
    if (!request.has_start()) {
      return {grpc::StatusCode::FAILED_PRECONDITION,
              "the first message of a Track stream must be a SessionStart"};
    }
    const api::SessionStart& start = request.start();
    if (grpc::Status status = service_.Authorize(token, start.map_name()); !status.ok()) {
      return status;
    }
    // Admission.
    if (grpc::Status status = service_.AdmitSession(peer_, token); !status.ok()) return status;
    struct ActiveSlot {
      LocalizerServer::Service& service;
      const std::string& peer;
      const std::optional<std::string>& token;
      ~ActiveSlot() { service.EndSession(peer, token); }
    } slot{service_, peer_, token};
    ServerCounters& counters = service_.counters();

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
    initial_t_ns_ = settings.initial_t_ns;
    validator_ = std::make_unique<RequestValidator>(settings, service_.session_limits());
    id_ = service_.NextSessionId();
    ++counters.sessions_started;
    const auto session_start = Clock::now();
    service_.Log(
        "session " + std::to_string(id_) + " start: map " + map->name + " version " + map->version +
        " (" + std::to_string(map->map.size()) + " points), client '" +
        EscapeForLog(start.client_name()) + "' " + context_->peer() + ", camera " +
        std::to_string(settings.camera.width) + "x" + std::to_string(settings.camera.height) +
        ", " + (tracker_->takes_frames() ? "frames" : "events") + ", " +
        settings.tracker.VariantName() + " at " + std::to_string(settings.tracker.step_rate_hz) +
        " Hz, opened in " +
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

    std::thread worker([this] { WorkerLoop(); });
    grpc::Status status = ReadLoop();
    // Let the worker track and send what is queued (after an error, a cancellation or the drain:
    // nothing more, and the step it runs is its last; the watchdog ends a drain that makes no
    // progress).
    if (status.ok()) {
      inbound_.Close();
    } else {
      stop_requested_ = true;
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
      totals->set_latency_p50_us(latencies_us_.Percentile(0.5));
      totals->set_latency_p99_us(latencies_us_.Percentile(0.99));
      Write(end);
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (status.ok() && idle_) status = IdleStatus();
    }
    if (status.ok() && write_failed_) {
      status = grpc::Status(grpc::StatusCode::CANCELLED, "the client went away");
    }
    const auto us = [](const wire::LogHistogram& histogram, double fraction) {
      return std::to_string(static_cast<int64_t>(histogram.Percentile(fraction)));
    };
    service_.Log(
        "session " + std::to_string(id_) + " end: " +
        (status.ok() ? std::string("OK")
                     : std::string(wire::StatusCodeName(status.error_code())) + ": " +
                           EscapeForLog(status.error_message(), 1024)) +
        "; " + std::to_string(validator_->decoder().packets()) + " packets, " +
        std::to_string(events_) + " events, " + std::to_string(frames_) + " frames, " +
        std::to_string(poses_) + " poses (" + std::to_string(lost_poses_) + " LOST), latency p50 " +
        us(latencies_us_, 0.5) + " us p99 " + us(latencies_us_, 0.99) + " us (in the queue p50 " +
        us(queue_us_, 0.5) + " p99 " + us(queue_us_, 0.99) + " us; stream write p50 " +
        us(write_us_, 0.5) + " p99 " + us(write_us_, 0.99) + " us), " +
        std::to_string(backpressure_notices_) + " backpressure notices, " +
        std::to_string(cpu_used_s_.load()) + " CPU s, " +
        std::to_string(std::chrono::duration<double>(Clock::now() - session_start).count()) + " s");
    return status;
  }

  // The status of a session the watchdog cancelled.
  grpc::Status IdleStatus() const {
    return {grpc::StatusCode::CANCELLED,
            "nothing received, tracked or sent for " + std::to_string(options_.idle_timeout_s) +
                " s (idle timeout: the client sent nothing or stopped reading its responses)"};
  }

  // Until the call is over: cancels it (once) when the first message did not arrive within the
  // handshake timeout, or when progress_ did not change for the idle timeout; passes the drain
  // on to the worker (stop_requested_) and cancels a call still waiting for its first message.
  void WatchdogLoop() {
    const auto seconds = [](double s) {
      return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
    };
    const auto limit = seconds(options_.idle_timeout_s);
    const auto handshake_limit = seconds(options_.handshake_timeout_s);
    const auto poll = std::min<Clock::duration>(std::min(limit, handshake_limit) / 10,
                                                std::chrono::milliseconds(100));
    const auto call_start = Clock::now();
    std::optional<Clock::time_point> drain_start;
    uint64_t last_progress = progress_.load();
    auto last_change = Clock::now();
    bool cancelled = false;
    std::unique_lock<std::mutex> lock(mutex_);
    while (!watchdog_cv_.wait_for(lock, poll, [&] { return session_over_; })) {
      if (service_.draining()) {
        stop_requested_ = true;
        draining_ = true;
        if (!drain_start) drain_start = Clock::now();
        // A stream without a session ends at once; a session whose client sends nothing (the
        // reader waits for its next message to answer "draining") is cancelled after 1 s.
        if (!cancelled && (!handshake_done_ || Clock::now() - *drain_start > kDrainReadWait)) {
          cancelled = true;
          context_->TryCancel();
        }
      }
      if (!handshake_done_) {
        if (!cancelled && Clock::now() - call_start > handshake_limit) {
          cancelled = true;
          handshake_expired_ = true;
          ++service_.counters().limited;
          context_->TryCancel();
        }
        continue;
      }
      const uint64_t progress = progress_.load();
      if (progress != last_progress) {
        last_progress = progress;
        last_change = Clock::now();
      } else if (!idle_ && !cancelled && Clock::now() - last_change > limit) {
        idle_ = true;
        cancelled = true;
        context_->TryCancel();
      }
    }
  }

  // Reads messages until the client half-closes (OK) or something is wrong (its status).
  grpc::Status ReadLoop() {
    api::TrackRequest request;
    MemoryBudget& memory = service_.memory();
    while (stream_->Read(&request)) {
      ++progress_;
      if (service_.draining()) return DrainingStatus();
      InboundItem item;
      item.received = Clock::now();
      if (grpc::Status status = validator_->Accept(request, &item.item); !status.ok()) {
        return status;
      }
      const uint64_t events = item.item.events.size();
      const int64_t bytes = static_cast<int64_t>(events) * kDecodedEventBytes +
                            static_cast<int64_t>(item.item.gray.total());
      std::optional<MemoryBudget::Reservation> reservation = memory.TryReserve(bytes);
      if (!reservation) {
        ++service_.counters().limited;
        return {grpc::StatusCode::RESOURCE_EXHAUSTED,
                "the server's memory budget for queued events (" + std::to_string(memory.limit()) +
                    " bytes, evloc-localizer --max-memory) is used up; retry later or use "
                    "another server"};
      }
      item.reservation = std::move(*reservation);
      latest_end_t_ns_ = item.item.t_ns;
      const PushResult pushed = inbound_.TryPush(std::move(item), events);
      if (pushed == PushResult::kFull) {
        return {grpc::StatusCode::RESOURCE_EXHAUSTED,
                "the session's queue of " + std::to_string(inbound_.capacity()) + " packets / " +
                    std::to_string(inbound_.max_weight()) +
                    " events overflowed: the tracker is slower than the stream; send at real "
                    "time, lower the step rate or max_points, or wait for Backpressure to clear"};
      }
      if (pushed == PushResult::kClosed) break;  // The worker stopped; its status follows.
      service_.UpdateHealth();
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

  // Sends a Backpressure notice when the queue crosses the threshold, in packets or in events
  // (again once it fell below half of it).
  void NoteQueueLevel() {
    const size_t queued = inbound_.size();
    const uint64_t queued_events = inbound_.weight();
    const bool above =
        queued >= backpressure_threshold_ || queued_events >= backpressure_event_threshold_;
    if (above && !backpressure_armed_) return;
    if (!above) {
      if (queued < backpressure_threshold_ / 2 &&
          queued_events < backpressure_event_threshold_ / 2) {
        backpressure_armed_ = true;
      }
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

  // Asked by the tracker between steps (worker thread): true to stop (the reader ended or the
  // drain: stop_requested_; the CPU budget: cpu_exceeded_).
  bool ShouldStop() {
    ++progress_;  // A step ran: the session is alive even when one packet takes long.
    if (stop_requested_) return true;
    const double used = ThreadCpuSeconds() - worker_cpu_start_s_;
    cpu_used_s_ = used;
    const double tracked_s =
        std::max(0.0, static_cast<double>(tracker_->advanced_t_ns() - initial_t_ns_) * 1e-9);
    if (used > options_.session_cpu_grace_s + options_.session_cpu_per_second * tracked_s) {
      cpu_exceeded_ = true;
      return true;
    }
    return false;
  }

  // Ends the session from the worker with `status`: the reader stops at its next message.
  void FailFromWorker(grpc::Status status) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      worker_status_ = std::move(status);
    }
    inbound_.Abort();
  }

  // Tracks the queued items in order and writes each pose as soon as its step has run.
  void WorkerLoop() {
    ServerCounters& counters = service_.counters();
    worker_cpu_start_s_ = ThreadCpuSeconds();
    const SessionTracker::StopFunction stop = [this] { return ShouldStop(); };
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
        estimates = tracker_->Process(item->item, stop);
      } catch (const std::exception& error) {
        service_.Log("session " + std::to_string(id_) +
                     " tracking failed: " + EscapeForLog(error.what(), 1024));
        FailFromWorker(grpc::Status(
            grpc::StatusCode::INTERNAL,
            ScrubServerPaths(std::string("tracking failed: ") + error.what(), options_.maps_dir)));
        context_->TryCancel();
        return;
      }
      item->reservation.Release();
      service_.UpdateHealth();
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
        queue_us_.Add(std::chrono::duration<double, std::micro>(dequeued - item->received).count());
        const auto write_start = Clock::now();
        const double latency_us =
            std::chrono::duration<double, std::micro>(write_start - item->received).count();
        response.mutable_pose()->set_latency_us(latency_us);
        latencies_us_.Add(latency_us);
        counters.RecordLatency(latency_us);
        if (!Write(response)) {
          inbound_.Abort();
          return;
        }
        write_us_.Add(MicrosecondsSince(write_start));
      }
      if (tracker_->stopped()) {
        if (cpu_exceeded_) {
          ++counters.limited;
          FailFromWorker({grpc::StatusCode::RESOURCE_EXHAUSTED,
                          "the session used " + std::to_string(cpu_used_s_.load()) +
                              " CPU s, over its budget of " +
                              std::to_string(options_.session_cpu_grace_s) + " s + " +
                              std::to_string(options_.session_cpu_per_second) +
                              " CPU s per second of session time tracked (evloc-localizer "
                              "--session-cpu-budget): lower the step rate or max_points"});
        } else if (draining_) {
          FailFromWorker(DrainingStatus());
        } else {
          inbound_.Abort();  // The reader ended the session; its status stands.
        }
        return;
      }
    }
  }

  LocalizerServer::Service& service_;
  const LocalizerServerOptions& options_;
  grpc::ServerContext* context_;
  TrackServerStream* stream_;
  // The peer's host (per-peer limits).
  std::string peer_;
  uint64_t id_ = 0;
  std::unique_ptr<SessionTracker> tracker_;
  std::unique_ptr<RequestValidator> validator_;
  int64_t initial_t_ns_ = 0;
  BoundedQueue<InboundItem> inbound_;

  // Reader state.
  size_t backpressure_threshold_;
  uint64_t backpressure_event_threshold_;
  bool backpressure_armed_ = true;
  int64_t latest_end_t_ns_ = 0;
  uint64_t backpressure_notices_ = 0;

  // Worker state (read by the reader after the worker joined, except tracked_end_t_ns_).
  std::atomic<int64_t> tracked_end_t_ns_{0};
  uint64_t events_ = 0;
  uint64_t frames_ = 0;
  uint64_t poses_ = 0;
  uint64_t lost_poses_ = 0;
  double worker_cpu_start_s_ = 0;
  std::atomic<double> cpu_used_s_{0};
  bool cpu_exceeded_ = false;

  // Per pose: latency (received to handed to gRPC), time the packet waited in the queue, time
  // of the stream write; microseconds, fixed-size histograms (written by the worker, read after
  // it joined).
  wire::LogHistogram latencies_us_;
  wire::LogHistogram queue_us_;
  wire::LogHistogram write_us_;

  // Set when a stream write failed (the client is gone).
  std::atomic<bool> write_failed_{false};
  // A Backpressure notice from the reader that the worker has not sent yet (guarded by
  // notice_mutex_).
  std::mutex notice_mutex_;
  std::optional<api::TrackResponse> pending_notice_;

  // Set once the first message arrived (or the stream ended before it).
  std::atomic<bool> handshake_done_{false};
  // Set by the watchdog when it cancelled a call without a first message in time.
  std::atomic<bool> handshake_expired_{false};
  // Asks the worker to stop after its current step (the reader ended with an error, the drain).
  std::atomic<bool> stop_requested_{false};
  // Set by the watchdog when the server drains.
  std::atomic<bool> draining_{false};

  // Shared between threads: messages read + items tracked + responses written (the watchdog's
  // sign of life); the rest is guarded by mutex_.
  std::atomic<uint64_t> progress_{0};
  std::mutex mutex_;
  std::condition_variable watchdog_cv_;
  grpc::Status worker_status_;
  // Set by the watchdog when it cancelled the call.
  bool idle_ = false;
  // Set by Run when the call is over (stops the watchdog).
  bool session_over_ = false;
};

}  // namespace

grpc::Status LocalizerServer::Service::Track(grpc::ServerContext* context,
                                             TrackServerStream* stream) {
  TrackStream session(*this, context, stream);
  grpc::Status status = ForClient(session.Run());
  if (!status.ok()) {
    ++counters_.rejected;
    if (!session.started()) {
      Log("Track from " + context->peer() +
          " refused: " + wire::StatusCodeName(status.error_code()) + ": " +
          EscapeForLog(status.error_message(), 1024));
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
    tls_files_ = std::make_unique<ServerTlsFiles>(
        *options.tls_cert_file, *options.tls_key_file, options.tls_client_ca_file,
        options.reload_interval_s,
        [service = service_.get()](const std::string& line) { service->Log(line); });
    credentials = tls_files_->credentials();
  }
  builder.AddListeningPort(options.listen_address, credentials, &port_);
  builder.RegisterService(service_.get());
  builder.SetMaxReceiveMessageSize(options.max_message_bytes);
  builder.AddChannelArgument(GRPC_ARG_MAX_CONCURRENT_STREAMS, options.max_streams_per_connection);
  if (options.max_connection_age_s > 0) {
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_AGE_MS,
                               static_cast<int>(options.max_connection_age_s * 1000));
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_AGE_GRACE_MS,
                               static_cast<int>(options.max_connection_age_grace_s * 1000));
  }
  grpc::ResourceQuota quota("evloc-localizer");
  quota.SetMaxThreads(options.threads == 0 ? options.max_sessions + 8 : options.threads);
  // gRPC's own buffers (messages being received and sent): the same budget, but room for at
  // least 16 messages of the largest size.
  quota.Resize(static_cast<size_t>(
      std::max(options.max_memory_bytes, int64_t{16} * options.max_message_bytes)));
  builder.SetResourceQuota(quota);
  server_ = builder.BuildAndStart();
  if (!server_ || port_ == 0) {
    throw IoError("cannot listen on '" + options.listen_address +
                  "' (address in use, or not a host:port this machine has)");
  }
  drain_timeout_s_ = options.drain_timeout_s;
  if (auto* health = server_->GetHealthCheckService()) {
    health->SetServingStatus(true);
    service_->SetHealth(health);
  }
  if (options.metrics_address) {
    const Service* service = service_.get();
    metrics_ = std::make_unique<MetricsHttpServer>(*options.metrics_address, [service] {
      return service->counters().PrometheusText() + service->ServiceMetricsText();
    });
  }
}

LocalizerServer::~LocalizerServer() { Shutdown(); }

int LocalizerServer::metrics_port() const { return metrics_ ? metrics_->port() : 0; }

void LocalizerServer::Shutdown() {
  if (shut_down_.exchange(true)) return;
  // Health first (load balancers stop sending), then the sessions stop and gRPC refuses new
  // calls; calls still open at the deadline are cancelled. The metrics server stops last, so a
  // scrape during the drain sees it.
  service_->StartDraining();
  server_->Shutdown(std::chrono::system_clock::now() +
                    std::chrono::duration_cast<std::chrono::system_clock::duration>(
                        std::chrono::duration<double>(drain_timeout_s_)));
  server_->Wait();
  metrics_.reset();
}

void LocalizerServer::Wait() { server_->Wait(); }

const ServerCounters& LocalizerServer::counters() const { return service_->counters(); }

MapRegistry& LocalizerServer::registry() { return service_->registry(); }

}  // namespace evloc::service
