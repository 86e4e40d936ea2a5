#include "tools/replay/replay.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <mutex>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "core/common/cli.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/events/event_reader.h"
#include "core/trajectory/tum_io.h"
#include "evloc/localizer.grpc.pb.h"
#include "localizer/offline/track_command.h"
#include "localizer/service/session.h"
#include "tools/replay/evt3_encoder.h"
#include "tools/sim/dataset.h"

namespace evloc::replay {
namespace {

using Clock = std::chrono::steady_clock;

double Percentile(std::vector<double> values, double fraction) {
  if (values.empty()) return 0.0;
  const size_t index = std::min(values.size() - 1,
                                static_cast<size_t>(fraction * static_cast<double>(values.size())));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(index),
                   values.end());
  return values[index];
}

// Floor division for possibly negative numerators.
int64_t FloorDiv(int64_t numerator, int64_t denominator) {
  int64_t quotient = numerator / denominator;
  if ((numerator % denominator != 0) && ((numerator < 0) != (denominator < 0))) --quotient;
  return quotient;
}

// Reads events from a file one at a time, in batches underneath.
class EventSource {
 public:
  explicit EventSource(EventReader& reader) : reader_(reader) { Refill(); }
  bool has_event() const { return index_ < batch_.size(); }
  Event event() const { return batch_[index_]; }
  void Advance() {
    if (++index_ >= batch_.size()) Refill();
  }

 private:
  void Refill() {
    batch_.clear();
    index_ = 0;
    reader_.Read(1 << 16, &batch_);
  }
  EventReader& reader_;
  EventBuffer batch_;
  size_t index_ = 0;
};

// A packet as sent: its last event's time and when it was sent.
struct SentPacket {
  std::optional<int64_t> last_event_t_ns;
  Clock::time_point sent;
};

// State shared between the sending loop and the response reader.
struct SharedState {
  std::mutex mutex;
  std::condition_variable pose_arrived;
  std::deque<SentPacket> sent;
  std::vector<TimedPose> poses;
  std::vector<bool> tracking;
  std::vector<double> client_latency_us;
  std::vector<double> server_latency_us;
  std::vector<double> server_overhead_us;
  std::vector<double> step_ms;
  int64_t lost = 0;
  int64_t backpressure = 0;
  int64_t last_pose_t_ns = 0;
  // Window ends of the packets sent whose tracking no pose has confirmed yet.
  std::deque<int64_t> unconfirmed_window_ends;
  bool ended = false;
};

}  // namespace

void ReplayOptions::Check() const {
  if (server.empty()) throw InvalidArgumentError("--server is required: the localizer's host:port");
  if (map_name.empty()) throw InvalidArgumentError("--map is required: a map name (ListMaps)");
  if (dataset.empty()) throw InvalidArgumentError("--dataset is required: a dataset folder");
  if (output.empty()) throw InvalidArgumentError("--out is required: the TUM trajectory to write");
  if (speed && !(*speed > 0)) throw InvalidArgumentError("--speed must be positive or 'max'");
  if (packet_us < 1 || packet_us > 1'000'000) {
    throw InvalidArgumentError("--packet-us must be in 1..1000000");
  }
  if (!(max_lead_ms > 0)) throw InvalidArgumentError("--max-lead-ms must be positive");
  if (duration_s && !(*duration_s > 0)) throw InvalidArgumentError("--duration must be positive");
  if (step_rate_hz && !(*step_rate_hz > 0)) throw InvalidArgumentError("--rate must be positive");
  if (ecd_width <= 0 || ecd_height <= 0) {
    throw InvalidArgumentError("--ecd-size must be WIDTHxHEIGHT with positive sizes");
  }
  if (tls_server_name && !tls_ca_file) {
    throw InvalidArgumentError("--tls-server-name needs --tls-ca");
  }
}

ReplayResult RunReplay(const ReplayOptions& options, std::ostream& log) {
  options.Check();
  sim::DatasetReaderOptions reader_options;
  reader_options.ecd_width = options.ecd_width;
  reader_options.ecd_height = options.ecd_height;
  const sim::Dataset dataset = sim::ReadDataset(options.dataset, reader_options);
  if (!dataset.events_path) {
    throw InvalidArgumentError("dataset '" + options.dataset.string() +
                               "' has no events.evb or events.txt");
  }
  const auto reader = OpenEventFile(*dataset.events_path);
  EventSource source(*reader);
  if (!source.has_event()) {
    throw InvalidArgumentError("dataset '" + options.dataset.string() + "' has no events");
  }
  const int64_t first_t_ns = source.event().t_ns;
  const TimedPose initial =
      tracking::ResolveInitialPose(dataset, options.initial_world_from_cam, first_t_ns);
  const Rigid3d& initial_world_from_cam = initial.world_from_cam;
  const int64_t initial_t_ns = initial.t_ns;
  const bool evt3 = options.encoding == WireEncoding::kEvt3;
  // EVT 3.0 carries microseconds from a sensor origin: sensor time = session time - offset.
  const int64_t sensor_offset_ns = FloorDiv(first_t_ns, 1000) * 1000;
  const auto session_time = [&](int64_t t_ns) {
    if (!evt3) return t_ns;
    return sensor_offset_ns + (FloorDiv(t_ns - sensor_offset_ns + 999, 1000)) * 1000;
  };

  grpc::ChannelArguments channel_arguments;
  channel_arguments.SetMaxReceiveMessageSize(64 << 20);
  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
  if (options.tls_ca_file) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = ReadFileToString(*options.tls_ca_file);
    credentials = grpc::SslCredentials(ssl);
    if (options.tls_server_name)
      channel_arguments.SetSslTargetNameOverride(*options.tls_server_name);
  }
  auto channel = grpc::CreateCustomChannel(options.server, credentials, channel_arguments);
  auto stub = api::Localizer::NewStub(channel);
  grpc::ClientContext context;
  if (options.token) context.AddMetadata("authorization", "Bearer " + *options.token);
  auto stream = stub->Track(&context);

  api::TrackRequest start_request;
  api::SessionStart* start = start_request.mutable_start();
  start->set_map_name(options.map_name);
  *start->mutable_camera() = service::CameraToProto(dataset.camera);
  *start->mutable_initial_world_from_cam() = service::RigidToProto(initial_world_from_cam);
  start->set_initial_t_ns(initial_t_ns);
  if (options.step_rate_hz) start->mutable_options()->set_step_rate_hz(*options.step_rate_hz);
  start->set_sensor_time_offset_ns(sensor_offset_ns);
  start->set_client_name("evloc-replay " + options.dataset.filename().string());

  const auto fail = [&](const std::string& what) -> Error {
    const grpc::Status status = stream->Finish();
    return Error(what + ": " + std::to_string(status.error_code()) + " " + status.error_message());
  };
  api::TrackResponse response;
  if (!stream->Write(start_request) || !stream->Read(&response) || !response.has_started()) {
    throw fail("the server refused the session (status code, message)");
  }
  log << "evloc-replay: session " << response.started().session_id() << " on map "
      << response.started().map().name() << " version " << response.started().map().version()
      << ", " << response.started().variant() << " at " << response.started().step_rate_hz()
      << " Hz, " << (evt3 ? "EVT 3.0" : "PACKED") << " packets of " << options.packet_us
      << " us, speed " << (options.speed ? std::to_string(*options.speed) : std::string("max"))
      << "\n";

  SharedState shared;
  shared.last_pose_t_ns = initial_t_ns;
  api::SessionEnd end;
  std::thread response_reader([&] {
    api::TrackResponse message;
    while (stream->Read(&message)) {
      const auto now = Clock::now();
      std::lock_guard<std::mutex> lock(shared.mutex);
      if (message.has_pose()) {
        const api::PoseUpdate& pose = message.pose();
        while (!shared.sent.empty() && (!shared.sent.front().last_event_t_ns ||
                                        *shared.sent.front().last_event_t_ns <= pose.t_ns())) {
          shared.sent.pop_front();
        }
        if (!shared.sent.empty()) {
          shared.client_latency_us.push_back(
              std::chrono::duration<double, std::micro>(now - shared.sent.front().sent).count());
        }
        shared.server_latency_us.push_back(pose.latency_us());
        shared.server_overhead_us.push_back(pose.latency_us() - pose.step_ms() * 1e3);
        shared.step_ms.push_back(pose.step_ms());
        shared.poses.push_back(
            {pose.t_ns(), service::RigidFromProto(pose.world_from_cam(), "PoseUpdate")});
        shared.tracking.push_back(pose.status() == api::TRACKING);
        if (pose.status() == api::LOST) ++shared.lost;
        shared.last_pose_t_ns = pose.t_ns();
        // The step at t ran after every event up to t was ingested.
        while (!shared.unconfirmed_window_ends.empty() &&
               shared.unconfirmed_window_ends.front() <= pose.t_ns()) {
          shared.unconfirmed_window_ends.pop_front();
        }
        shared.pose_arrived.notify_all();
      } else if (message.has_backpressure()) {
        ++shared.backpressure;
      } else if (message.has_end()) {
        end = message.end();
        shared.ended = true;
      }
    }
    std::lock_guard<std::mutex> lock(shared.mutex);
    shared.ended = true;
    shared.pose_arrived.notify_all();
  });

  ReplayResult result;
  const auto wall_start = Clock::now();
  const int64_t packet_ns = options.packet_us * 1000;
  const int64_t window_origin_ns = session_time(first_t_ns) - 1;
  // Session time at which the replay stops (no limit without --duration).
  const int64_t stop_ns =
      options.duration_s
          ? initial_t_ns + static_cast<int64_t>(std::llround(*options.duration_s * 1e9))
          : std::numeric_limits<int64_t>::max();
  // With --speed max: packets in flight, at most half the server's queue and max_lead_ms.
  const size_t max_in_flight = static_cast<size_t>(std::max<int64_t>(
      1, std::min<int64_t>(response.started().queue_capacity() / 2,
                           static_cast<int64_t>(options.max_lead_ms * 1e3) / options.packet_us)));
  Evt3Encoder encoder;
  EventBuffer window_events;
  bool stream_open = true;
  for (int64_t window_start = window_origin_ns; stream_open && source.has_event();
       window_start += packet_ns) {
    const int64_t window_end = window_start + packet_ns;
    if (window_start >= stop_ns) break;
    window_events.clear();
    while (source.has_event() && session_time(source.event().t_ns) <= window_end) {
      Event event = source.event();
      event.t_ns = session_time(event.t_ns) - (evt3 ? sensor_offset_ns : 0);
      window_events.push_back(event);
      source.Advance();
    }
    api::TrackRequest request;
    api::EventPacket* packet = request.mutable_events();
    packet->set_end_t_ns(window_end);
    if (evt3) {
      packet->set_encoding(api::EVENT_ENCODING_EVT3);
      encoder.Encode(window_events, packet->mutable_data());
    } else {
      packet->set_encoding(api::EVENT_ENCODING_PACKED);
      packet->set_time_base_ns(window_start);
      packet->set_data(
          service::EncodePackedEvents(window_events, 0, window_events.size(), window_start));
    }
    // Pacing.
    if (options.speed) {
      const auto due =
          wall_start +
          std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(
              static_cast<double>(window_end - window_origin_ns) * 1e-9 / *options.speed));
      std::this_thread::sleep_until(due);
    } else {
      std::unique_lock<std::mutex> lock(shared.mutex);
      // A pose confirms packets; without one for 20 ms (e.g. while the first events only prime
      // the time surfaces) one more packet goes out.
      shared.pose_arrived.wait_for(lock, std::chrono::milliseconds(20), [&] {
        return shared.ended || shared.unconfirmed_window_ends.size() < max_in_flight;
      });
    }
    {
      std::lock_guard<std::mutex> lock(shared.mutex);
      shared.sent.push_back(
          {window_events.empty()
               ? std::nullopt
               : std::optional<int64_t>(window_events.t_ns.back() + (evt3 ? sensor_offset_ns : 0)),
           Clock::now()});
      shared.unconfirmed_window_ends.push_back(window_end);
    }
    stream_open = stream->Write(request);
    result.events_sent += static_cast<int64_t>(window_events.size());
    ++result.packets_sent;
  }
  stream->WritesDone();
  response_reader.join();
  const grpc::Status status = stream->Finish();
  result.wall_s = std::chrono::duration<double>(Clock::now() - wall_start).count();
  if (!status.ok()) {
    throw Error("the session failed after " + std::to_string(result.packets_sent) +
                " packets: " + std::to_string(status.error_code()) + " " + status.error_message());
  }
  result.trajectory = Trajectory(shared.poses);
  result.tracking = shared.tracking;
  result.lost_poses = shared.lost;
  result.backpressure_notices = shared.backpressure;
  result.client_latency_p50_us = Percentile(shared.client_latency_us, 0.5);
  result.client_latency_p99_us = Percentile(shared.client_latency_us, 0.99);
  result.server_latency_p50_us = Percentile(shared.server_latency_us, 0.5);
  result.server_latency_p99_us = Percentile(shared.server_latency_us, 0.99);
  result.server_overhead_p50_us = Percentile(shared.server_overhead_us, 0.5);
  result.server_overhead_p99_us = Percentile(shared.server_overhead_us, 0.99);
  result.step_p50_ms = Percentile(shared.step_ms, 0.5);
  WriteTumTrajectory(options.output, result.trajectory);
  log << "evloc-replay: sent " << result.events_sent << " events in " << result.packets_sent
      << " packets, received " << result.trajectory.size() << " poses (" << result.lost_poses
      << " LOST), " << result.backpressure_notices << " backpressure notices, in " << result.wall_s
      << " s\n"
      << "evloc-replay: latency client p50 " << result.client_latency_p50_us << " us p99 "
      << result.client_latency_p99_us << " us; server p50 " << result.server_latency_p50_us
      << " us p99 " << result.server_latency_p99_us << " us (of which outside the step: p50 "
      << result.server_overhead_p50_us << " us p99 " << result.server_overhead_p99_us
      << " us); median step " << result.step_p50_ms << " ms\n"
      << "evloc-replay: server totals: " << end.events() << " events, " << end.poses()
      << " poses; trajectory written to " << options.output.string() << "\n";
  return result;
}

std::string ReplayUsage() {
  return R"(Usage: evloc-replay --server HOST:PORT --map NAME --dataset DIR --out TRAJ.txt [options]

Streams a dataset's events to an evloc localizer (docs/api.md) as a live camera would, writes
the poses it gets back as a TUM trajectory, and prints events sent, poses received and the
packet-to-pose latency (p50, p99).

Options:
  --server HOST:PORT     localizer address (required)
  --map NAME             map name on the server (required)
  --dataset DIR          dataset folder, evloc or Event Camera Dataset layout (required)
  --out PATH             output TUM trajectory (required)
  --speed S|max          playback speed relative to real time (default 1), or max: as fast as
                         the server keeps up
  --encoding packed|evt3 wire encoding (default packed; evt3 rounds times up to microseconds)
  --packet-us N          time window per packet, microseconds (default 1000)
  --token T              bearer token (sent as 'authorization: Bearer T')
  --tls-ca PEM           use TLS, trusting these root certificates (default plaintext)
  --tls-server-name NAME host name in the server's certificate, when not --server's host
  --init-pose "tx ty tz qx qy qz qw"
                         initial world_from_cam (default: first ground-truth pose)
  --rate HZ              tracking steps per second (default: the server's)
  --max-lead-ms MS       with --speed max: session time sent ahead of the last pose (default 50)
  --duration S           stop after S seconds of session time after the initial pose
  --ecd-size WxH         sensor size for ECD folders with calib.txt only (default 240x180)
  --help                 print this help

Exit codes: 0 success, 1 failure (including a session the server ended with an error),
2 bad command line.
)";
}

ReplayOptions ParseReplayCommandLine(const std::vector<std::string>& arguments, bool* help) {
  ReplayOptions options;
  *help = false;
  for (size_t i = 0; i < arguments.size(); ++i) {
    const std::string& flag = arguments[i];
    if (flag == "--help" || flag == "-h") {
      *help = true;
      return options;
    }
    if (i + 1 >= arguments.size()) {
      throw InvalidArgumentError(flag.rfind("--", 0) == 0 ? flag + " needs a value"
                                                          : "unexpected argument '" + flag + "'");
    }
    const std::string& value = arguments[++i];
    if (flag == "--server") {
      options.server = value;
    } else if (flag == "--map") {
      options.map_name = value;
    } else if (flag == "--dataset") {
      options.dataset = value;
    } else if (flag == "--out") {
      options.output = value;
    } else if (flag == "--speed") {
      options.speed =
          value == "max" ? std::nullopt : std::optional<double>(ParseDoubleFlag(flag, value));
    } else if (flag == "--encoding") {
      if (value == "packed") {
        options.encoding = WireEncoding::kPacked;
      } else if (value == "evt3") {
        options.encoding = WireEncoding::kEvt3;
      } else {
        throw InvalidArgumentError("--encoding expects packed or evt3, got '" + value + "'");
      }
    } else if (flag == "--packet-us") {
      options.packet_us = ParseIntegerFlag(flag, value);
    } else if (flag == "--token") {
      options.token = value;
    } else if (flag == "--tls-ca") {
      options.tls_ca_file = value;
    } else if (flag == "--tls-server-name") {
      options.tls_server_name = value;
    } else if (flag == "--init-pose") {
      options.initial_world_from_cam = tracking::ParsePoseText(flag, value);
    } else if (flag == "--rate") {
      options.step_rate_hz = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-lead-ms") {
      options.max_lead_ms = ParseDoubleFlag(flag, value);
    } else if (flag == "--duration") {
      options.duration_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--ecd-size") {
      ParseSizeFlag(flag, value, &options.ecd_width, &options.ecd_height);
    } else {
      throw InvalidArgumentError("unknown flag '" + flag + "' (see --help)");
    }
  }
  options.Check();
  return options;
}

}  // namespace evloc::replay
