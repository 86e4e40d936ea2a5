// evloc-replay: streams a recorded dataset to a localizer server as a live camera would
// (docs/api.md), collects the poses and measures the latency.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "core/dataset/dataset.h"
#include "core/geometry/rigid3.h"
#include "core/trajectory/trajectory.h"

namespace evloc::replay {

// How events are put on the wire.
enum class WireEncoding {
  // evloc's PACKED layout (8 bytes per event, nanosecond times).
  kPacked,
  // Prophesee EVT 3.0 (microsecond times: event times are rounded up to whole microseconds).
  kEvt3,
};

// Options of a replay; every field is a flag of evloc-replay.
struct ReplayOptions {
  // Server address: host:port, or a gRPC target naming several replicas, e.g.
  // "ipv4:127.0.0.1:50051,127.0.0.1:50052" or "dns:///evloc-localizer-headless:50051" (--server).
  std::string server;
  // Map name on the server (--map).
  std::string map_name;
  // Dataset folder (core/dataset/dataset.h layout) or ROS1 bag (--dataset).
  std::filesystem::path dataset;
  // The topics when the dataset is a bag (--events-topic, --image-topic, --camera-info-topic,
  // --groundtruth-topic).
  RosbagTopics bag_topics;
  // Output TUM trajectory of the received poses (--out).
  std::filesystem::path output;
  // Playback speed relative to real time; nullopt: as fast as the server keeps up (--speed 1 |
  // 2.5 | max).
  std::optional<double> speed = 1.0;
  // Wire encoding (--encoding packed|evt3).
  WireEncoding encoding = WireEncoding::kPacked;
  // Length of the time window of one packet, microseconds (--packet-us).
  int64_t packet_us = 1000;
  // Bearer token sent as `authorization: Bearer T` (--token).
  std::optional<std::string> token;
  // PEM root certificate(s) to verify a TLS server with; unset: plaintext (--tls-ca).
  std::optional<std::filesystem::path> tls_ca_file;
  // Host name expected in the server's certificate when it differs from --server's host
  // (--tls-server-name).
  std::optional<std::string> tls_server_name;
  // Initial world_from_cam; default: the dataset's first ground-truth pose (--init-pose).
  std::optional<Rigid3d> initial_world_from_cam;
  // Tracking steps per second asked of the server; nullopt: the server's default (--rate).
  std::optional<double> step_rate_hz;
  // With --speed max: the most session time sent ahead of the last pose received, ms
  // (--max-lead-ms); keeps the server's queue from overflowing.
  double max_lead_ms = 50.0;
  // Stop after this much session time after the initial pose, seconds (--duration).
  std::optional<double> duration_s;
  // Sensor size for ECD folders with calib.txt only (--ecd-size).
  int ecd_width = 240;
  // Sensor height for ECD folders.
  int ecd_height = 180;
  // Most reconnect attempts in a row after the stream failed with a transient status
  // (UNAVAILABLE, CANCELLED, ABORTED, UNKNOWN: no status, as from a proxy whose backend died;
  // RESOURCE_EXHAUSTED: the replica is full or the session's queue overflowed); 0: fail at once
  // (--reconnect N). A new session
  // starts at the last pose received, and the count starts again once it delivers a pose.
  int reconnect = 0;
  // Wait before the first reconnect attempt, ms; doubled per further attempt up to
  // kMaxReconnectBackoffMs, with +-20 % jitter (--reconnect-backoff-ms).
  double reconnect_backoff_ms = 100.0;
  // Session time of events before the resume pose that a new session is sent again to prime
  // its time surfaces, ms (--resume-prime-ms).
  double resume_prime_ms = 100.0;
  // gRPC load-balancing policy over the addresses of --server: "pick_first" or "round_robin";
  // empty: gRPC's default (pick_first) (--lb).
  std::string lb_policy;
  // JSON file for the figures of the replay, written when it completes (--report).
  std::optional<std::filesystem::path> report;

  // Throws InvalidArgumentError naming the first invalid field.
  void Check() const;
};

// Longest wait between two reconnect attempts, ms.
inline constexpr double kMaxReconnectBackoffMs = 2000.0;

// One stream failure the replay recovered from.
struct Outage {
  // gRPC status code and message of the failed stream.
  int status_code = 0;
  // The failed stream's status message.
  std::string status_message;
  // When the failure was seen: wall-clock (system) time, seconds since the Unix epoch.
  double failed_at_unix_s = 0;
  // Session time of the last pose received before the failure (the resume pose), ns.
  int64_t resume_t_ns = 0;
  // Reconnect attempts it took (1: the first one succeeded).
  int attempts = 0;
  // Wall time from the failure's status to the first pose of the new session, ms.
  double resume_ms = 0;
  // Wall time from the last pose before the failure to the first pose after it, ms.
  double interruption_ms = 0;
};

// What a replay measured.
struct ReplayResult {
  // The received poses, world_from_cam.
  Trajectory trajectory;
  // Status of each pose: true when TRACKING.
  std::vector<bool> tracking;
  // Events sent.
  int64_t events_sent = 0;
  // Packets sent (each window of the dataset counted once).
  int64_t packets_sent = 0;
  // Packets sent again to a new session after a stream failure (priming and in-flight ones).
  int64_t packets_resent = 0;
  // Stream failures recovered by reconnecting, in order.
  std::vector<Outage> outages;
  // Poses received with status LOST.
  int64_t lost_poses = 0;
  // Backpressure notices received.
  int64_t backpressure_notices = 0;
  // Client-side latency, microseconds: pose received minus sending of the packet holding the
  // first event after the pose's time (the event that let the step run); median and 99th pct.
  double client_latency_p50_us = 0;
  // 99th percentile of the client-side latency, microseconds.
  double client_latency_p99_us = 0;
  // Server-side latency (PoseUpdate.latency_us), median and 99th percentile, microseconds.
  double server_latency_p50_us = 0;
  // 99th percentile of the server-side latency, microseconds.
  double server_latency_p99_us = 0;
  // Server-side overhead (latency_us minus the step's own time): queueing, serialisation and
  // hand-over; median and 99th percentile, microseconds.
  double server_overhead_p50_us = 0;
  // 99th percentile of the overhead, microseconds.
  double server_overhead_p99_us = 0;
  // Median wall time of a tracking step on the server, milliseconds.
  double step_p50_ms = 0;
  // Wall time of the replay, seconds.
  double wall_s = 0;
};

// Streams the dataset, writes the trajectory and returns the figures; progress and the summary
// go to `log`. Throws InvalidArgumentError / IoError / ParseError for bad options or dataset,
// and Error with the gRPC status for a failed session.
ReplayResult RunReplay(const ReplayOptions& options, std::ostream& log);

// Writes the figures of `result` as JSON (the --report file), atomically. Throws IoError.
void WriteReplayReport(const std::filesystem::path& path, const ReplayResult& result);

// Asks the grpc.health.v1 Health/Check service of `options.server` (over TLS with
// `options.tls_ca_file`) for the server's overall status and returns its name: SERVING,
// NOT_SERVING, UNKNOWN or SERVICE_UNKNOWN. Throws Error with the gRPC status when the call fails
// or takes longer than `timeout_s` (evloc-replay --health-check; a container health probe).
std::string CheckHealth(const ReplayOptions& options, double timeout_s);

// The usage text of evloc-replay.
std::string ReplayUsage();

// What the command line asks for.
struct ReplayCommand {
  // Print the usage and exit.
  bool help = false;
  // Only check the server's health (--health-check): needs --server only.
  bool health_check = false;
  // Deadline of the health check, seconds (--health-timeout).
  double health_timeout_s = 5.0;
  // The replay's options (for a health check: the server and TLS fields only).
  ReplayOptions options;
};

// Parses the command line (arguments after the program name). Throws InvalidArgumentError
// naming the flag.
ReplayCommand ParseReplayCommandLine(const std::vector<std::string>& arguments);

}  // namespace evloc::replay
