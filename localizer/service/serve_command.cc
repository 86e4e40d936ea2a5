#include "localizer/service/serve_command.h"

#include "core/common/cli.h"
#include "core/common/error.h"
#include "localizer/tracking/event_filter.h"

namespace evloc::service {

std::string ServeUsage() {
  return R"(Usage: evloc-localizer serve --maps DIR [options]
       evloc-localizer locate --map MAP --image IMAGE --calib CALIB [--json]  (locate --help)

Serves map-based tracking of event cameras over gRPC (proto/evloc/localizer.proto, docs/api.md),
with grpc.health.v1 health checking and server reflection.

Options:
  --maps DIR                 folder with one subdirectory per map, NAME/map.evmap (required)
  --listen HOST:PORT         address to listen on (default 127.0.0.1:50051; port 0: any free)
  --max-sessions N           most Track sessions at once (default 8)
  --threads N                most gRPC handler threads of the unary calls (ListMaps, GetMap,
                             Locate), >= max-sessions + 2 (default 0: max-sessions + 8); Track
                             streams hold none
  --tracking-threads N       tracking workers shared by every session (default 0: one per
                             core); a session runs on one worker at a time
  --search-threads N         workers of their own for the sessions searching the map
                             (INITIALIZING, RELOCALIZING), so a search never holds a tracking
                             worker (default 1; 0: they share the tracking workers)
  --search-priority P        idle (default: SCHED_IDLE, the search gets only CPU that nothing
                             else in the server's cgroup wants: a container, a systemd unit),
                             low (nice 10) or normal; on a machine shared with other busy
                             programs in one cgroup, use low or normal (docs/api.md, "Threads")
  --max-message-bytes N      largest request message, bytes (default 4194304)
  --idle-timeout SECONDS     cancel a session that sends nothing this long (default 30)
  --queue-packets N          packets a session may have waiting (default 256)
  --backpressure-fraction F  queue fill that triggers a Backpressure notice (default 0.5)
  --searching-event-rate R   events per pixel and second a searching session needs at most,
                             announced to clients so they may thin their streams while the
                             session searches (SessionStarted.searching_event_rate; default 20,
                             0: no advice)
  --map-memory SIZE          memory budget of the loaded maps and, separately, of the loaded
                             tiles of sites, bytes with a K/M/G/T suffix (e.g. 2G); least
                             recently used maps beyond it are unloaded (sessions keep theirs),
                             and so are tiles no session uses (default 1G)
  --max-map-memory MIB       the same in MiB (default 1024)
  --tile-loader-threads N    background threads loading and composing sites' tiles (default 1)
  --tile-loader-priority P   their priority: idle (SCHED_IDLE), low (nice 10) or normal (default
                             normal; docs/benchmarks.md 4.y)
  --map-keep-dir DIR|none    where a copy of each map version loaded is kept, to serve again
                             when the map's file stops loading after the version left the
                             memory budget (default: a private folder under $TMPDIR, removed at
                             exit; none: keep nothing)
  --max-camera-pixels N      largest camera a session may declare, width * height (default
                             4194304; a session's memory grows with it)
  --max-packet-span SECONDS  most a packet's end_t_ns (or a pose hint) may lie after the session
                             time: bounds the steps one request runs (default 1)
  --max-rate HZ              highest step rate a session may ask for (default 2000)
  --max-points-limit N       most map points per step a session may ask for (default 10000)
  --max-steps-per-request N  most tracking steps one event packet may complete (default 1000)
  --max-packet-events N      most events one packet may decode to (default 1048576)
  --queue-events N           decoded events a session may have waiting (default 2097152)
  --max-memory BYTES         server-wide budget of queued decoded events (13 bytes each) and
                             of gRPC's buffers (default 1073741824); no new session while 3/4
                             of it is used
  --session-cpu-budget X     CPU seconds a session may use per second of session time tracked,
                             after the grace (default 8)
  --session-cpu-grace S      CPU seconds a session may use before its budget applies (default 10)
  --handshake-timeout S      cancel a stream whose SessionStart has not come after S (default 5)
  --max-streams-per-peer N   most Track streams from one address at once (default 0:
                             max-sessions; raise it behind a proxy)
  --max-sessions-per-peer N  most sessions from one address at once (default 0: max-sessions)
  --max-sessions-per-token N most sessions per bearer token at once (default 0: no limit)
  --max-streams-per-connection N  most concurrent streams per HTTP/2 connection (default 16)
  --max-connection-age S     send GOAWAY to a connection after S (default 3600; 0: never)
  --max-connection-age-grace S  then cut its streams after S more (default 300)
  --drain-timeout S          on SIGTERM: sessions stop within a step and end UNAVAILABLE
                             "draining"; calls still open after S are cancelled (default 10:
                             Kubernetes' grace of 20 s also covers the 5 s preStop sleep)
  --auth-tokens FILE         bearer tokens, one per line: TOKEN * (every map) or TOKEN map1,map2;
                             read again when it changes (docs/api.md, "Authentication")
  --metrics [IPV4:]PORT      serve Prometheus metrics at http://IPV4:PORT/metrics; a bare PORT
                             listens on 127.0.0.1 only: sessions, events, poses, LOST,
                             rejections, latency histogram (default: no metrics)
  --viewer [IPV4:]PORT       serve the live web viewer at http://IPV4:PORT/ (https with
                             --tls-cert; tokens of --auth-tokens); a bare PORT listens on
                             127.0.0.1 only; a network address needs TLS and authentication
                             like --listen, or --insecure (docs/viewer.md; default: none)
  --viewer-max-clients N     most viewer pages open at once (default 8)
  --viewer-rate HZ           highest update rate of a viewer page (default 30)
  --tls-cert PEM             TLS certificate chain (with --tls-key); default plaintext
  --tls-key PEM              TLS private key
  --tls-client-ca PEM        mutual TLS: require client certificates signed by this CA
  --reload-interval SECONDS  check the TLS files and the token file for changes this often;
                             changes apply without a restart (default 10)
  --log-level LEVEL          trace | debug | info | warning | error | critical | off: the
                             least severe record written (default info)
  --log-format FORMAT        text (default: "evloc-localizer: message" lines) | json (one
                             object per line: time, level, logger, session, message, fields)
  --insecure                 allow a non-loopback --listen without TLS or without
                             authentication (tokens or client certificates); without it such a
                             server refuses to start (docs/deploy.md, "Secure defaults")
  --rate HZ                  default tracking steps per second (default 300)
  --variant NAME             default variant: EVT, EVT-PR, EVT-OH or EVT-- (default EVT)
  --max-points N             default map points per step (default 2500)
  --binning B|auto           track every session on time surfaces of B x B sensor pixels
                             (default 1; 2 tracks a 1280x720 sensor in real time on one core;
                             auto: per session, the smallest B that fits its image in 640x480;
                             docs/tracking.md, "Binning")
  --informative-points N     default: of those, register only the N that constrain the pose
                             most (default 0: all; docs/tracking.md, "Point selection")
  --tau SECONDS              default time-surface decay time (default 0.03)
  --decay-trail PX           default adaptive decay trail, pixels (default 1; 0: a fixed decay time;
                             docs/tracking.md)
  --search-cpu-share F       CPU a searching session's search may use, cores per second of
                             session time (default 0.5; 0: unbounded; docs/relocalization.md)
  --stamp-at-step-time on|off
                             move each pose forward by the age of the events it was registered
                             to, to its step time (default on; off: the registered pose, which
                             lags by 1.5-5.5 ms, 11.5 against 7.6 cm at 10 m/s; docs/tracking.md,
                             "Pose time")
  --motion-prior V,W          each session's constant-velocity prediction as a prior in its
                             tracking solves, the velocity trusted to V m/s and W deg/s (default
                             0,0: none; docs/tracking.md, "Motion prior")
  default noise filters (docs/tracking.md, "Noise filters"; a session's
  TrackingOptions.event_filter overrides them):
)" + std::string(tracking::kEventFilterFlagsUsage) +
         R"(  --help                     print this help

Stop with Ctrl-C (SIGINT) or SIGTERM. Exit codes: 0 stopped, 1 failure, 2 bad command line.
)";
}

ServeCommand ParseServeCommandLine(const std::vector<std::string>& arguments) {
  ServeCommand command;
  size_t first = 0;
  if (!arguments.empty() && arguments[0] == "serve") first = 1;
  for (size_t i = first; i < arguments.size(); ++i) {
    const std::string& flag = arguments[i];
    if (flag == "--help" || flag == "-h") {
      command.help = true;
      continue;
    }
    if (first == 0) {
      throw InvalidArgumentError("the first argument must be the command 'serve' (see --help)");
    }
    if (flag == "--insecure") {
      command.server.insecure = true;
      continue;
    }
    const std::string& value = TakeFlagValue(arguments, &i);
    LocalizerServerOptions& server = command.server;
    if (flag == "--maps") {
      server.maps_dir = value;
    } else if (flag == "--listen") {
      server.listen_address = value;
    } else if (flag == "--max-sessions") {
      server.max_sessions = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--threads") {
      server.threads = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--tracking-threads") {
      server.tracking_threads = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--search-threads") {
      server.search_threads = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--search-priority") {
      server.search_priority = ParseSearchPriority(value);
    } else if (flag == "--max-message-bytes") {
      server.max_message_bytes = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--idle-timeout") {
      server.idle_timeout_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--queue-packets") {
      server.queue_packets = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--backpressure-fraction") {
      server.backpressure_fraction = ParseDoubleFlag(flag, value);
    } else if (flag == "--searching-event-rate") {
      server.searching_events_per_pixel_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-map-memory") {
      const int64_t mib = ParseIntegerFlag(flag, value);
      if (mib < 1 || mib > (int64_t{1} << 40)) {
        throw InvalidArgumentError("--max-map-memory must be 1 .. 2^40 MiB, got " + value);
      }
      server.max_map_memory_bytes = static_cast<uint64_t>(mib) << 20;
    } else if (flag == "--map-keep-dir") {
      if (value == "none") {
        server.keep_maps = false;
      } else {
        server.keep_maps = true;
        server.map_keep_dir = value;
      }
    } else if (flag == "--map-memory") {
      server.max_map_memory_bytes = ParseByteSizeFlag(flag, value);
      if (server.max_map_memory_bytes == 0) {
        throw InvalidArgumentError("--map-memory must be more than 0 bytes, got " + value);
      }
    } else if (flag == "--tile-loader-priority") {
      const std::optional<ThreadPriority> priority = ThreadPriorityNamed(value);
      if (!priority) {
        throw InvalidArgumentError("--tile-loader-priority must be idle, low or normal, got '" +
                                   value + "'");
      }
      server.tile_loader_priority = *priority;
    } else if (flag == "--tile-loader-threads") {
      server.tile_loader_threads = ParseIntFlag(flag, value);
    } else if (flag == "--max-camera-pixels") {
      server.max_camera_pixels = ParseIntegerFlag(flag, value);
    } else if (flag == "--max-packet-span") {
      server.max_packet_span_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-rate") {
      server.max_step_rate_hz = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-points-limit") {
      server.max_points_limit = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--max-steps-per-request") {
      server.max_steps_per_request = ParseIntegerFlag(flag, value);
    } else if (flag == "--max-packet-events") {
      server.max_packet_events = ParseIntegerFlag(flag, value);
    } else if (flag == "--queue-events") {
      server.queue_events = ParseIntegerFlag(flag, value);
    } else if (flag == "--max-memory") {
      server.max_memory_bytes = ParseIntegerFlag(flag, value);
    } else if (flag == "--session-cpu-budget") {
      server.session_cpu_per_second = ParseDoubleFlag(flag, value);
    } else if (flag == "--session-cpu-grace") {
      server.session_cpu_grace_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--handshake-timeout") {
      server.handshake_timeout_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-streams-per-peer") {
      server.max_streams_per_peer = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--max-sessions-per-peer") {
      server.max_sessions_per_peer = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--max-sessions-per-token") {
      server.max_sessions_per_token = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--max-streams-per-connection") {
      server.max_streams_per_connection = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--max-connection-age") {
      server.max_connection_age_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-connection-age-grace") {
      server.max_connection_age_grace_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--drain-timeout") {
      server.drain_timeout_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--auth-tokens") {
      server.auth_tokens_file = value;
    } else if (flag == "--metrics") {
      // A bare port listens on loopback only.
      server.metrics_address = value.find(':') == std::string::npos ? "127.0.0.1:" + value : value;
    } else if (flag == "--viewer") {
      server.viewer_address = value.find(':') == std::string::npos ? "127.0.0.1:" + value : value;
    } else if (flag == "--viewer-max-clients") {
      server.viewer_max_clients = ParseIntFlag(flag, value);
    } else if (flag == "--viewer-rate") {
      server.viewer_rate_hz = ParseDoubleFlag(flag, value);
    } else if (flag == "--tls-cert") {
      server.tls_cert_file = value;
    } else if (flag == "--tls-key") {
      server.tls_key_file = value;
    } else if (flag == "--tls-client-ca") {
      server.tls_client_ca_file = value;
    } else if (flag == "--reload-interval") {
      server.reload_interval_s = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--log-level") {
      command.logging.level = ParseLogLevel(flag, value);
    } else if (flag == "--log-format") {
      command.logging.format = ParseLogFormat(flag, value);
    } else if (flag == "--rate") {
      server.tracker.step_rate_hz = ParseDoubleFlag(flag, value);
    } else if (flag == "--variant") {
      server.tracker.SetVariant(value);
    } else if (flag == "--max-points") {
      server.tracker.max_points = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--binning") {
      ParseBinningFlag(flag, value, &server.tracker);
    } else if (flag == "--informative-points") {
      server.tracker.informative_points = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--tau") {
      server.tracker.decay_time_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--decay-trail") {
      server.tracker.decay_trail_px = ParseDoubleFlag(flag, value);
    } else if (flag == "--search-cpu-share") {
      server.tracker.relocalization_cpu_share = ParseDoubleFlag(flag, value);
    } else if (flag == "--stamp-at-step-time") {
      server.tracker.stamp_at_step_time = ParseSwitchFlag(flag, value);
    } else if (flag == "--motion-prior") {
      tracking::ParseMotionPriorFlag(flag, value, &server.tracker);
    } else if (tracking::ApplyEventFilterFlag(flag, value, &server.tracker.event_filter)) {
    } else {
      throw InvalidArgumentError("unknown flag '" + flag + "' (see --help)");
    }
  }
  if (command.help) return command;
  if (first == 0) throw InvalidArgumentError("missing the command 'serve' (see --help)");
  if (command.server.maps_dir.empty()) {
    throw InvalidArgumentError("--maps is required: a folder with one subdirectory per map");
  }
  command.server.Check();
  return command;
}

}  // namespace evloc::service
