// The evloc localizer gRPC server (proto/evloc/localizer.proto, docs/api.md): the Localizer
// service over a MapRegistry, with one TrackStream object per Track call, gRPC health checking
// and server reflection. Library code: it logs through a callback and throws typed errors.
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

#include "localizer/service/map_registry.h"
#include "localizer/service/session.h"
#include "localizer/tracking/tracker_options.h"

namespace grpc {
class Server;
}  // namespace grpc

namespace evloc::service {

class MetricsHttpServer;

// Options of the server; every field is a flag of `evloc-localizer serve`.
struct LocalizerServerOptions {
  // Folder with one subdirectory per map (NAME/map.evmap) (--maps).
  std::filesystem::path maps_dir;
  // Address to listen on, host:port; port 0 lets the OS choose (--listen).
  std::string listen_address = "127.0.0.1:50051";
  // Most Track sessions running at once; more get RESOURCE_EXHAUSTED (--max-sessions).
  int max_sessions = 8;
  // Most threads gRPC may use for request handlers, each running Track stream holding one;
  // 0: max_sessions + 8 (--threads). Each session also runs a tracking and a writer thread.
  int threads = 0;
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
  // File of bearer tokens, one per line: `TOKEN` (every map) or `TOKEN map1,map2` (those maps
  // only); '#' starts a comment. Unset: no authentication (--auth-tokens).
  std::optional<std::filesystem::path> auth_tokens_file;
  // Serve Prometheus metrics over HTTP at this IPV4:PORT (GET /metrics); unset: none
  // (--metrics).
  std::optional<std::string> metrics_address;
  // PEM certificate chain for TLS; with tls_key_file. Unset: plaintext (--tls-cert).
  std::optional<std::filesystem::path> tls_cert_file;
  // PEM private key for TLS (--tls-key).
  std::optional<std::filesystem::path> tls_key_file;
  // Budget of the loaded-map cache, bytes; least recently used maps beyond it are dropped
  // (--max-map-memory, in MiB).
  uint64_t max_map_memory_bytes = MapRegistryOptions{}.max_map_memory_bytes;
  // Largest camera a session may declare, width * height pixels (--max-camera-pixels).
  int64_t max_camera_pixels = SessionLimits{}.max_camera_pixels;
  // Most a packet's end (or a PoseHint) may lie after the session time, seconds
  // (--max-packet-span).
  double max_packet_span_s = 1.0;
  // Highest step rate a session may ask for, Hz (--max-rate).
  double max_step_rate_hz = SessionLimits{}.max_step_rate_hz;
  // Default tracker options of every session (SessionStart.options override them).
  tracking::TrackerOptions tracker;

  // Throws InvalidArgumentError naming the first invalid field.
  void Check() const;
  // What every session is checked against (tracker defaults, camera size).
  SessionLimits session_limits() const;
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

// Bearer tokens and the maps each may use.
class TokenTable {
 public:
  // Reads a token file (format in LocalizerServerOptions::auth_tokens_file). Throws IoError when
  // it cannot be read, ParseError naming the line for a malformed line.
  static TokenTable Read(const std::filesystem::path& path);
  // True when `token` is known.
  bool Knows(const std::string& token) const { return maps_.count(token) > 0; }
  // True when `token` is known and may use `map_name`.
  bool Allows(const std::string& token, const std::string& map_name) const;
  // Number of tokens.
  size_t size() const { return maps_.size(); }

 private:
  // Token -> allowed maps (empty: every map).
  std::map<std::string, std::set<std::string>> maps_;
};

// A running localizer server.
class LocalizerServer {
 public:
  // A log line (no trailing newline); called from gRPC threads, must be thread-safe.
  using LogFunction = std::function<void(const std::string& line)>;

  // Starts serving. Throws InvalidArgumentError for invalid options, IoError when the address
  // cannot be bound or the token file cannot be read.
  explicit LocalizerServer(const LocalizerServerOptions& options, LogFunction log = {});
  // Shuts down (see Shutdown).
  ~LocalizerServer();
  LocalizerServer(const LocalizerServer&) = delete;
  LocalizerServer& operator=(const LocalizerServer&) = delete;

  // The port actually bound (useful with port 0).
  int port() const { return port_; }
  // Cancels running sessions and stops; idempotent.
  void Shutdown();
  // Blocks until Shutdown() is called from another thread.
  void Wait();
  // Counters since start.
  const ServerCounters& counters() const;
  // Port of the metrics endpoint (0 without one).
  int metrics_port() const;
  // The map registry.
  MapRegistry& registry();

  // The gRPC service behind the server (defined in localizer_server.cc).
  class Service;

 private:
  std::unique_ptr<Service> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<MetricsHttpServer> metrics_;
  int port_ = 0;
  std::atomic<bool> shut_down_{false};
};

}  // namespace evloc::service
