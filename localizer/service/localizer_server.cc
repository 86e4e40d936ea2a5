#include "localizer/service/localizer_server.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <ctime>
#include <deque>
#include <fstream>
#include <memory>
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
#include "core/common/thread_cpu_time.h"
#include "core/geo/geo_trajectory.h"
#include "evloc/localizer.grpc.pb.h"
#include "localizer/service/bounded_queue.h"
#include "localizer/service/client_text.h"
#include "localizer/service/locate_rpc.h"
#include "localizer/service/metrics_http.h"
#include "localizer/service/session.h"
#include "localizer/service/tracking_pool.h"
#include "localizer/service/viewer_board.h"
#include "localizer/service/viewer_http.h"
#include "localizer/wire/percentile.h"
#include "localizer/wire/status_name.h"

namespace evloc::service {

// ---------------------------------------------------------------------------------------------
// Options and tokens.

void LocalizerServerOptions::Check() const {
  registry_options().Check();
  if (listen_address.empty()) throw InvalidArgumentError("--listen: the address is empty");
  if (max_sessions < 1) throw InvalidArgumentError("--max-sessions must be at least 1");
  if (threads != 0 && threads < max_sessions + 2) {
    throw InvalidArgumentError("--threads must be 0 (automatic) or at least --max-sessions + 2 (" +
                               std::to_string(max_sessions + 2) + "): the unary calls' handlers");
  }
  if (tracking_threads < 0 || tracking_threads > 1024) {
    throw InvalidArgumentError("--tracking-threads must be in [0, 1024] (0: one per core)");
  }
  if (search_threads < 0 || search_threads > 64) {
    throw InvalidArgumentError(
        "--search-threads must be in [0, 64] (0: searching sessions share the tracking workers)");
  }
  if (max_message_bytes < 1024) {
    throw InvalidArgumentError("--max-message-bytes must be at least 1024");
  }
  if (!(idle_timeout_s > 0)) throw InvalidArgumentError("--idle-timeout must be positive");
  if (queue_packets < 2) throw InvalidArgumentError("--queue-packets must be at least 2");
  if (!(backpressure_fraction > 0 && backpressure_fraction <= 1)) {
    throw InvalidArgumentError("--backpressure-fraction must be in (0, 1]");
  }
  if (!(searching_events_per_pixel_s >= 0 && searching_events_per_pixel_s <= 1e6)) {
    throw InvalidArgumentError(
        "--searching-event-rate must be 0 (no advice) .. 1e6 events per pixel and second");
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
  if (viewer_address) {
    viewer_options().Check();
    CheckListenSecurity(*viewer_address, listen_security());
  }
  session_limits().Check();
}

ViewerOptions LocalizerServerOptions::viewer_options() const {
  ViewerOptions options;
  options.address = viewer_address.value_or("");
  options.max_clients = viewer_max_clients;
  options.max_rate_hz = viewer_rate_hz;
  return options;
}

ListenSecurity LocalizerServerOptions::listen_security() const {
  return {tls_cert_file.has_value(), auth_tokens_file.has_value(), tls_client_ca_file.has_value(),
          insecure};
}

MapRegistryOptions LocalizerServerOptions::registry_options() const {
  MapRegistryOptions options;
  options.maps_dir = maps_dir;
  options.max_map_memory_bytes = max_map_memory_bytes;
  options.max_tile_memory_bytes = max_map_memory_bytes;
  options.tile_loader_threads = tile_loader_threads;
  options.tile_loader_priority = tile_loader_priority;
  if (keep_maps && map_keep_dir) options.keep_dir = *map_keep_dir;
  return options;
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
  metric("evloc_searching_packets_shed_total", "counter",
         "Event packets thinned into another or dropped unread by sessions searching the map "
         "whose queue was full.",
         packets_shed);
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

std::string TileCacheMetricsText(const TileCacheStats& stats) {
  std::ostringstream text;
  const auto metric = [&text](const char* name, const char* type, const char* help, auto value) {
    text << "# HELP " << name << " " << help << "\n# TYPE " << name << " " << type << "\n"
         << name << " " << value << "\n";
  };
  metric("evloc_tile_hits_total", "counter",
         "Tiles a session newly needed that were resident (sites, docs/api.md).", stats.hits);
  metric("evloc_tile_misses_total", "counter",
         "Tiles a session newly needed that had to be loaded.", stats.misses);
  metric("evloc_tile_loads_total", "counter", "Tiles loaded by the loader threads.", stats.loads);
  metric("evloc_tile_load_failures_total", "counter",
         "Tile loads that failed (missing, damaged or mismatching tile files).",
         stats.load_failures);
  metric("evloc_tile_load_seconds_total", "counter", "Wall time spent loading tiles.",
         stats.load_seconds);
  metric("evloc_tile_load_seconds_max", "gauge", "The longest tile load so far.",
         stats.max_load_seconds);
  metric("evloc_tile_evictions_total", "counter",
         "Unused tiles dropped to meet the --map-memory budget.", stats.evictions);
  metric("evloc_tile_resident_bytes", "gauge", "Memory of the loaded tiles (estimate).",
         stats.resident_bytes);
  metric("evloc_tile_resident", "gauge", "Loaded tiles.", stats.resident_tiles);
  metric("evloc_tile_in_use", "gauge", "Loaded tiles some session uses.", stats.tiles_in_use);
  metric("evloc_tile_pending_loads", "gauge", "Tile loads queued or running.", stats.pending_loads);
  metric("evloc_tile_budget_bytes", "gauge", "The --map-memory budget of the tiles.",
         stats.budget_bytes);
  return text.str();
}

std::string LocalizerServerOptions::Describe() const {
  std::ostringstream text;
  text << "maps: " << maps_dir.string() << "\n"
       << "listen: " << listen_address << "\n"
       << "max-sessions: " << max_sessions << "\n"
       << "threads: " << (threads == 0 ? max_sessions + 8 : threads)
       << (threads == 0 ? " (automatic)" : "") << "\n"
       << "tracking-threads: " << TrackingPool::ThreadsFor(tracking_threads)
       << (tracking_threads == 0 ? " (one per core)" : "") << "\n"
       << "search-threads: " << search_threads << "\n"
       << "search-priority: " << ThreadPriorityName(search_priority) << "\n"
       << "max-message-bytes: " << max_message_bytes << "\n"
       << "idle-timeout: " << idle_timeout_s << " s\n"
       << "queue-packets: " << queue_packets << "\n"
       << "backpressure-fraction: " << backpressure_fraction << "\n"
       << "searching-event-rate: " << searching_events_per_pixel_s
       << " events per pixel and second\n"
       << "map-memory: " << max_map_memory_bytes << " bytes (maps; and the tiles of sites)\n"
       << "map-keep-dir: "
       << (!keep_maps     ? std::string("none")
           : map_keep_dir ? map_keep_dir->string()
                          : std::string("a private folder under the temporary directory"))
       << "\n"
       << "tile-loader-threads: " << tile_loader_threads << "\n"
       << "tile-loader-priority: " << ThreadPriorityName(tile_loader_priority) << "\n"
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
       << "viewer: "
       << (viewer_address ? *viewer_address + " (" + std::to_string(viewer_max_clients) +
                                " pages, " + std::to_string(viewer_rate_hz) + " Hz)"
                          : std::string("none"))
       << "\n"
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
       << " Hz, max-points " << tracker.max_points << ", tau " << tracker.decay_time_s
       << " s, binning "
       << (tracker.binning == tracking::kAutoBinning ? std::string("auto")
                                                     : std::to_string(tracker.binning))
       << "\n"
       << "stamp-at-step-time: " << (tracker.stamp_at_step_time ? "on" : "off") << "\n"
       << "motion-prior: " << tracker.motion_prior_velocity_sigma_mps << " m/s, "
       << tracker.motion_prior_angular_velocity_sigma_dps << " deg/s"
       << (tracker.motion_prior_velocity_sigma_mps > 0 ||
                   tracker.motion_prior_angular_velocity_sigma_dps > 0
               ? ""
               : " (none)")
       << "\n";
  return text.str();
}

// ---------------------------------------------------------------------------------------------
// The service.

// How long the drain keeps the connections open after the last call ended (see Shutdown).
constexpr auto kFinalStatusLinger = std::chrono::milliseconds(500);
// The retry delay a draining server asks of the clients it stops or refuses
// (grpc-retry-pushback-ms): the linger and as much again for the other calls to end, so that a
// client's next attempt finds this replica's connections closed and its channel moves on to
// another address, instead of being refused by the same replica again and again.
constexpr auto kDrainRetryPushback = 2 * kFinalStatusLinger;

class LocalizerServer::Service final
    : public api::Localizer::WithCallbackMethod_Track<api::Localizer::Service> {
 public:
  Service(const LocalizerServerOptions& options, std::shared_ptr<Logger> logger)
      : options_(options),
        session_limits_(options.session_limits()),
        logger_(std::move(logger)),
        keep_folder_(options.keep_maps && !options.map_keep_dir
                         ? std::make_unique<PrivateTempFolder>("evloc-kept-maps",
                                                               "the last good map versions")
                         : nullptr),
        registry_(RegistryOptions(options)),
        memory_(options.max_memory_bytes),
        pool_(TrackingPool::ThreadsFor(options.tracking_threads), options.search_threads,
              options.search_priority) {
    if (options.auth_tokens_file) {
      tokens_ = std::make_unique<TokenFile>(
          *options.auth_tokens_file, std::chrono::seconds(options.reload_interval_s),
          [this](LogLevel level, const std::string& line) { Log(level, line); });
    }
    if (options.viewer_address) viewer_board_ = std::make_unique<ViewerBoard>();
    // Background threads whose lower priority the kernel refused (SetThisThreadPriority).
    const auto warn_refused = [this](const std::string& threads, const std::string& flag,
                                     ThreadPriority priority) {
      Log(LogLevel::kWarning,
          "the kernel refused the " + threads + "' priority (" + flag + " " +
              ThreadPriorityName(priority) + "); they run at " +
              (priority == ThreadPriority::kIdle ? "nice 19" : "the tracking workers' priority"));
    };
    if (!pool_.background_priority_applied()) {
      warn_refused("search workers", "--search-priority", options.search_priority);
    }
    if (!registry_.tile_cache().stats().loader_priority_applied) {
      warn_refused("tile loaders", "--tile-loader-priority", options.tile_loader_priority);
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

  // Track calls from TrackCall::Begin until their final status is handed to gRPC or they are done
  // (refused ones too): the drain waits for them.
  void CallBegun() {
    std::lock_guard<std::mutex> lock(calls_mutex_);
    ++calls_open_;
  }
  void CallEnded() {
    {
      std::lock_guard<std::mutex> lock(calls_mutex_);
      --calls_open_;
    }
    calls_done_.notify_all();
  }
  int calls_open() {
    std::lock_guard<std::mutex> lock(calls_mutex_);
    return calls_open_;
  }
  // Waits until every Track call has ended or `deadline` passes; true when none is.
  bool WaitForCalls(std::chrono::steady_clock::time_point deadline) {
    std::unique_lock<std::mutex> lock(calls_mutex_);
    return calls_done_.wait_until(lock, deadline, [this] { return calls_open_ == 0; });
  }

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
        << "\n"
        << "# HELP evloc_log_records_dropped_total Log records dropped because the log's queue "
           "was full (the log's output could not keep up).\n"
        << "# TYPE evloc_log_records_dropped_total counter\nevloc_log_records_dropped_total "
        << (logger_ ? logger_->dropped() : 0) << "\n"
        << TileCacheMetricsText(registry_.tile_cache().stats());
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
        Log(LogLevel::kWarning,
            "ListMaps: skipping map '" + EscapeForLog(name) +
                "': " + EscapeForLog(error.what(), 1024),
            {{"map", EscapeForLog(name)}, {"error", EscapeForLog(error.what(), 1024)}});
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
      Log(LogLevel::kWarning,
          "GetMap '" + EscapeForLog(request->name()) +
              "': cannot load: " + EscapeForLog(error.what(), 1024),
          {{"map", EscapeForLog(request->name())}, {"error", EscapeForLog(error.what(), 1024)}});
      return Reject(ForClient({grpc::StatusCode::FAILED_PRECONDITION,
                               std::string("the map cannot be loaded: ") + error.what()}));
    }
    return grpc::Status::OK;
  }

  // A Track stream (callback API: no thread of its own; defined below with TrackCall).
  grpc::ServerBidiReactor<api::TrackRequest, api::TrackResponse>* Track(
      grpc::CallbackServerContext* context) override;

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
      Log(LogLevel::kInfo,
          "Locate on map '" + EscapeForLog(request->map_name()) +
              "' rejected: " + EscapeForLog(status.error_message(), 1024),
          {{"map", EscapeForLog(request->map_name())},
           {"code", wire::StatusCodeName(status.error_code())},
           {"error", EscapeForLog(status.error_message(), 1024)}});
      return Reject(ForClient(status));
    }
    const char* found = response->status() == api::FOUND ? "FOUND" : "NOT_FOUND";
    Log(LogLevel::kInfo,
        "Locate on map '" + EscapeForLog(request->map_name()) + "': " + found + " in " +
            std::to_string(response->locate_ms()) + " ms",
        {{"map", EscapeForLog(request->map_name())},
         {"status", found},
         {"locate_ms", response->locate_ms()}});
    return status;
  }

  // Counts a rejected request and passes its status through.
  grpc::Status Reject(grpc::Status status) {
    ++counters_.rejected;
    return status;
  }

  // Checks the bearer token when tokens are configured; `token` receives it.
  grpc::Status Authenticate(const grpc::ServerContextBase& context,
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

  // Logs a record (core/common/log.h); `session` 0: none. Never blocks on the log's output.
  void Log(LogLevel level, std::string_view message, std::initializer_list<LogField> fields = {},
           uint64_t session = 0) const {
    if (logger_) logger_->Log(level, message, fields, session);
  }
  void Log(LogLevel level, std::string_view message, const std::vector<LogField>& fields,
           uint64_t session) const {
    if (logger_) logger_->Log(level, message, fields, session);
  }

  const LocalizerServerOptions& options() const { return options_; }
  MapRegistry& registry() { return registry_; }
  // The registry's options: the server's, with the private keep folder and the log's warnings.
  MapRegistryOptions RegistryOptions(const LocalizerServerOptions& options) {
    MapRegistryOptions registry = options.registry_options();
    if (keep_folder_) registry.keep_dir = keep_folder_->path();
    registry.warn = [this](const std::string& line) {
      Log(LogLevel::kWarning, EscapeForLog(line, 2048));
    };
    return registry;
  }
  ServerCounters& counters() { return counters_; }
  const ServerCounters& counters() const { return counters_; }
  const SessionLimits& session_limits() const { return session_limits_; }
  uint64_t NextSessionId() { return ++last_session_id_; }
  // The sessions as the live viewer shows them (null without --viewer).
  ViewerBoard* viewer_board() { return viewer_board_.get(); }
  // The token file (null without --auth-tokens).
  TokenFile* tokens() { return tokens_.get(); }
  // The tracking workers every session's work runs on.
  TrackingPool& pool() { return pool_; }
  // The one timer of every stream's deadlines.
  SharedTimer& timer() { return timer_; }

 private:
  LocalizerServerOptions options_;
  SessionLimits session_limits_;
  std::shared_ptr<Logger> logger_;
  std::unique_ptr<PrivateTempFolder> keep_folder_;
  MapRegistry registry_;
  std::unique_ptr<TokenFile> tokens_;
  std::unique_ptr<ViewerBoard> viewer_board_;
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
  std::mutex calls_mutex_;
  std::condition_variable calls_done_;
  int calls_open_ = 0;
  // Declared last, stopped first: their threads may hold the last reference to a call, whose
  // destruction releases memory_ reservations.
  TrackingPool pool_;
  SharedTimer timer_;
};

namespace {

using TrackReactor = grpc::ServerBidiReactor<api::TrackRequest, api::TrackResponse>;

// One Track call on gRPC's callback API: no thread of its own. gRPC's read callback validates and
// queues each request (a bounded queue: it never waits for tracking); the call is a serial job of
// the server's tracking pool, which runs its queued requests one per slice (never two workers at
// once, sessions taking turns) and hands each pose to the stream as soon as its step has run;
// writes go out one at a time from a short queue of responses (a session whose responses are not
// being read stops being tracked until they are, so its own queue overflows or its idle timeout
// ends it); the server's one timer thread checks the call every poll period (handshake timeout,
// idle timeout, drain). The session opens (map load) on the pool too. Between steps the tracker
// asks whether to stop (reader ended with an error, the drain, the CPU budget), so no request
// keeps a core busy after its session ended.
class TrackCall final : public TrackReactor,
                        public TrackingPool::Job,
                        public std::enable_shared_from_this<TrackCall> {
 public:
  TrackCall(LocalizerServer::Service& service, grpc::CallbackServerContext* context)
      : service_(service),
        options_(service.options()),
        context_(context),
        inbound_(static_cast<size_t>(options_.queue_packets),
                 static_cast<uint64_t>(options_.queue_events)),
        backpressure_threshold_(
            std::max<size_t>(1, static_cast<size_t>(options_.backpressure_fraction *
                                                    static_cast<double>(options_.queue_packets)))),
        backpressure_event_threshold_(std::max<uint64_t>(
            1, static_cast<uint64_t>(options_.backpressure_fraction *
                                     static_cast<double>(options_.queue_events)))) {}

  ~TrackCall() override { CloseViewer(); }

  // Starts the call; `self` owns it until gRPC calls OnDone.
  void Begin(std::shared_ptr<TrackCall> self) {
    self_ = std::move(self);
    service_.CallBegun();
    call_start_ = Clock::now();
    last_change_ = call_start_;
    if (grpc::Status status = service_.Authenticate(*context_, &token_); !status.ok()) {
      FinishCall(status);
      return;
    }
    peer_ = PeerHost(context_->peer());
    if (grpc::Status status = service_.OpenStream(peer_); !status.ok()) {
      FinishCall(status);
      return;
    }
    stream_open_ = true;
    ScheduleCheck();
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    ++progress_;
    if (finish_called_) return;
    if (!handshake_done_) {
      handshake_done_ = true;
      Handshake(ok);
      return;
    }
    if (!ok) {
      grpc::Status status;
      if (context_->IsCancelled()) {
        std::lock_guard<std::mutex> lock(mutex_);
        if (!worker_status_.ok()) {
          status = worker_status_;
        } else if (idle_) {
          status = IdleStatus();
        } else {
          status = {grpc::StatusCode::CANCELLED, "the client cancelled or went away"};
        }
      }
      EndReading(status);
      return;
    }
    if (service_.draining()) {
      EndReading(DrainingStatus());
      return;
    }
    InboundItem item;
    item.received = Clock::now();
    if (grpc::Status status = validator_->Accept(request_, &item.item); !status.ok()) {
      EndReading(status);
      return;
    }
    packets_read_ = validator_->decoder().packets();
    raw_time_adjustments_ = validator_->decoder().raw_time_adjustments();
    MemoryBudget& memory = service_.memory();
    const uint64_t events = item.item.events.size();
    const int64_t bytes = static_cast<int64_t>(events) * kDecodedEventBytes +
                          static_cast<int64_t>(item.item.gray.total()) +
                          static_cast<int64_t>(item.item.depth_m.total() * sizeof(float));
    std::optional<MemoryBudget::Reservation> reservation = memory.TryReserve(bytes);
    if (!reservation) {
      ++service_.counters().limited;
      EndReading({grpc::StatusCode::RESOURCE_EXHAUSTED,
                  "the server's memory budget for queued events (" +
                      std::to_string(memory.limit()) +
                      " bytes, evloc-localizer --max-memory) is used up; retry later or use "
                      "another server"});
      return;
    }
    item.reservation = std::move(*reservation);
    latest_end_t_ns_ = item.item.t_ns;
    if (catching_up_ && inbound_.size() * 4 <= inbound_.capacity()) catching_up_ = false;
    if ((searching_ || catching_up_) && item.item.kind == SessionItem::Kind::kEvents &&
        inbound_.WouldBeFull(events)) {
      if (ThinIntoQueue(item.item, &item.reservation)) {
        service_.UpdateHealth();
        NoteQueueLevel();
        Wake();
        ReadNext();
        return;
      }
      // Dropping is for a search only: a gap in a tracked stream can give wrong poses (a 640x480
      // run tracked 12.7 cm off after one); a session catching up overflows as any other.
      if (searching_) DropWhileSearching();
    }
    const PushResult pushed = inbound_.TryPush(std::move(item), events);
    if (pushed == PushResult::kFull) {
      EndReading(
          {grpc::StatusCode::RESOURCE_EXHAUSTED,
           "the session's queue of " + std::to_string(inbound_.capacity()) + " packets / " +
               std::to_string(inbound_.max_weight()) +
               " events overflowed: the tracker is slower than the stream; send at real "
               "time, lower the step rate or max_points, or wait for Backpressure to clear"});
      return;
    }
    if (pushed == PushResult::kClosed) {  // The worker stopped; its status follows.
      EndReading(grpc::Status::OK);
      return;
    }
    service_.UpdateHealth();
    NoteQueueLevel();
    Wake();
    ReadNext();
  }

  // A session searching the map (it has no pose to keep) whose queue is full sheds events
  // instead of overflowing. First it thins: the new packet's every kSearchThinning-th event goes
  // into the queue's last event packet, which keeps the events continuous in time (a search
  // follows its best candidate pose from step to step and verifies on consecutive steps, and a
  // gap of 100 ms loses both; it found the camera on as few as a quarter of the events,
  // docs/relocalization.md). That costs the reader a quarter of the packet's copy, at normal
  // priority; thinning the whole queue there cost the sessions beside it 1.5x their p99
  // latency. Only when the session is more than kMaxSearchLagNs behind, or the queue's events
  // are at their bound, does it drop the older half of its queued event packets: the steps of
  // the dropped packets run on the next ones with fewer events. Frames, hints and GNSS fixes
  // are never thinned, and one at the front stops the dropping.
  static constexpr size_t kSearchThinning = 4;
  static constexpr int64_t kMaxSearchLagNs = 1'000'000'000;
  // Returns true when `incoming` went, thinned, into the queue's last packet (and its share of
  // the memory budget with it).
  bool ThinIntoQueue(const SessionItem& incoming, MemoryBudget::Reservation* reservation) {
    // A search may fall behind by kMaxSearchLagNs before it drops; a session catching up
    // overflows instead, when not even this is left.
    if (searching_ && latest_end_t_ns_ - tracked_end_t_ns_.load() > kMaxSearchLagNs) return false;
    const size_t events = incoming.events.size();
    const size_t kept = (events + kSearchThinning - 1) / kSearchThinning;
    const bool appended = inbound_.TryAppendToBack(
        kept, [](const InboundItem& last) { return last.item.kind == SessionItem::Kind::kEvents; },
        [&](InboundItem& last) {
          AppendThinnedEvents(&last.item, incoming, kSearchThinning);
          last.appended_reservations.push_back(std::move(*reservation));
          last.thinning = kSearchThinning;  // partly; not folded further
        });
    if (appended) CountShed(1, events - kept);
    return appended;
  }
  // The worker's side, at the search's idle priority (or while catching up): before each
  // packet, a queue more than half full is thinned as a whole, each pair of consecutive event
  // packets of equal thinning folded into one with every other event of the two, down to one
  // in kSearchThinning. That keeps room for the reader, so that it thins or drops only while
  // the worker is held up (an image request of 0.3-0.5 s).
  void FoldQueue() {
    const auto [packets, events] = inbound_.FoldPairs(
        [](const InboundItem& a, const InboundItem& b) {
          return a.item.kind == SessionItem::Kind::kEvents &&
                 b.item.kind == SessionItem::Kind::kEvents && a.thinning == b.thinning &&
                 a.thinning < static_cast<int>(kSearchThinning);
        },
        [](InboundItem& a, InboundItem&& b) -> uint64_t {
          FoldEventPackets(&a.item, b.item);
          a.thinning *= 2;
          // b's share of the memory budget goes with it; a's covers the folded pair.
          return a.item.events.size();
        });
    CountShed(packets, events);
  }
  void DropWhileSearching() {
    const auto [packets, events] = inbound_.DropFront(
        std::max<size_t>(1, inbound_.size() / 2),
        [](const InboundItem& queued) { return queued.item.kind == SessionItem::Kind::kEvents; });
    CountShed(packets, events);
  }
  void CountShed(uint64_t packets, uint64_t events) {
    if (packets == 0) return;
    if (packets_shed_ == 0) {
      service_.Log(LogLevel::kInfo,
                   "session " + std::to_string(id_) +
                       ": searching and behind its stream: thinning its newest event packets "
                       "and, when that is not enough, dropping the oldest (SessionEnd.packets_shed "
                       "and events_shed count them)",
                   {{"event", "shedding"}}, id_);
    }
    packets_shed_ += packets;
    events_shed_ += events;
    service_.counters().packets_shed += static_cast<int64_t>(packets);
  }

  void OnWriteDone(bool ok) override {
    api::TrackResponse* next = nullptr;
    bool finish = false;
    bool wake = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (ok) {
        ++progress_;
        if (outbound_.front().pose) write_us_.Add(MicrosecondsSince(write_start_));
        outbound_.pop_front();
        wake = outbound_.size() + 1 == kMaxOutbound;  // A session waiting for writes may go on.
      } else {
        write_failed_ = true;
        stop_requested_ = true;
        outbound_.clear();
        wake = true;
      }
      write_in_flight_ = false;
      if (!outbound_.empty()) {
        write_in_flight_ = true;
        next = PrepareWrite(outbound_.front());
      } else if (finish_pending_) {
        finish_pending_ = false;
        finish = true;
      }
    }
    if (next) StartWrite(next);
    if (finish) FinishStream();
    if (wake) Wake();
  }

  void OnDone() override {
    {
      std::lock_guard<std::recursive_mutex> lock(context_mutex_);
      done_ = true;
    }
    CountEnded();
    std::shared_ptr<TrackCall> self = std::move(self_);  // May destroy the call (last owner).
  }

  // While searching the map, the session's slices run on the pool's background workers
  // (--search-threads), so that its long search steps never hold a worker that tracking sessions
  // wait for.
  bool background() const override { return searching_.load(std::memory_order_relaxed); }

  // Runs on a worker of the tracking pool, never two at once: opens the session, then tracks one
  // queued request per slice; ends the call when the session is over.
  bool RunSlice() override {
    if (finish_called_) return false;
    if (!opened_) {
      if (!open_requested_) return false;
      Open();
      return false;
    }
    if (draining_ && !worker_failed_) {
      // The drain: a session whose client had half-closed and that has nothing left ends with its
      // SessionEnd, every other one with UNAVAILABLE "draining" (the step it ran was its last).
      if (!(reader_ended_ && reader_status_.ok() && inbound_.drained())) {
        FailFromWorker(DrainingStatus());
      }
    }
    if (!worker_failed_ && !write_failed_ && !stop_requested_) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (outbound_.size() >= kMaxOutbound) return false;  // OnWriteDone wakes the job.
      }
      if (std::optional<InboundItem> item = inbound_.TryPop()) {
        Track(*item);
        return true;  // The next slice tracks the next request or ends the session.
      }
    }
    if (worker_failed_ || write_failed_ || (reader_ended_ && inbound_.drained())) EndSession();
    return false;
  }

 private:
  using Clock = std::chrono::steady_clock;

  // An item from the stream reader to the tracking pool.
  struct InboundItem {
    // The validated request.
    SessionItem item;
    // When the reader received the message.
    Clock::time_point received;
    // Its share of the server's memory budget (released once tracked, or when dropped).
    MemoryBudget::Reservation reservation;
    // The shares of packets thinned into this one (ThinIntoQueue), released with it.
    std::vector<MemoryBudget::Reservation> appended_reservations;
    // Events of it kept one in `thinning` (FoldQueue, ThinIntoQueue; 1: as received).
    int thinning = 1;
  };

  // A response waiting to be written.
  struct Outbound {
    api::TrackResponse response;
    // A PoseUpdate: its latency is measured when its write starts.
    bool pose = false;
    // When its request was received and taken from the queue (poses).
    Clock::time_point received;
    Clock::time_point dequeued;
    // A pose without a trusted estimate (LOST, INITIALIZING, RELOCALIZING).
    bool no_estimate = false;
  };

  // Responses a session may have waiting for the stream; beyond it the session is not tracked
  // until its client reads.
  static constexpr size_t kMaxOutbound = 64;

  // How long a draining session's call may stay open before it is cancelled: half the drain
  // timeout, at least 1 s. A session stops within a step of the drain, but its last responses
  // and status go out only as fast as its client reads them (on a loaded machine that took over
  // 1 s); the other half is left for the cancellations and the final statuses.
  Clock::duration DrainReadWait() const {
    return std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(std::max(1.0, 0.5 * options_.drain_timeout_s)));
  }

  static double MicrosecondsSince(Clock::time_point start) {
    return std::chrono::duration<double, std::micro>(Clock::now() - start).count();
  }

  // "ipv4:1.2.3.4:5678" -> "ipv4:1.2.3.4", "ipv6:[::1]:5678" -> "ipv6:[::1]": what the per-peer
  // limits count (a client opens each connection from another port).
  static std::string PeerHost(const std::string& peer) {
    if (peer.rfind("ipv4:", 0) != 0 && peer.rfind("ipv6:", 0) != 0) return peer;
    const size_t colon = peer.rfind(':');
    return colon > 5 ? peer.substr(0, colon) : peer;
  }

  // CPU time of the calling thread, seconds.
  static double ThreadCpuSeconds() { return static_cast<double>(ThreadCpuTimeNs()) * 1e-9; }

  // The status of a session stopped by the drain.
  static grpc::Status DrainingStatus() {
    return {grpc::StatusCode::UNAVAILABLE,
            "draining: the server is shutting down; start a new session on another server (from "
            "the last pose received)"};
  }

  // The status of a session the idle check cancelled.
  grpc::Status IdleStatus() const {
    return {grpc::StatusCode::CANCELLED,
            "nothing received, tracked or sent for " + std::to_string(options_.idle_timeout_s) +
                " s (idle timeout: the client sent nothing or stopped reading its responses)"};
  }

  void Wake() { service_.pool().Wake(shared_from_this()); }

  // Starts reading the next request unless the call is finishing (the pool may end the call
  // while gRPC's read callback runs).
  void ReadNext() {
    std::lock_guard<std::recursive_mutex> lock(read_mutex_);
    if (!finish_called_) StartRead(&request_);
  }

  // The first message: a SessionStart that the token may use, and a free slot; the session is
  // then opened on the pool (it may load a map).
  void Handshake(bool received) {
    if (!received) {
      if (handshake_expired_) {
        FinishCall({grpc::StatusCode::CANCELLED,
                    "no SessionStart within " + std::to_string(options_.handshake_timeout_s) +
                        " s of the call (evloc-localizer --handshake-timeout)"});
      } else {
        FinishCall({grpc::StatusCode::CANCELLED, "the stream ended before a SessionStart"});
      }
      return;
    }
    if (!request_.has_start()) {
      FinishCall({grpc::StatusCode::FAILED_PRECONDITION,
                  "the first message of a Track stream must be a SessionStart"});
      return;
    }
    if (grpc::Status status = service_.Authorize(token_, request_.start().map_name());
        !status.ok()) {
      FinishCall(status);
      return;
    }
    if (grpc::Status status = service_.AdmitSession(peer_, token_); !status.ok()) {
      FinishCall(status);
      return;
    }
    admitted_ = true;
    start_ = request_.start();
    // Without a pose the session searches from its first step (its queue may fill while the map
    // opens).
    searching_ = !start_.has_initial_world_from_cam();
    open_requested_ = true;
    Wake();
  }

  // Opens the session (on the pool): map, settings, tracker; sends SessionStarted and starts
  // reading the requests.
  void Open() {
    const auto open_start = Clock::now();
    OpenedSession opened;
    if (grpc::Status status =
            OpenSession(start_, service_.registry(), service_.session_limits(), &opened);
        !status.ok()) {
      FinishCall(status);
      return;
    }
    ++progress_;
    const std::shared_ptr<const LoadedMap>& map = opened.map;
    const SessionSettings& settings = opened.settings;
    tracker_ = std::move(opened.tracker);
    initial_t_ns_ = settings.initial_t_ns;
    validator_ = std::make_unique<RequestValidator>(settings, service_.session_limits());
    id_ = service_.NextSessionId();
    ++service_.counters().sessions_started;
    session_start_ = Clock::now();
    const int64_t open_ms = static_cast<int64_t>(MicrosecondsSince(open_start) / 1000);
    const char* input = tracker_->takes_frames() ? "frames" : "events";
    service_.Log(LogLevel::kInfo,
                 "session " + std::to_string(id_) + " start: map " + map->name + " version " +
                     map->version + " (" + std::to_string(map->map.size()) + " points), client '" +
                     EscapeForLog(start_.client_name()) + "' " + context_->peer() + ", camera " +
                     std::to_string(settings.camera.width) + "x" +
                     std::to_string(settings.camera.height) + ", " + input + ", " +
                     settings.tracker.VariantName() + " at " +
                     std::to_string(settings.tracker.step_rate_hz) + " Hz, opened in " +
                     std::to_string(open_ms) + " ms",
                 {{"event", "start"},
                  {"map", map->name},
                  {"map_version", map->version},
                  {"map_points", map->map.size()},
                  {"client", EscapeForLog(start_.client_name())},
                  {"peer", context_->peer()},
                  {"camera_width", settings.camera.width},
                  {"camera_height", settings.camera.height},
                  {"input", input},
                  {"variant", settings.tracker.VariantName()},
                  {"step_rate_hz", settings.tracker.step_rate_hz},
                  {"open_ms", open_ms}},
                 id_);
    api::TrackResponse started;
    started.mutable_started()->set_session_id(id_);
    *started.mutable_started()->mutable_map() = DescribeMap(*map);
    started.mutable_started()->set_step_rate_hz(settings.tracker.step_rate_hz);
    started.mutable_started()->set_variant(settings.tracker.VariantName());
    started.mutable_started()->set_queue_capacity(static_cast<uint32_t>(inbound_.capacity()));
    started.mutable_started()->set_searching_event_rate(static_cast<uint64_t>(std::llround(
        options_.searching_events_per_pixel_s * static_cast<double>(settings.camera.width) *
        static_cast<double>(settings.camera.height))));
    Send(std::move(started));
    if (ViewerBoard* board = service_.viewer_board()) {
      viewer_ = board->Open(id_, map->name, EscapeForLog(start_.client_name()));
    }
    opened_ = true;
    ReadNext();
  }

  // The reader is done (`status` OK: the client half-closed; else the status that ends the
  // session): what is queued is tracked (OK) or dropped, and the pool ends the session.
  void EndReading(grpc::Status status) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      reader_status_ = std::move(status);
    }
    if (reader_status_.ok()) {
      inbound_.Close();
    } else {
      stop_requested_ = true;
      inbound_.Abort();
    }
    reader_ended_ = true;
    Wake();
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
    // The reader must keep reading: the pool sends the notice after the request it is tracking.
    std::lock_guard<std::mutex> lock(notice_mutex_);
    pending_notice_ = std::move(notice);  // A newer notice replaces one not sent yet.
  }

  // Queues a pending Backpressure notice, if any, for writing.
  void SendPendingNotice() {
    std::optional<api::TrackResponse> notice;
    {
      std::lock_guard<std::mutex> lock(notice_mutex_);
      notice.swap(pending_notice_);
    }
    if (notice) Send(std::move(*notice));
  }

  // Queues `response` for writing and starts the write when none is in flight (dropped once a
  // write failed: the client is gone). A pose carries when its request was received and taken
  // from the queue, and whether it has no trusted pose.
  void Send(api::TrackResponse response, bool pose = false, Clock::time_point received = {},
            Clock::time_point dequeued = {}, bool no_estimate = false) {
    api::TrackResponse* next = nullptr;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (write_failed_) return;
      outbound_.push_back({std::move(response), pose, received, dequeued, no_estimate});
      if (write_in_flight_) return;
      write_in_flight_ = true;
      next = PrepareWrite(outbound_.front());
    }
    // The element stays in place while others are queued behind it; only OnWriteDone of this
    // write removes it.
    StartWrite(next);
  }

  // Just before `next` is handed to gRPC (mutex_ held): a pose gets its latency (received to
  // handed to gRPC) and is counted. Returns the message to write.
  api::TrackResponse* PrepareWrite(Outbound& next) {
    if (next.pose) {
      write_start_ = Clock::now();
      ServerCounters& counters = service_.counters();
      const double latency_us =
          std::chrono::duration<double, std::micro>(write_start_ - next.received).count();
      next.response.mutable_pose()->set_latency_us(latency_us);
      latencies_us_.Add(latency_us);
      queue_us_.Add(
          std::chrono::duration<double, std::micro>(next.dequeued - next.received).count());
      counters.RecordLatency(latency_us);
      ++counters.poses;
      if (next.no_estimate) ++counters.lost_poses;
    }
    return &next.response;
  }

  // Asked by the tracker between steps: true to stop (the reader ended with an error, the
  // drain, a failed write: stop_requested_; the CPU budget: cpu_exceeded_).
  bool ShouldStop() {
    ++progress_;  // A step ran: the session is alive even when one packet takes long.
    if (stop_requested_) return true;
    const double used = cpu_before_item_s_ + (ThreadCpuSeconds() - item_cpu_start_s_);
    cpu_used_s_ = used;
    const double tracked_s =
        std::max(0.0, static_cast<double>(tracker_->advanced_t_ns() - initial_t_ns_) * 1e-9);
    if (used > options_.session_cpu_grace_s + options_.session_cpu_per_second * tracked_s) {
      cpu_exceeded_ = true;
      return true;
    }
    return false;
  }

  // Ends the session from the pool with `status` (the reader stops at its next message).
  void FailFromWorker(grpc::Status status) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      worker_status_ = std::move(status);
    }
    worker_failed_ = true;
    inbound_.Abort();
  }

  // Tracks one queued request and queues its poses for writing.
  void Track(InboundItem& item) {
    ServerCounters& counters = service_.counters();
    const auto dequeued = Clock::now();
    std::vector<tracking::PoseEstimate> estimates;
    std::vector<odometry::PoseSource> sources;
    if ((searching_ || catching_up_) && (inbound_.size() * 2 > inbound_.capacity() ||
                                         inbound_.weight() * 2 > inbound_.max_weight())) {
      FoldQueue();
    }
    item_cpu_start_s_ = ThreadCpuSeconds();
    if (item.item.kind == SessionItem::Kind::kGnssFix && !tracker_->geo()) {
      FailFromWorker({grpc::StatusCode::FAILED_PRECONDITION,
                      "GnssFix: " + MissingGeoAnchorMessage(start_.map_name())});
      return;
    }
    try {
      estimates = tracker_->Process(
          item.item, [this] { return ShouldStop(); }, &sources);
    } catch (const std::exception& error) {
      service_.Log(LogLevel::kError,
                   "session " + std::to_string(id_) +
                       " tracking failed: " + EscapeForLog(error.what(), 1024),
                   {{"event", "failed"}, {"error", EscapeForLog(error.what(), 1024)}}, id_);
      FailFromWorker(grpc::Status(
          grpc::StatusCode::INTERNAL,
          ScrubServerPaths(std::string("tracking failed: ") + error.what(), options_.maps_dir)));
      return;
    }
    cpu_before_item_s_ += ThreadCpuSeconds() - item_cpu_start_s_;
    cpu_used_s_ = cpu_before_item_s_;
    item.reservation.Release();
    service_.UpdateHealth();
    if (item.item.kind == SessionItem::Kind::kFrame) ++frames_;
    if (item.item.kind == SessionItem::Kind::kDepth) ++depth_frames_;
    events_ += item.item.events.size();
    counters.events += static_cast<int64_t>(item.item.events.size());
    tracked_end_t_ns_ = item.item.t_ns;
    ++progress_;
    SendPendingNotice();
    for (size_t i = 0; i < estimates.size(); ++i) {
      const tracking::PoseEstimate& estimate = estimates[i];
      api::TrackResponse response;
      *response.mutable_pose() = PoseUpdateFromEstimate(estimate, tracker_->geo(), sources[i]);
      if (sources[i] == odometry::PoseSource::kOdometry) ++odometry_poses_;
      const bool no_estimate = tracking::HasNoEstimate(estimate.status);
      ++poses_;
      lost_poses_ += no_estimate ? 1 : 0;
      Send(std::move(response), true, item.received, dequeued, no_estimate);
    }
    if (viewer_ && !estimates.empty()) PublishToViewer(estimates.back());
    if (!estimates.empty()) {
      const bool searching = tracking::IsSearching(estimates.back().status);
      if (searching_ && !searching) catching_up_ = true;
      searching_ = searching;
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
        inbound_.Abort();  // The reader ended the session (or a write failed); its status stands.
      }
    }
  }

  // Publishes a step's pose to the viewer (one short lock) and, when a viewer asked for it, the
  // time surface with the map reprojected at that pose (docs/viewer.md).
  void PublishToViewer(const tracking::PoseEstimate& estimate) {
    viewer_->Publish({estimate.t_ns, estimate.world_from_cam, estimate.status});
    if (viewer_->surface_requested()) {
      viewer_->PublishSurface(tracker_->SurfacePicture(estimate.world_from_cam, estimate.t_ns));
    }
  }

  // Removes the session from the viewer.
  void CloseViewer() {
    if (!viewer_) return;
    if (ViewerBoard* board = service_.viewer_board()) board->Close(id_);
    viewer_.reset();
  }

  // Ends an opened session (on the pool): its SessionEnd when it ended well, the log line, the
  // final status.
  void EndSession() {
    CloseViewer();
    grpc::Status status;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      status = reader_ended_ && !reader_status_.ok() ? reader_status_ : worker_status_;
    }
    // A notice left by the reader goes out also when the session ends with an error (an
    // overflow follows its notice).
    SendPendingNotice();
    if (status.ok()) {
      api::TrackResponse end;
      api::SessionEnd* totals = end.mutable_end();
      totals->set_packets(packets_read_);
      totals->set_events(events_);
      totals->set_frames(frames_);
      totals->set_depth_frames(depth_frames_);
      totals->set_odometry_poses(odometry_poses_);
      totals->set_backpressure_notices(backpressure_notices_);
      totals->set_raw_time_adjustments(raw_time_adjustments_);
      totals->set_packets_shed(packets_shed_.load());
      totals->set_events_shed(events_shed_.load());
      totals->set_duration_s(std::chrono::duration<double>(Clock::now() - session_start_).count());
      totals->set_poses(poses_);
      totals->set_lost_poses(lost_poses_);
      {
        // Of the poses handed to gRPC so far (all but the last few queued behind a write).
        std::lock_guard<std::mutex> lock(mutex_);
        totals->set_latency_p50_us(latencies_us_.Percentile(0.5));
        totals->set_latency_p99_us(latencies_us_.Percentile(0.99));
      }
      Send(std::move(end));
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (status.ok() && idle_) status = IdleStatus();
      if (status.ok() && write_failed_) {
        status = grpc::Status(grpc::StatusCode::CANCELLED, "the client went away");
      }
    }
    const auto us = [](const wire::LogHistogram& histogram, double fraction) {
      return std::to_string(static_cast<int64_t>(histogram.Percentile(fraction)));
    };
    std::string figures;
    const double duration_s = std::chrono::duration<double>(Clock::now() - session_start_).count();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      figures = "latency p50 " + us(latencies_us_, 0.5) + " us p99 " + us(latencies_us_, 0.99) +
                " us (in the queue p50 " + us(queue_us_, 0.5) + " p99 " + us(queue_us_, 0.99) +
                " us; stream write p50 " + us(write_us_, 0.5) + " p99 " + us(write_us_, 0.99) +
                " us)";
      end_fields_ = {{"event", "end"},
                     {"code", wire::StatusCodeName(status.error_code())},
                     {"error", EscapeForLog(status.error_message(), 1024)},
                     {"packets", packets_read_.load()},
                     {"events", events_},
                     {"frames", frames_},
                     {"poses", poses_},
                     {"lost_poses", lost_poses_},
                     {"latency_p50_us", latencies_us_.Percentile(0.5)},
                     {"latency_p99_us", latencies_us_.Percentile(0.99)},
                     {"queue_p50_us", queue_us_.Percentile(0.5)},
                     {"queue_p99_us", queue_us_.Percentile(0.99)},
                     {"write_p50_us", write_us_.Percentile(0.5)},
                     {"write_p99_us", write_us_.Percentile(0.99)},
                     {"backpressure_notices", backpressure_notices_.load()},
                     {"cpu_s", cpu_used_s_.load()},
                     {"duration_s", duration_s}};
    }
    end_log_ = "session " + std::to_string(id_) + " end: " +
               (status.ok() ? std::string("OK")
                            : std::string(wire::StatusCodeName(status.error_code())) + ": " +
                                  EscapeForLog(status.error_message(), 1024)) +
               "; " + std::to_string(packets_read_.load()) + " packets, " +
               std::to_string(events_) + " events, " + std::to_string(frames_) + " frames, " +
               std::to_string(poses_) + " poses (" + std::to_string(lost_poses_) + " LOST), " +
               figures + ", " + std::to_string(backpressure_notices_) + " backpressure notices, " +
               std::to_string(cpu_used_s_.load()) + " CPU s, " + std::to_string(duration_s) + " s";
    FinishCall(status);
  }

  // Ends the call with `status` (once): frees its session and stream slots, counts and logs it,
  // and finishes the stream once the responses queued before it are written.
  void FinishCall(const grpc::Status& status) {
    {
      // No read starts after this (ReadNext); one already started is allowed with Finish.
      std::lock_guard<std::recursive_mutex> lock(read_mutex_);
      if (finish_called_.exchange(true)) return;
    }
    if (admitted_) service_.EndSession(peer_, token_);
    if (stream_open_) service_.CloseStream(peer_);
    const grpc::Status client_status = service_.ForClient(status);
    if (!client_status.ok()) {
      ++service_.counters().rejected;
      if (id_ == 0) {
        service_.Log(LogLevel::kInfo,
                     "Track from " + context_->peer() +
                         " refused: " + wire::StatusCodeName(client_status.error_code()) + ": " +
                         EscapeForLog(client_status.error_message(), 1024),
                     {{"event", "refused"},
                      {"peer", context_->peer()},
                      {"code", wire::StatusCodeName(client_status.error_code())},
                      {"error", EscapeForLog(client_status.error_message(), 1024)}});
      }
    }
    if (!end_log_.empty()) service_.Log(LogLevel::kInfo, end_log_, end_fields_, id_);
    // A session the drain stopped, or a call refused while draining, is asked to retry only once
    // this replica has closed its connections (kDrainRetryPushback).
    if (client_status.error_code() == grpc::StatusCode::UNAVAILABLE && service_.draining()) {
      std::lock_guard<std::recursive_mutex> lock(context_mutex_);
      if (!done_) {
        context_->AddTrailingMetadata("grpc-retry-pushback-ms",
                                      std::to_string(kDrainRetryPushback.count()));
      }
    }
    bool finish = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      final_status_ = client_status;
      if (write_in_flight_ || !outbound_.empty()) {
        finish_pending_ = true;
      } else {
        finish = true;
      }
    }
    if (finish) FinishStream();
  }

  // Hands the final status to gRPC (once the responses before it are written).
  void FinishStream() {
    Finish(final_status_);
    CountEnded();
  }

  // Tells the service (once) that the call has ended for its client: its final status is handed
  // to gRPC, or the call is done without one. gRPC calls OnDone only when the client's side is
  // closed too, which a streaming client does after it has read the status.
  void CountEnded() {
    if (!counted_ended_.exchange(true)) service_.CallEnded();
  }

  // Schedules the next check of the call on the server's timer.
  void ScheduleCheck() {
    const auto seconds = [](double s) {
      return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
    };
    const auto poll = std::min<Clock::duration>(
        std::min(seconds(options_.idle_timeout_s), seconds(options_.handshake_timeout_s)) / 10,
        std::chrono::milliseconds(100));
    service_.timer().Schedule(Clock::now() + poll, [weak = weak_from_this()] {
      if (std::shared_ptr<TrackCall> call = weak.lock()) call->Check();
    });
  }

  // On the timer thread, every poll period until the call is done: cancels the call (once) when
  // the first message did not arrive within the handshake timeout, or when progress_ did not
  // change for the idle timeout; passes the drain on to the session (stop_requested_) and
  // cancels a call still waiting for its first message, or still open 1 s into the drain.
  void Check() {
    std::lock_guard<std::recursive_mutex> lock(context_mutex_);
    if (done_) return;
    const auto seconds = [](double s) {
      return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
    };
    const auto now = Clock::now();
    if (service_.draining()) {
      if (!draining_) {
        draining_ = true;
        stop_requested_ = true;
        drain_start_ = now;
        Wake();
      }
      if (!cancelled_ && (!handshake_done_ || now - drain_start_ > DrainReadWait())) {
        cancelled_ = true;
        context_->TryCancel();
      }
    }
    if (!handshake_done_) {
      if (!cancelled_ && now - call_start_ > seconds(options_.handshake_timeout_s)) {
        cancelled_ = true;
        handshake_expired_ = true;
        ++service_.counters().limited;
        context_->TryCancel();
      }
    } else {
      const uint64_t progress = progress_.load();
      if (progress != last_progress_) {
        last_progress_ = progress;
        last_change_ = now;
      } else if (!cancelled_ && now - last_change_ > seconds(options_.idle_timeout_s)) {
        {
          std::lock_guard<std::mutex> state(mutex_);
          idle_ = true;
        }
        cancelled_ = true;
        context_->TryCancel();
      }
    }
    ScheduleCheck();
  }

  LocalizerServer::Service& service_;
  const LocalizerServerOptions& options_;
  grpc::CallbackServerContext* context_;
  // Owns the call from Begin until OnDone.
  std::shared_ptr<TrackCall> self_;
  // The bearer token (with tokens) and the peer's host (per-peer limits).
  std::optional<std::string> token_;
  std::string peer_;
  bool stream_open_ = false;
  std::atomic<bool> admitted_{false};
  // The request being read (one read at a time).
  api::TrackRequest request_;
  // The SessionStart, for the pool to open the session.
  api::SessionStart start_;
  std::atomic<bool> open_requested_{false};
  std::atomic<bool> opened_{false};
  // The last step searched the map (INITIALIZING, RELOCALIZING): the pool runs the session on its
  // background workers (background()).
  std::atomic<bool> searching_{false};
  // The session found its pose with the backlog its search left in the queue: until the queue
  // is down to a quarter, the reader still sheds rather than overflow (ThinIntoQueue).
  std::atomic<bool> catching_up_{false};
  // Event packets thinned into another or dropped, and the events left out, while searching or
  // catching up (ThinIntoQueue and DropWhileSearching on the stream's reader, FoldQueue on the
  // worker).
  std::atomic<uint64_t> packets_shed_{0};
  std::atomic<uint64_t> events_shed_{0};
  std::atomic<uint64_t> id_{0};
  std::unique_ptr<SessionTracker> tracker_;
  // The session's slot on the viewer's board (null without --viewer; the worker's only).
  std::shared_ptr<ViewerSession> viewer_;
  std::unique_ptr<RequestValidator> validator_;
  int64_t initial_t_ns_ = 0;
  Clock::time_point session_start_;
  BoundedQueue<InboundItem> inbound_;

  // Reader state (gRPC's read callbacks, one at a time).
  size_t backpressure_threshold_;
  uint64_t backpressure_event_threshold_;
  bool backpressure_armed_ = true;
  int64_t latest_end_t_ns_ = 0;
  std::atomic<uint64_t> backpressure_notices_{0};
  std::atomic<bool> reader_ended_{false};
  // The decoder's figures (the pool reads them at the end, while the reader may still run).
  std::atomic<uint64_t> packets_read_{0};
  std::atomic<uint64_t> raw_time_adjustments_{0};

  // Tracking state (the pool, one slice at a time).
  std::atomic<int64_t> tracked_end_t_ns_{0};
  uint64_t events_ = 0;
  uint64_t frames_ = 0;
  uint64_t depth_frames_ = 0;
  uint64_t odometry_poses_ = 0;
  uint64_t poses_ = 0;
  uint64_t lost_poses_ = 0;
  double cpu_before_item_s_ = 0;
  double item_cpu_start_s_ = 0;
  std::atomic<double> cpu_used_s_{0};
  bool cpu_exceeded_ = false;
  std::atomic<bool> worker_failed_{false};
  std::string end_log_;
  // Its figures as typed fields (JSON logs).
  std::vector<LogField> end_fields_;

  // A Backpressure notice from the reader that the pool has not sent yet (guarded by
  // notice_mutex_).
  std::mutex notice_mutex_;
  std::optional<api::TrackResponse> pending_notice_;

  // Set once the first message arrived (or the stream ended before it).
  std::atomic<bool> handshake_done_{false};
  // Set by the check when it cancelled a call without a first message in time.
  std::atomic<bool> handshake_expired_{false};
  // Asks the tracker to stop after its current step (the reader ended with an error, the drain,
  // a failed write).
  std::atomic<bool> stop_requested_{false};
  // Set by the check when the server drains.
  std::atomic<bool> draining_{false};
  // Set once FinishCall ran (under read_mutex_, which ReadNext holds to start a read).
  std::atomic<bool> finish_called_{false};
  std::recursive_mutex read_mutex_;
  // Messages read + items tracked + responses written: the idle check's sign of life.
  std::atomic<uint64_t> progress_{0};

  // The idle check's state (the timer thread only).
  Clock::time_point call_start_;
  uint64_t last_progress_ = 0;
  Clock::time_point last_change_;
  Clock::time_point drain_start_;
  bool cancelled_ = false;

  // Guards the context against OnDone: the check cancels only a call that is not done.
  std::recursive_mutex context_mutex_;
  bool done_ = false;

  // The rest is guarded by mutex_: statuses, the responses waiting to be written and the
  // per-pose figures (latency: received to handed to gRPC; time in the queue; stream write),
  // microseconds, fixed-size histograms.
  std::mutex mutex_;
  grpc::Status reader_status_;
  grpc::Status worker_status_;
  grpc::Status final_status_;
  bool idle_ = false;
  std::deque<Outbound> outbound_;
  bool write_in_flight_ = false;
  bool finish_pending_ = false;
  // Set when a write failed (the client is gone); atomic for the pool's unlocked checks.
  std::atomic<bool> write_failed_{false};
  // Set once CountEnded told the service.
  std::atomic<bool> counted_ended_{false};
  Clock::time_point write_start_;
  wire::LogHistogram latencies_us_;
  wire::LogHistogram queue_us_;
  wire::LogHistogram write_us_;
};

}  // namespace

TrackReactor* LocalizerServer::Service::Track(grpc::CallbackServerContext* context) {
  auto call = std::make_shared<TrackCall>(*this, context);
  call->Begin(call);
  return call.get();
}

// ---------------------------------------------------------------------------------------------
// The server.

namespace {

// The logger of a LogFunction: synchronous text lines without a name.
std::shared_ptr<Logger> LoggerOfFunction(LocalizerServer::LogFunction log) {
  if (!log) return nullptr;
  LoggerOptions options;
  options.asynchronous = false;
  return std::make_shared<Logger>(
      "", options, [log = std::move(log)](std::string_view line) { log(std::string(line)); });
}

}  // namespace

LocalizerServer::LocalizerServer(const LocalizerServerOptions& options, LogFunction log)
    : LocalizerServer(options, LoggerOfFunction(std::move(log))) {}

LocalizerServer::LocalizerServer(const LocalizerServerOptions& options,
                                 std::shared_ptr<Logger> logger) {
  options.Check();
  service_ = std::make_unique<Service>(options, std::move(logger));
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  std::shared_ptr<grpc::ServerCredentials> credentials = grpc::InsecureServerCredentials();
  if (options.tls_cert_file) {
    tls_files_ = std::make_unique<ServerTlsFiles>(
        *options.tls_cert_file, *options.tls_key_file, options.tls_client_ca_file,
        options.reload_interval_s,
        [service = service_.get()](LogLevel level, const std::string& line) {
          service->Log(level, line);
        });
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
  if (options.viewer_address) {
    ViewerOptions viewer = options.viewer_options();
    if (options.tls_cert_file) {
      viewer.tls =
          ReadTlsFiles(*options.tls_cert_file, *options.tls_key_file, options.tls_client_ca_file);
    }
    viewer_ = std::make_unique<ViewerServer>(viewer, *service_->viewer_board(),
                                             service_->registry(), service_->tokens());
    service_->Log(LogLevel::kInfo, "viewer: " + std::string(viewer.tls ? "https" : "http") + "://" +
                                       viewer.address.substr(0, viewer.address.rfind(':')) + ":" +
                                       std::to_string(viewer_->port()) + "/");
  }
}

LocalizerServer::~LocalizerServer() { Shutdown(); }

int LocalizerServer::metrics_port() const { return metrics_ ? metrics_->port() : 0; }

int LocalizerServer::viewer_port() const { return viewer_ ? viewer_->port() : 0; }

ViewerBoard* LocalizerServer::viewer_board() { return service_->viewer_board(); }

void LocalizerServer::Shutdown() {
  if (shut_down_.exchange(true)) return;
  // Health first (load balancers stop sending), then the sessions stop and gRPC refuses new
  // calls; calls still open at the deadline are cancelled. The metrics server stops last, so a
  // scrape during the drain sees it.
  //
  // A call is done for gRPC only when its client has closed its side too, and gRPC keeps a
  // connection open until it is closed by the client or cancelled; but as soon as the last call
  // on a connection is done after the shutdown began, it closes the connection, and a connection
  // closed while its client is still sending (a streaming client sends until it reads its final
  // status) is reset by the kernel, which throws away what the client had not read yet: the
  // final status. So gRPC's shutdown starts only after every call has handed its final status
  // to gRPC (or the drain timeout passed) and the clients have had 0.5 s to read it; then it
  // cancels what is left at once.
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(drain_timeout_s_));
  const bool had_calls = service_->calls_open() > 0;
  service_->StartDraining();
  if (had_calls && service_->WaitForCalls(deadline)) {
    std::this_thread::sleep_until(
        std::min(deadline, std::chrono::steady_clock::now() + kFinalStatusLinger));
  }
  server_->Shutdown(std::chrono::system_clock::now());
  server_->Wait();
  viewer_.reset();
  metrics_.reset();
}

void LocalizerServer::Wait() { server_->Wait(); }

const ServerCounters& LocalizerServer::counters() const { return service_->counters(); }

MapRegistry& LocalizerServer::registry() { return service_->registry(); }

}  // namespace evloc::service
