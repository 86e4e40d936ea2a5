// evloc-replay: streams a recorded dataset to a localizer server as a live camera would
// (docs/api.md), collects the poses and measures the latency.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <ostream>
#include <string>
#include <utility>
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
  // Dataset folder (core/dataset/dataset.h layout), ROS1 bag or AEDAT4 file (--dataset).
  std::filesystem::path dataset;
  // The topics when the dataset is a bag (--events-topic, --image-topic, --camera-info-topic,
  // --groundtruth-topic).
  RosbagTopics bag_topics;
  // The streams, calibration and ground truth when the dataset is an AEDAT4 file
  // (--events-topic, --image-topic, --calib, --groundtruth).
  Aedat4DatasetOptions aedat4;
  // Output TUM trajectory of the received poses (--out).
  std::filesystem::path output;
  // Playback speed relative to real time; nullopt: as fast as the server keeps up (--speed 1 |
  // 2.5 | max).
  std::optional<double> speed = 1.0;
  // Wire encoding (--encoding packed|evt3).
  WireEncoding encoding = WireEncoding::kPacked;
  // Length of the time window of one packet, microseconds (--packet-us).
  int64_t packet_us = 1000;
  // Bearer token sent as `authorization: Bearer T` (--token). Visible in the process list and
  // the shell history: prefer token_file.
  std::optional<std::string> token;
  // File holding the bearer token (one line; ReadTokenFile), read when the replay starts
  // (--token-file). Not with `token`.
  std::optional<std::filesystem::path> token_file;
  // PEM root certificate(s) to verify a TLS server with; unset: plaintext (--tls-ca).
  std::optional<std::filesystem::path> tls_ca_file;
  // PEM client certificate chain for a server that requires one (mutual TLS, the server's
  // --tls-client-ca); with tls_key_file and tls_ca_file (--tls-cert).
  std::optional<std::filesystem::path> tls_cert_file;
  // PEM private key of tls_cert_file (--tls-key).
  std::optional<std::filesystem::path> tls_key_file;
  // Host name expected in the server's certificate when it differs from --server's host
  // (--tls-server-name).
  std::optional<std::string> tls_server_name;
  // Initial world_from_cam; default: the dataset's first ground-truth pose (--init-pose).
  std::optional<Rigid3d> initial_world_from_cam;
  // Start without a pose: the server searches the map (PoseUpdates INITIALIZING, without a pose,
  // until it verifies one); the dataset needs no ground truth (--init-pose none).
  bool start_without_pose = false;
  // The first session starts moving with the ground truth's velocity at the initial pose
  // (SessionStart.initial_velocity, over the tracker's 20 ms velocity window), as a vehicle client
  // that knows its speed can, instead of at rest (--initial-velocity truth). Needs a pose and
  // ground truth there.
  bool initial_velocity_from_truth = false;
  // A simulated GNSS receiver (--gnss-sigma M): right after the session starts and then every
  // gnss_period_s of session time (before the packet that reaches it), a GnssFix at the
  // ground-truth position moved by Gaussian noise of this one-sigma on each axis (seed
  // gnss_seed, --gnss-seed), with this accuracy, through the map's geo anchor; it narrows the
  // search, and on a site chooses the tiles a session without a pose searches (docs/geo.md).
  // Needs ground truth and a map with a geo anchor.
  std::optional<double> gnss_sigma_m;
  double gnss_period_s = 1.0;
  uint32_t gnss_seed = 1;
  // Tracking steps per second asked of the server; nullopt: the server's default (--rate).
  std::optional<double> step_rate_hz;
  // The motion prior asked of the server, (m/s, deg/s) (TrackingOptions.motion_prior_*); nullopt:
  // the server's default (evloc-localizer serve --motion-prior).
  std::optional<std::pair<double, double>> motion_prior;
  // While the session searches (no pose in its updates; from the start with --init-pose none),
  // send only every k-th event of a packet whose rate exceeds the server's
  // SessionStarted.searching_event_rate (wire::ThinningStride); the rest of the stream goes out
  // whole
  // (--thin-while-searching on|off).
  bool thin_while_searching = true;
  // With --speed max: the most session time sent ahead of the last pose received, ms
  // (--max-lead-ms); keeps the server's queue from overflowing.
  double max_lead_ms = 50.0;
  // Stop after this much session time after the initial pose, seconds (--duration).
  std::optional<double> duration_s;
  // Sensor size for ECD folders with calib.txt only (--ecd-size).
  int ecd_width = 240;
  // Sensor height for ECD folders.
  int ecd_height = 180;
  // Most reconnect attempts of one outage after the stream failed with a transient status
  // (UNAVAILABLE, e.g. "draining"; CANCELLED, ABORTED, UNKNOWN: no status, as from a proxy whose
  // backend died; RESOURCE_EXHAUSTED: the replica is full or the session's queue overflowed,
  // retried as "slow down"); 0: fail at once (--reconnect N). A new session starts at the last
  // pose received. The outage, and with it the count and the backoff, ends only once a new
  // session stayed up for reconnect_stable_s.
  int reconnect = 0;
  // Ceiling of the first reconnect attempt's delay, ms: attempt k waits uniformly in
  // [0, min(reconnect_backoff_max_ms, reconnect_backoff_ms * 2^(k-1))] (full jitter), at least
  // half that ceiling after RESOURCE_EXHAUSTED, and at least the retry delay the server asked
  // for (--reconnect-backoff-ms).
  double reconnect_backoff_ms = 100.0;
  // Largest ceiling of a reconnect delay, ms (--reconnect-backoff-max-ms).
  double reconnect_backoff_max_ms = 2000.0;
  // Most wall time of one outage, seconds: no attempt starts later than this after the failure
  // that began it (--reconnect-max-s).
  double reconnect_max_s = 60.0;
  // Wall time a new session must stay up, seconds, before its failure counts as a new outage
  // with a fresh backoff (--reconnect-stable-s).
  double reconnect_stable_s = 10.0;
  // Seed of the reconnect jitter; unset: random (--reconnect-seed).
  std::optional<uint64_t> reconnect_seed;
  // Session time of events before the resume pose that a new session is sent again to prime
  // its time surfaces, ms (--resume-prime-ms).
  double resume_prime_ms = 100.0;
  // Window of the velocity a resumed session starts with, ms: the twist over the last TRACKING
  // poses received within it (ResumeVelocity); 0: resume at rest (--resume-velocity-ms).
  double resume_velocity_ms = 100.0;
  // gRPC load-balancing policy over the addresses of --server: "pick_first" or "round_robin";
  // empty: gRPC's default (pick_first) (--lb).
  std::string lb_policy;
  // JSON file for the figures of the replay, written when it completes (--report).
  std::optional<std::filesystem::path> report;
  // The received poses in WGS84 (--geo FILE; docs/geo.md): the map needs a geo anchor.
  std::optional<std::filesystem::path> geo_output;

  // Throws InvalidArgumentError naming the first invalid field.
  void Check() const;
};

// Reads a bearer token file: the token on its first non-empty line, surrounding white space
// (and the line end) removed. Throws IoError when the file cannot be read, ParseError when it
// holds no token, a token with white space inside, or more than one line.
std::string ReadTokenFile(const std::filesystem::path& path);

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
  // GnssFix requests sent (--gnss-sigma).
  int64_t gnss_fixes_sent = 0;
  // Stream failures recovered by reconnecting, in order.
  std::vector<Outage> outages;
  // Poses received with status LOST.
  int64_t lost_poses = 0;
  // Updates received without a pose (INITIALIZING or RELOCALIZING: the server was searching).
  int64_t searching_updates = 0;
  // Events left out of packets while the session searched (thin_while_searching).
  int64_t events_thinned = 0;
  // Event packets the server folded into their neighbours or dropped while it searched and the
  // session was behind its stream (SessionEnd.packets_shed of the last session; 0 when it kept up).
  int64_t packets_shed = 0;
  // Session time from the session's start (the initial pose's time, or the first event with
  // --init-pose none) to the first TRACKING pose, seconds; unset when no pose
  // was TRACKING (with --init-pose none: the time the server took to find the camera).
  std::optional<double> first_tracking_s;
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
// `options.tls_ca_file`) for the status of `service` ("": the server's overall status, what a
// liveness probe asks; "evloc.api.Localizer": whether the server admits new sessions, what a
// readiness probe asks) and returns its name: SERVING, NOT_SERVING, UNKNOWN or SERVICE_UNKNOWN.
// Throws Error with the gRPC status when the call fails (NOT_FOUND for a service the server does
// not know) or takes longer than `timeout_s` (evloc-replay --health-check; a container probe).
std::string CheckHealth(const ReplayOptions& options, double timeout_s,
                        const std::string& service = "");

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
  // The service whose health is asked; "": the server's overall health (--health-service).
  std::string health_service;
  // The replay's options (for a health check: the server and TLS fields only).
  ReplayOptions options;
};

// Parses the command line (arguments after the program name). Throws InvalidArgumentError
// naming the flag.
ReplayCommand ParseReplayCommandLine(const std::vector<std::string>& arguments);

}  // namespace evloc::replay
