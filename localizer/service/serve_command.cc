#include "localizer/service/serve_command.h"

#include "core/common/cli.h"
#include "core/common/error.h"

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
  --threads N                most gRPC handler threads, >= max-sessions + 2 (default 0:
                             max-sessions + 8)
  --max-message-bytes N      largest request message, bytes (default 4194304)
  --idle-timeout SECONDS     cancel a session that sends nothing this long (default 30)
  --queue-packets N          packets a session may have waiting (default 256)
  --backpressure-fraction F  queue fill that triggers a Backpressure notice (default 0.5)
  --max-map-memory MIB       memory budget of the loaded maps; least recently used maps beyond
                             it are unloaded, sessions keep theirs (default 1024)
  --max-camera-pixels N      largest camera a session may declare, width * height (default
                             4194304; a session's memory grows with it)
  --max-packet-span SECONDS  most a packet's end_t_ns (or a pose hint) may lie after the session
                             time: bounds the steps one request runs (default 1)
  --max-rate HZ              highest step rate a session may ask for (default 10000)
  --auth-tokens FILE         bearer tokens, one per line: TOKEN [map1,map2]
  --metrics IPV4:PORT        serve Prometheus metrics at http://IPV4:PORT/metrics (e.g.
                             127.0.0.1:9464): sessions, events, poses, LOST, rejections,
                             latency histogram
  --tls-cert PEM             TLS certificate chain (with --tls-key); default plaintext
  --tls-key PEM              TLS private key
  --rate HZ                  default tracking steps per second (default 300)
  --variant NAME             default variant: EVT, EVT-PR, EVT-OH or EVT-- (default EVT)
  --max-points N             default map points per step (default 2500)
  --tau SECONDS              default time-surface decay time (default 0.03)
  --decay-trail PX           default adaptive decay trail, pixels (default 1; 0: a fixed decay time;
                             docs/tracking.md)
  --help                     print this help

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
    } else if (flag == "--max-message-bytes") {
      server.max_message_bytes = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--idle-timeout") {
      server.idle_timeout_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--queue-packets") {
      server.queue_packets = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--backpressure-fraction") {
      server.backpressure_fraction = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-map-memory") {
      const int64_t mib = ParseIntegerFlag(flag, value);
      if (mib < 1 || mib > (int64_t{1} << 40)) {
        throw InvalidArgumentError("--max-map-memory must be 1 .. 2^40 MiB, got " + value);
      }
      server.max_map_memory_bytes = static_cast<uint64_t>(mib) << 20;
    } else if (flag == "--max-camera-pixels") {
      server.max_camera_pixels = ParseIntegerFlag(flag, value);
    } else if (flag == "--max-packet-span") {
      server.max_packet_span_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-rate") {
      server.max_step_rate_hz = ParseDoubleFlag(flag, value);
    } else if (flag == "--auth-tokens") {
      server.auth_tokens_file = value;
    } else if (flag == "--metrics") {
      server.metrics_address = value;
    } else if (flag == "--tls-cert") {
      server.tls_cert_file = value;
    } else if (flag == "--tls-key") {
      server.tls_key_file = value;
    } else if (flag == "--rate") {
      server.tracker.step_rate_hz = ParseDoubleFlag(flag, value);
    } else if (flag == "--variant") {
      server.tracker.SetVariant(value);
    } else if (flag == "--max-points") {
      server.tracker.max_points = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--tau") {
      server.tracker.decay_time_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--decay-trail") {
      server.tracker.decay_trail_px = ParseDoubleFlag(flag, value);
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
