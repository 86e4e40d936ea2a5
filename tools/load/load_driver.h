// evloc-load: many concurrent Track sessions against one localizer server, for the capacity
// benchmark and the soak test (docs/benchmarks.md §4, docs/reliability.md §4). Each of N session
// slots opens a session, streams the dataset's events (pre-encoded once, shared by every slot)
// at real time or as fast as the server confirms them, ends it (normally, by cancelling, or with
// a deliberately bad packet) and opens the next, until the run's duration has elapsed.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

namespace evloc::load {

// Options of a load run; every field is a flag of evloc-load.
struct LoadOptions {
  // Server address, host:port (--server).
  std::string server;
  // Map name on the server (--map).
  std::string map_name;
  // Dataset folder (core/dataset/dataset.h layout) with ground truth for the initial pose
  // (--dataset).
  std::filesystem::path dataset;
  // Concurrent session slots (--sessions).
  int sessions = 1;
  // Session time streamed per session after the initial pose, seconds (--session-s).
  double session_s = 1.0;
  // Wall time of the run: each slot opens sessions until it elapses; 0: one session per slot
  // (--duration).
  double duration_s = 0;
  // Playback speed relative to real time; nullopt: as fast as the server confirms packets
  // (--speed 1 | max).
  std::optional<double> speed = 1.0;
  // Length of the time window of one packet, microseconds (--packet-us).
  int64_t packet_us = 1000;
  // Tracking steps per second asked of the server; nullopt: the server's default (--rate).
  std::optional<double> step_rate_hz;
  // Fraction of sessions the client cancels at a random packet (--cancel-fraction).
  double cancel_fraction = 0;
  // Fraction of sessions that send an event outside the sensor at a random packet and expect
  // INVALID_ARGUMENT (--bad-fraction).
  double bad_fraction = 0;
  // Spread the sessions over a grid of copies of the dataset's scene (a site made of copies,
  // docs/benchmarks.md "Sites"): the k-th session opened (over all slots) starts at its initial
  // pose moved by ((k mod columns) * pitch, ((k / columns) mod rows) * pitch, 0) metres
  // (--spread COLUMNSxROWS:PITCH); 0 columns: every session at the dataset's pose.
  int spread_columns = 0;
  int spread_rows = 0;
  double spread_pitch_m = 0;
  // Start the sessions along a long dataset instead of all at its start (a vehicle route through
  // a site, docs/benchmarks.md "Sites"): the k-th session opened (over all slots) starts
  // (k mod stagger_count) * stagger_s seconds after the dataset's first ground-truth pose, from
  // the ground truth there, with the events of the 50 ms before it priming its surfaces
  // (--stagger COUNT:SECONDS); 0: every session at the dataset's start.
  int stagger_count = 0;
  double stagger_s = 0;
  // Each session sends the ground truth's velocity at its start (SessionStart.initial_velocity,
  // over the tracker's 20 ms velocity window) instead of starting at rest, as a vehicle client
  // that knows its speed from its wheels or its last session can (--initial-velocity truth).
  // Needs ground truth.
  bool initial_velocity_from_truth = false;
  // Seed of the random choices (--seed).
  uint32_t seed = 1;
  // Write the result as JSON here (--report).
  std::optional<std::filesystem::path> report;

  // Throws InvalidArgumentError naming the first invalid field.
  void Check() const;
};

// What a load run measured.
struct LoadResult {
  // Sessions opened.
  int64_t sessions = 0;
  // Sessions that ended as planned: OK after a normal end, CANCELLED after a client cancel,
  // INVALID_ARGUMENT after a bad packet.
  int64_t sessions_as_planned = 0;
  // Sessions that ended with an unplanned status, per status name (e.g. RESOURCE_EXHAUSTED).
  std::map<std::string, int64_t> unplanned;
  // The first few unplanned status messages.
  std::vector<std::string> unplanned_messages;
  // Sessions ended normally, cancelled, and with a bad packet (as planned or not).
  int64_t normal_sessions = 0;
  // Sessions the client cancelled.
  int64_t cancelled_sessions = 0;
  // Sessions that sent a bad packet.
  int64_t bad_packet_sessions = 0;
  // Packets and events sent, poses received.
  int64_t packets = 0;
  // Events sent.
  int64_t events = 0;
  // Poses received.
  int64_t poses = 0;
  // Backpressure notices received.
  int64_t backpressure_notices = 0;
  // Server-side latency (PoseUpdate.latency_us): median, 99th percentile, maximum, microseconds.
  double server_latency_p50_us = 0;
  // 99th percentile.
  double server_latency_p95_us = 0;
  double server_latency_p99_us = 0;
  // Maximum.
  double server_latency_max_us = 0;
  // Client-side latency: pose received minus sending of the packet whose end_t_ns reached the
  // pose's time; median, 99th percentile, maximum, microseconds.
  double client_latency_p50_us = 0;
  // 99th percentile.
  double client_latency_p99_us = 0;
  // Maximum.
  double client_latency_max_us = 0;
  // Median and 99th percentile of the server's step time, milliseconds.
  double step_p50_ms = 0;
  // 99th percentile.
  double step_p95_ms = 0;
  double step_p99_ms = 0;
  // Distance of the TRACKING poses from the dataset's ground truth at their time: median and
  // maximum, metres (0 without ground truth).
  double error_p50_m = 0;
  double error_max_m = 0;
  // Wall time of the run, seconds.
  double wall_s = 0;
};

// Runs the load; progress and the summary go to `log`. Throws InvalidArgumentError / IoError /
// ParseError for bad options or dataset (server errors are counted, not thrown).
LoadResult RunLoad(const LoadOptions& options, std::ostream& log);

// The usage text of evloc-load.
std::string LoadUsage();

// Parses the command line (arguments after the program name); `help` is set for --help.
// Throws InvalidArgumentError naming the flag.
LoadOptions ParseLoadCommandLine(const std::vector<std::string>& arguments, bool* help);

}  // namespace evloc::load
