// The evloc localizer gRPC server (proto/evloc/localizer.proto, docs/api.md): the Localizer
// service over a MapRegistry, with one TrackCall object per Track call (gRPC's callback API, its
// work on a fixed pool of tracking workers, its deadlines on one shared timer), gRPC health
// checking and server reflection. Library code: it logs through a callback and throws typed errors.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>

#include "core/common/log.h"
#include "localizer/service/auth.h"
#include "localizer/service/map_registry.h"
#include "localizer/service/session.h"
#include "localizer/service/tracking_pool.h"
#include "localizer/service/viewer_http.h"
#include "localizer/tracking/tracker_options.h"

namespace grpc {
class Server;
}  // namespace grpc

namespace evloc::service {

class MetricsHttpServer;

// The Prometheus text of the sites' tile cache counters (evloc_tile_*; docs/api.md, "Metrics").
std::string TileCacheMetricsText(const TileCacheStats& stats);

// Options of the server; every field is a flag of `evloc-localizer serve`.
struct LocalizerServerOptions {
  // Folder with one subdirectory per map (NAME/map.evmap) (--maps).
  std::filesystem::path maps_dir;
  // Address to listen on, host:port; port 0 lets the OS choose (--listen).
  std::string listen_address = "127.0.0.1:50051";
  // Most Track sessions running at once; more get RESOURCE_EXHAUSTED (--max-sessions).
  int max_sessions = 8;
  // Most threads gRPC may use for the handlers of the unary calls (ListMaps, GetMap, Locate);
  // 0: max_sessions + 8 (--threads). Track streams hold no thread (gRPC's callback API): their
  // work runs on the tracking pool below.
  int threads = 0;
  // Tracking workers shared by every session (a session runs on one at a time, sessions take
  // turns one request each); 0: one per core (--tracking-threads).
  int tracking_threads = 0;
  // Workers of their own for the sessions that search the map (INITIALIZING, RELOCALIZING), so
  // that a search never holds a worker the tracking sessions wait for (--search-threads); 0:
  // searching sessions share the tracking workers.
  int search_threads = 1;
  // The priority of those workers (--search-priority idle|low|normal): idle (SCHED_IDLE: only CPU
  // that nothing else on the machine wants), low (nice 10) or the tracking workers' own.
  TrackingPool::BackgroundPriority search_priority = TrackingPool::BackgroundPriority::kIdle;
  // Largest request message accepted, bytes; larger ones get RESOURCE_EXHAUSTED
  // (--max-message-bytes).
  int max_message_bytes = 4 << 20;
  // A session that receives nothing for this long is cancelled, seconds (--idle-timeout).
  double idle_timeout_s = 30.0;
  // Packets a session may have waiting for its tracker; a full queue ends the session with
  // RESOURCE_EXHAUSTED (--queue-packets).
  int queue_packets = 256;
  // A Backpressure notice is sent when the queue holds at least this fraction of its capacity
  // (--backpressure-fraction).
  double backpressure_fraction = 0.5;
  // Events per pixel and second a searching session's search needs at most, announced to its
  // client as SessionStarted.searching_event_rate (times the camera's pixels) so that it may thin
  // its stream while searching; 0: no advice (--searching-event-rate). 20: twice what the search
  // was measured to need at 640x480 (docs/benchmarks.md, "A relocalizing neighbour").
  double searching_events_per_pixel_s = 20.0;
  // File of bearer tokens, one per line: `TOKEN *` (every map) or `TOKEN map1,map2` (those maps
  // only); '#' starts a comment (format: TokenTable in auth.h). Read again when it changes.
  // Unset: no token authentication (--auth-tokens).
  std::optional<std::filesystem::path> auth_tokens_file;
  // Serve Prometheus metrics over HTTP at this IPV4:PORT (GET /metrics); unset: none
  // (--metrics).
  std::optional<std::string> metrics_address;
  // Serve the live web viewer (docs/viewer.md) over HTTP at this IPV4:PORT; unset: none
  // (--viewer). The same rules as the API's address: TLS (the same certificate) and tokens (the
  // same file) apply to it, and a non-loopback address needs them or --insecure.
  std::optional<std::string> viewer_address;
  // Most viewer pages open at once (each holds one event stream) (--viewer-max-clients).
  int viewer_max_clients = 8;
  // Highest update rate of a viewer page, Hz (--viewer-rate).
  double viewer_rate_hz = 30.0;
  // PEM certificate chain for TLS; with tls_key_file. Unset: plaintext (--tls-cert).
  std::optional<std::filesystem::path> tls_cert_file;
  // PEM private key for TLS (--tls-key).
  std::optional<std::filesystem::path> tls_key_file;
  // PEM certificate(s) of the CA that issues client certificates: when set, every client must
  // present a certificate that this CA signed (mutual TLS); needs tls_cert_file. Unset: clients
  // are not asked for a certificate (--tls-client-ca).
  std::optional<std::filesystem::path> tls_client_ca_file;
  // How often the TLS files and the token file are checked for changes, seconds; a change takes
  // effect without a restart (--reload-interval).
  int reload_interval_s = 10;
  // Serve on a non-loopback address without TLS or without authentication (tokens or client
  // certificates). False: such a configuration is refused by Check() (--insecure).
  bool insecure = false;
  // Budget of the loaded maps and of the sites' loaded tiles, bytes (--map-memory SIZE, or
  // --max-map-memory in MiB): least recently used maps beyond it are dropped (sessions keep
  // theirs), and so are tiles no session uses; whole maps and tiles are two caches, each bounded
  // by it.
  uint64_t max_map_memory_bytes = MapRegistryOptions{}.max_map_memory_bytes;
  // Background threads that load the sites' tiles and compose them for sessions
  // (--tile-loader-threads); never the tracking workers.
  int tile_loader_threads = 1;
  // Their priority (--tile-loader-priority idle|low|normal; ThreadPriority).
  ThreadPriority tile_loader_priority = MapRegistryOptions{}.tile_loader_priority;
  // Keep a copy of each map version the server loaded, to serve again when the map's file stops
  // loading (copied in place, truncated) after the version left the memory budget
  // (--map-keep-dir none: false).
  bool keep_maps = true;
  // Where those copies go (--map-keep-dir DIR, an existing folder; copies there outlive the
  // server and are used after a restart). Unset: a private folder under the temporary directory,
  // made at start and removed at exit.
  std::optional<std::filesystem::path> map_keep_dir;
  // Largest camera a session may declare, width * height pixels (--max-camera-pixels).
  int64_t max_camera_pixels = SessionLimits{}.max_camera_pixels;
  // Most a packet's end (or a PoseHint) may lie after the session time, seconds
  // (--max-packet-span).
  double max_packet_span_s = 1.0;
  // Highest step rate a session may ask for, Hz (--max-rate).
  double max_step_rate_hz = SessionLimits{}.max_step_rate_hz;
  // Most map points per step a session may ask for (--max-points-limit).
  int max_points_limit = SessionLimits{}.max_points_limit;
  // Most steps one EventPacket may complete (--max-steps-per-request).
  int64_t max_steps_per_request = SessionLimits{}.max_steps_per_request;
  // Most events one EventPacket may decode to (--max-packet-events).
  int64_t max_packet_events = SessionLimits{}.max_packet_events;
  // Decoded events a session may have waiting for its tracker; more end the session with
  // RESOURCE_EXHAUSTED like a packet overflow (--queue-events). At least max_packet_events.
  int64_t queue_events = int64_t{1} << 21;
  // Server-wide budget for decoded requests waiting in the sessions' queues, bytes (13 per
  // event, frame pixels); a packet that does not fit ends its session with RESOURCE_EXHAUSTED,
  // and no session is admitted while 3/4 of it is used. gRPC's own buffers get a ResourceQuota
  // of the same size, at least 16 x max_message_bytes (--max-memory).
  int64_t max_memory_bytes = int64_t{1} << 30;
  // CPU budget of a session's tracking: CPU seconds per second of session time tracked,
  // beyond session_cpu_grace_s; a session over it ends with RESOURCE_EXHAUSTED
  // (--session-cpu-budget).
  double session_cpu_per_second = 8.0;
  // CPU seconds a session may use before its budget applies (start-up, a first search)
  // (--session-cpu-grace).
  double session_cpu_grace_s = 10.0;
  // A Track stream whose first message (SessionStart) has not arrived this long after the call
  // started is cancelled, seconds (--handshake-timeout).
  double handshake_timeout_s = 5.0;
  // Most Track streams open at once from one peer address (host, without the port), sessions
  // or not; 0: max_sessions. More get RESOURCE_EXHAUSTED (--max-streams-per-peer). Behind a
  // proxy every client has the proxy's address: raise it there.
  int max_streams_per_peer = 0;
  // Most sessions at once from one peer address; 0: max_sessions (--max-sessions-per-peer).
  int max_sessions_per_peer = 0;
  // Most sessions at once per bearer token (with auth_tokens_file); 0: no limit
  // (--max-sessions-per-token).
  int max_sessions_per_token = 0;
  // Most concurrent streams on one HTTP/2 connection (GRPC_ARG_MAX_CONCURRENT_STREAMS)
  // (--max-streams-per-connection).
  int max_streams_per_connection = 16;
  // A connection is told to go away (GOAWAY) after this long, seconds; 0: never
  // (--max-connection-age). Its streams get max_connection_age_grace_s more, then are cut
  // (UNAVAILABLE: clients reconnect, evloc-replay --reconnect resumes from the last pose).
  double max_connection_age_s = 3600.0;
  // Grace after max_connection_age_s for the streams of an old connection, seconds
  // (--max-connection-age-grace).
  double max_connection_age_grace_s = 300.0;
  // On SIGTERM (Shutdown), running sessions stop within one step and end with UNAVAILABLE
  // "draining" when their client next sends or half-closes; calls still open after this long are
  // cancelled, seconds. Keep it below the pod's terminationGracePeriodSeconds (20) minus its
  // preStop sleep (5) (--drain-timeout).
  double drain_timeout_s = 10.0;
  // Default tracker options of every session (SessionStart.options override them). A searching
  // session's search may use half a core per second of session time (--search-cpu-share): a
  // live session whose search is slower than real time keeps up with its events instead of
  // overflowing its queue, and leaves the rest of its worker to the other sessions.
  tracking::TrackerOptions tracker = [] {
    tracking::TrackerOptions options;
    options.relocalization_cpu_share = 0.5;
    return options;
  }();

  // Throws InvalidArgumentError naming the first invalid field.
  void Check() const;
  // What secures the listen address (TLS, tokens, client certificates, --insecure).
  ListenSecurity listen_security() const;
  // What every session is checked against (tracker defaults, camera size).
  SessionLimits session_limits() const;
  // The viewer's options (address, pages, rate; TLS is added by the server).
  ViewerOptions viewer_options() const;
  // The map registry's options (maps folder, budgets, tile loader threads).
  MapRegistryOptions registry_options() const;
  // The effective configuration, one "key: value" line per option.
  std::string Describe() const;
};

// Counters of a server since it started (all atomic; read them at any time).
struct ServerCounters {
  // Sessions accepted.
  std::atomic<int64_t> sessions_started{0};
  // Sessions running now.
  std::atomic<int64_t> sessions_active{0};
  // Requests rejected with an error status (any RPC).
  std::atomic<int64_t> rejected{0};
  // Events tracked.
  std::atomic<int64_t> events{0};
  // PoseUpdates sent.
  std::atomic<int64_t> poses{0};
  // PoseUpdates with status LOST.
  std::atomic<int64_t> lost_poses{0};
  // Requests refused by a server limit (sessions, per peer or token, memory, handshake, CPU,
  // packet events, steps) (RESOURCE_EXHAUSTED, or CANCELLED for a missed handshake).
  std::atomic<int64_t> limited{0};
  // Event packets shed by searching sessions whose
  // queue was full (thinned into the packet before them, or dropped).
  std::atomic<int64_t> packets_shed{0};
  // Upper bounds of the latency histogram buckets, microseconds (the last bucket is +Inf).
  static constexpr std::array<double, 8> kLatencyBucketsUs = {100,  250,  500,   1000,
                                                              2000, 5000, 10000, 50000};
  // PoseUpdates per latency bucket (not cumulative; index 8: above the last bound).
  std::array<std::atomic<int64_t>, 9> latency_bucket_counts{};
  // Sum of the latencies, microseconds.
  std::atomic<double> latency_sum_us{0};

  // Adds one pose latency to the histogram.
  void RecordLatency(double latency_us);
  // The counters in the Prometheus text exposition format.
  std::string PrometheusText() const;
};

// A running localizer server.
class LocalizerServer {
 public:
  // A log line (no trailing newline); called from gRPC threads, must be thread-safe.
  using LogFunction = std::function<void(const std::string& line)>;

  // Starts serving; its records (session start and end with the session id, refusals, reloads,
  // failures: docs/api.md, "Logs") go to `logger` (none when null). Throws
  // InvalidArgumentError for invalid options, IoError when the address cannot be bound or the
  // token file cannot be read.
  LocalizerServer(const LocalizerServerOptions& options, std::shared_ptr<Logger> logger);
  // The same with every record rendered as a text line without the logger's name (level info:
  // the message; others "LEVEL: message") and handed to `log` on the thread that logs.
  explicit LocalizerServer(const LocalizerServerOptions& options, LogFunction log = {});
  // Shuts down (see Shutdown).
  ~LocalizerServer();
  LocalizerServer(const LocalizerServer&) = delete;
  LocalizerServer& operator=(const LocalizerServer&) = delete;

  // The port actually bound (useful with port 0).
  int port() const { return port_; }
  // Drains and stops; idempotent: health turns NOT_SERVING, new calls are refused, running
  // sessions stop within one step and end with UNAVAILABLE "draining" (or their SessionEnd when
  // they were finishing), calls still open after drain_timeout_s are cancelled, the connections
  // stay open 0.5 s after the last call ended (its client reads the status), then the metrics
  // server stops.
  void Shutdown();
  // Blocks until Shutdown() is called from another thread.
  void Wait();
  // Counters since start.
  const ServerCounters& counters() const;
  // Port of the metrics endpoint (0 without one).
  int metrics_port() const;
  // Port of the live viewer (0 without one).
  int viewer_port() const;
  // The sessions as the viewer shows them (null without a viewer).
  ViewerBoard* viewer_board();
  // The map registry.
  MapRegistry& registry();

  // The gRPC service behind the server (defined in localizer_server.cc).
  class Service;

 private:
  std::unique_ptr<Service> service_;
  // The TLS files, read again when they change (null without TLS); outlives server_.
  std::unique_ptr<ServerTlsFiles> tls_files_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<MetricsHttpServer> metrics_;
  std::unique_ptr<ViewerServer> viewer_;
  int port_ = 0;
  double drain_timeout_s_ = 0;
  std::atomic<bool> shut_down_{false};
};

}  // namespace evloc::service
