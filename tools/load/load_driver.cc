#include "tools/load/load_driver.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <limits>
#include <mutex>
#include <random>
#include <thread>

#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "core/common/cli.h"
#include "core/common/cli_app.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/dataset/dataset.h"
#include "core/events/event_reader.h"
#include "evloc/localizer.grpc.pb.h"
#include "localizer/wire/packed_events.h"
#include "localizer/wire/percentile.h"
#include "localizer/wire/status_name.h"
#include "localizer/wire/twist.h"
#include "proto/convert/proto_convert.h"

namespace evloc::load {
namespace {

using Clock = std::chrono::steady_clock;
using wire::Percentile;

// How a session ends.
enum class Ending { kNormal, kCancel, kBadPacket };

// What every session sends: built once, shared read-only by the slots.
struct Workload {
  api::TrackRequest start;
  std::vector<api::TrackRequest> packets;
  // Start of the first packet's window, ns.
  int64_t origin_ns = 0;
  int64_t packet_ns = 0;
  // Index of the first packet whose window reaches past the initial time (earlier ones prime).
  size_t first_tracked_packet = 0;
  int sensor_width = 0;
  int64_t events = 0;
  // The dataset's ground truth (shared by the workloads), if any: the TRACKING poses are scored
  // against it.
  std::shared_ptr<const Trajectory> ground_truth;
};

// The events of the 50 ms before a staggered session's start prime its surfaces (the decay
// times are 5-30 ms).
constexpr int64_t kStaggerPrimeNs = 50'000'000;

// The workloads of a run: one at the dataset's start, or one per --stagger start.
std::vector<Workload> MakeWorkloads(const LoadOptions& options) {
  const Dataset dataset = ReadDataset(options.dataset);
  if (!dataset.events_path) {
    throw InvalidArgumentError("dataset '" + options.dataset.string() +
                               "' has no events.evb or events.txt");
  }
  const auto reader = OpenEventFile(*dataset.events_path);
  EventBuffer events;
  if (reader->Read(1, &events) == 0) {
    throw InvalidArgumentError("dataset '" + options.dataset.string() + "' has no events");
  }
  const TimedPose first = ResolveInitialPose(dataset, std::nullopt, events.t_ns[0]);
  const int count = std::max(1, options.stagger_count);
  const int64_t stagger_ns = static_cast<int64_t>(options.stagger_s * 1e9);
  const int64_t session_ns = static_cast<int64_t>(options.session_s * 1e9);
  const int64_t stop_ns = first.t_ns + (count - 1) * stagger_ns + session_ns;
  while (events.t_ns.back() <= stop_ns && reader->Read(1 << 20, &events) > 0) {
  }
  if (events.t_ns.back() < stop_ns) {
    throw InvalidArgumentError(
        "dataset '" + options.dataset.string() + "' ends " +
        std::to_string((stop_ns - events.t_ns.back()) * 1e-9) +
        " s before the last session would (--stagger COUNT:SECONDS and --session-s): give fewer "
        "or closer starts");
  }
  std::shared_ptr<const Trajectory> ground_truth;
  if (dataset.ground_truth)
    ground_truth = std::make_shared<const Trajectory>(*dataset.ground_truth);
  std::vector<Workload> workloads;
  for (int k = 0; k < count; ++k) {
    TimedPose initial = first;
    if (k > 0) {
      initial.t_ns = first.t_ns + k * stagger_ns;
      const std::optional<Rigid3d> pose =
          dataset.ground_truth ? dataset.ground_truth->Lookup(initial.t_ns) : std::nullopt;
      if (!pose) {
        throw InvalidArgumentError(
            "dataset '" + options.dataset.string() + "' has no ground truth " +
            std::to_string(k * options.stagger_s) + " s after its start (--stagger)");
      }
      initial.world_from_cam = *pose;
    }
    // The session's events: from the dataset's start (k = 0, as without --stagger) or the
    // priming window, to the end of its session time.
    const int64_t begin_ns = k == 0 ? events.t_ns.front() : initial.t_ns - kStaggerPrimeNs;
    const auto begin = std::lower_bound(events.t_ns.begin(), events.t_ns.end(), begin_ns);
    const auto end = std::upper_bound(begin, events.t_ns.end(), initial.t_ns + session_ns);
    EventBuffer session;
    session.Append(events, static_cast<size_t>(begin - events.t_ns.begin()),
                   static_cast<size_t>(end - begin));
    if (session.empty()) {
      throw InvalidArgumentError("dataset '" + options.dataset.string() + "' has no events " +
                                 std::to_string(k * options.stagger_s) +
                                 " s after its start (--stagger)");
    }
    Workload& workload = workloads.emplace_back();
    workload.packet_ns = options.packet_us * 1000;
    workload.origin_ns = session.t_ns.front() - 1;
    workload.sensor_width = dataset.camera.width;
    workload.events = static_cast<int64_t>(session.size());
    workload.ground_truth = ground_truth;
    for (api::EventPacket& packet :
         wire::PackEventWindows(session, workload.origin_ns, workload.packet_ns)) {
      *workload.packets.emplace_back().mutable_events() = std::move(packet);
    }
    workload.first_tracked_packet = static_cast<size_t>(
        std::max<int64_t>(0, (initial.t_ns - workload.origin_ns) / workload.packet_ns));
    api::SessionStart* start = workload.start.mutable_start();
    start->set_map_name(options.map_name);
    *start->mutable_camera() = CameraToProto(dataset.camera);
    *start->mutable_initial_world_from_cam() = RigidToProto(initial.world_from_cam);
    start->set_initial_t_ns(initial.t_ns);
    if (options.initial_velocity_from_truth) {
      const std::optional<Vector6d> velocity =
          ground_truth ? ground_truth->Velocity(initial.t_ns, wire::kClientVelocityWindowNs)
                       : std::nullopt;
      if (!velocity) {
        throw InvalidArgumentError("dataset '" + options.dataset.string() +
                                   "' has no ground truth around " +
                                   std::to_string(k * options.stagger_s) +
                                   " s after its start for --initial-velocity truth");
      }
      *start->mutable_initial_velocity() = wire::TwistToProto(*velocity);
    }
    if (options.step_rate_hz) start->mutable_options()->set_step_rate_hz(*options.step_rate_hz);
    start->set_client_name("evloc-load " + options.dataset.filename().string());
  }
  return workloads;
}

// What one session measured.
struct SessionOutcome {
  grpc::Status status;
  bool as_planned = false;
  int64_t packets = 0;
  int64_t events = 0;
  int64_t backpressure = 0;
  std::vector<double> server_latency_us;
  std::vector<double> client_latency_us;
  std::vector<double> step_ms;
  // Distance of each TRACKING pose from the ground truth at its time, metres.
  std::vector<double> error_m;
};

// A packet with one event outside the sensor (x = width) after the window's start.
api::TrackRequest BadPacket(const api::TrackRequest& packet, int width) {
  api::TrackRequest bad = packet;
  EventBuffer outside;
  outside.push_back({packet.events().time_base_ns() + 1, static_cast<uint16_t>(width), 0, 1});
  bad.mutable_events()->set_data(
      wire::EncodePackedEvents(outside, 0, 1, packet.events().time_base_ns()));
  return bad;
}

SessionOutcome RunSession(api::Localizer::Stub& stub, const Workload& workload,
                          const api::TrackRequest& start, const LoadOptions& options, Ending ending,
                          size_t cut) {
  SessionOutcome outcome;
  grpc::ClientContext context;
  auto stream = stub.Track(&context);
  api::TrackResponse response;
  if (!stream->Write(start) || !stream->Read(&response) || !response.has_started()) {
    outcome.status = stream->Finish();
    return outcome;
  }
  const size_t count = workload.packets.size();
  // With --speed max: at most a quarter of the server's queue unconfirmed, below the
  // Backpressure threshold (half, by default).
  const size_t max_in_flight = std::max<size_t>(1, response.started().queue_capacity() / 4);
  std::vector<std::atomic<int64_t>> sent_ns(count);
  for (auto& sent : sent_ns) sent = -1;
  std::mutex mutex;
  std::condition_variable confirmed_cv;
  // Packets [0, confirmed) are tracked: a pose reached their end (priming packets count).
  size_t confirmed = workload.first_tracked_packet;
  bool ended = false;
  std::thread reader([&] {
    api::TrackResponse message;
    while (stream->Read(&message)) {
      const int64_t now_ns = Clock::now().time_since_epoch().count();
      if (message.has_pose()) {
        const api::PoseUpdate& pose = message.pose();
        // The packet whose window holds the pose's time completed its step.
        const int64_t offset = pose.t_ns() - workload.origin_ns;
        const size_t index = static_cast<size_t>(
            std::clamp<int64_t>((offset + workload.packet_ns - 1) / workload.packet_ns - 1, 0,
                                static_cast<int64_t>(count) - 1));
        const int64_t sent = sent_ns[index].load(std::memory_order_acquire);
        std::lock_guard<std::mutex> lock(mutex);
        if (sent >= 0) outcome.client_latency_us.push_back((now_ns - sent) * 1e-3);
        outcome.server_latency_us.push_back(pose.latency_us());
        outcome.step_ms.push_back(pose.step_ms());
        if (workload.ground_truth && pose.status() == api::TRACKING && pose.has_world_from_cam()) {
          if (const auto truth = workload.ground_truth->Lookup(pose.t_ns())) {
            outcome.error_m.push_back(
                (RigidFromProto(pose.world_from_cam(), "PoseUpdate").translation -
                 truth->translation)
                    .norm());
          }
        }
        confirmed = std::max(confirmed, index + 1);
        confirmed_cv.notify_all();
      } else if (message.has_backpressure()) {
        std::lock_guard<std::mutex> lock(mutex);
        ++outcome.backpressure;
      }
    }
    std::lock_guard<std::mutex> lock(mutex);
    ended = true;
    confirmed_cv.notify_all();
  });

  const auto wall_start = Clock::now();
  bool cancelled = false;
  for (size_t i = 0; i < count; ++i) {
    if (ending == Ending::kCancel && i == cut) {
      context.TryCancel();
      cancelled = true;
      break;
    }
    if (options.speed) {
      const double session_s =
          static_cast<double>(workload.packets[i].events().end_t_ns() - workload.origin_ns) * 1e-9;
      std::this_thread::sleep_until(wall_start +
                                    std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(session_s / *options.speed)));
    } else {
      std::unique_lock<std::mutex> lock(mutex);
      confirmed_cv.wait(lock, [&] { return ended || i < confirmed + max_in_flight; });
      if (ended) break;
    }
    api::TrackRequest bad_packet;
    if (ending == Ending::kBadPacket && i == cut) {
      bad_packet = BadPacket(workload.packets[i], workload.sensor_width);
    }
    const api::TrackRequest& request = bad_packet.has_events() ? bad_packet : workload.packets[i];
    sent_ns[i].store(Clock::now().time_since_epoch().count(), std::memory_order_release);
    if (!stream->Write(request)) break;
    ++outcome.packets;
    outcome.events +=
        static_cast<int64_t>(request.events().data().size() / wire::kPackedEventBytes);
  }
  if (!cancelled) stream->WritesDone();
  reader.join();
  outcome.status = stream->Finish();
  const grpc::StatusCode planned = ending == Ending::kNormal   ? grpc::StatusCode::OK
                                   : ending == Ending::kCancel ? grpc::StatusCode::CANCELLED
                                                               : grpc::StatusCode::INVALID_ARGUMENT;
  outcome.as_planned = outcome.status.error_code() == planned;
  return outcome;
}

nlohmann::json ResultJson(const LoadOptions& options, const LoadResult& result) {
  nlohmann::json json;
  json["server"] = options.server;
  json["dataset"] = options.dataset.string();
  json["sessions"] = options.sessions;
  json["session_s"] = options.session_s;
  json["duration_s"] = options.duration_s;
  json["speed"] = options.speed ? nlohmann::json(*options.speed) : nlohmann::json("max");
  json["packet_us"] = options.packet_us;
  json["sessions_opened"] = result.sessions;
  json["sessions_as_planned"] = result.sessions_as_planned;
  json["normal_sessions"] = result.normal_sessions;
  json["cancelled_sessions"] = result.cancelled_sessions;
  json["bad_packet_sessions"] = result.bad_packet_sessions;
  json["unplanned"] = result.unplanned;
  json["unplanned_messages"] = result.unplanned_messages;
  json["packets"] = result.packets;
  json["events"] = result.events;
  json["poses"] = result.poses;
  json["backpressure_notices"] = result.backpressure_notices;
  json["server_latency_us"] = {{"p50", result.server_latency_p50_us},
                               {"p95", result.server_latency_p95_us},
                               {"p99", result.server_latency_p99_us},
                               {"max", result.server_latency_max_us}};
  json["client_latency_us"] = {{"p50", result.client_latency_p50_us},
                               {"p99", result.client_latency_p99_us},
                               {"max", result.client_latency_max_us}};
  json["step_ms"] = {
      {"p50", result.step_p50_ms}, {"p95", result.step_p95_ms}, {"p99", result.step_p99_ms}};
  json["error_m"] = {{"p50", result.error_p50_m}, {"max", result.error_max_m}};
  json["wall_s"] = result.wall_s;
  return json;
}

}  // namespace

void LoadOptions::Check() const {
  if (server.empty()) throw InvalidArgumentError("--server is required: the localizer's host:port");
  if (map_name.empty()) throw InvalidArgumentError("--map is required: a map name (ListMaps)");
  if (dataset.empty()) throw InvalidArgumentError("--dataset is required: a dataset folder");
  if (sessions < 1 || sessions > 1024) throw InvalidArgumentError("--sessions must be 1..1024");
  if (!(session_s > 0)) throw InvalidArgumentError("--session-s must be positive");
  if (!(duration_s >= 0)) throw InvalidArgumentError("--duration must be 0 or positive");
  if (speed && !(*speed > 0)) throw InvalidArgumentError("--speed must be positive or 'max'");
  if (packet_us < 1 || packet_us > 1'000'000) {
    throw InvalidArgumentError("--packet-us must be in 1..1000000");
  }
  if (step_rate_hz && !(*step_rate_hz > 0)) throw InvalidArgumentError("--rate must be positive");
  if (stagger_count < 0 || stagger_count > 10000 || !std::isfinite(stagger_s) || stagger_s < 0 ||
      (stagger_count > 1 && !(stagger_s > 0))) {
    throw InvalidArgumentError("--stagger needs a count in 0..10000 and positive seconds");
  }
  if (!(cancel_fraction >= 0 && bad_fraction >= 0 && cancel_fraction + bad_fraction <= 1)) {
    throw InvalidArgumentError(
        "--cancel-fraction and --bad-fraction must be >= 0 with a sum of at most 1");
  }
}

LoadResult RunLoad(const LoadOptions& options, std::ostream& log) {
  options.Check();
  const std::vector<Workload> workloads = MakeWorkloads(options);
  log << "evloc-load: " << options.sessions << " session slots, "
      << workloads.front().packets.size() << " packets (" << workloads.front().events
      << " events) per session";
  if (workloads.size() > 1) log << " (the first of " << workloads.size() << " starts)";
  log << ", speed " << (options.speed ? std::to_string(*options.speed) : std::string("max"))
      << ", run " << options.duration_s << " s\n";
  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(64 << 20);
  // One connection per slot, as separate clients would have.
  arguments.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);

  LoadResult result;
  std::mutex mutex;
  std::vector<double> server_latency_us;
  std::vector<double> client_latency_us;
  std::vector<double> step_ms;
  std::vector<double> error_m;
  const auto wall_start = Clock::now();
  const auto deadline = wall_start + std::chrono::duration_cast<Clock::duration>(
                                         std::chrono::duration<double>(options.duration_s));
  std::vector<std::thread> slots;
  int64_t session_next = 0;  // the k of --spread and --stagger
  for (int slot = 0; slot < options.sessions; ++slot) {
    slots.emplace_back([&, slot] {
      auto stub = api::Localizer::NewStub(
          grpc::CreateCustomChannel(options.server, grpc::InsecureChannelCredentials(), arguments));
      std::mt19937 random(options.seed * 7919u + static_cast<uint32_t>(slot));
      std::uniform_real_distribution<double> unit(0.0, 1.0);
      do {
        int64_t k = 0;
        {
          std::lock_guard<std::mutex> lock(mutex);
          k = session_next++;
        }
        const Workload& workload = workloads[static_cast<size_t>(k) % workloads.size()];
        std::uniform_int_distribution<size_t> packet_index(workload.first_tracked_packet,
                                                           workload.packets.size() - 1);
        const double draw = unit(random);
        const Ending ending = draw < options.cancel_fraction ? Ending::kCancel
                              : draw < options.cancel_fraction + options.bad_fraction
                                  ? Ending::kBadPacket
                                  : Ending::kNormal;
        api::TrackRequest start = workload.start;
        if (options.spread_columns > 0) {
          auto* translation =
              start.mutable_start()->mutable_initial_world_from_cam()->mutable_translation();
          translation->set_x(translation->x() + static_cast<double>(k % options.spread_columns) *
                                                    options.spread_pitch_m);
          translation->set_y(translation->y() + static_cast<double>((k / options.spread_columns) %
                                                                    options.spread_rows) *
                                                    options.spread_pitch_m);
        }
        const SessionOutcome outcome =
            RunSession(*stub, workload, start, options, ending, packet_index(random));
        std::lock_guard<std::mutex> lock(mutex);
        ++result.sessions;
        result.normal_sessions += ending == Ending::kNormal;
        result.cancelled_sessions += ending == Ending::kCancel;
        result.bad_packet_sessions += ending == Ending::kBadPacket;
        if (outcome.as_planned) {
          ++result.sessions_as_planned;
        } else {
          ++result.unplanned[wire::StatusCodeName(outcome.status.error_code())];
          if (result.unplanned_messages.size() < 5) {
            result.unplanned_messages.push_back(outcome.status.error_message());
          }
        }
        result.packets += outcome.packets;
        result.events += outcome.events;
        result.poses += static_cast<int64_t>(outcome.server_latency_us.size());
        result.backpressure_notices += outcome.backpressure;
        server_latency_us.insert(server_latency_us.end(), outcome.server_latency_us.begin(),
                                 outcome.server_latency_us.end());
        client_latency_us.insert(client_latency_us.end(), outcome.client_latency_us.begin(),
                                 outcome.client_latency_us.end());
        step_ms.insert(step_ms.end(), outcome.step_ms.begin(), outcome.step_ms.end());
        error_m.insert(error_m.end(), outcome.error_m.begin(), outcome.error_m.end());
      } while (Clock::now() < deadline);
    });
  }
  for (std::thread& slot : slots) slot.join();
  result.wall_s = std::chrono::duration<double>(Clock::now() - wall_start).count();
  result.server_latency_p50_us = Percentile(server_latency_us, 0.5);
  result.server_latency_p95_us = Percentile(server_latency_us, 0.95);
  result.server_latency_p99_us = Percentile(server_latency_us, 0.99);
  result.server_latency_max_us = Percentile(server_latency_us, 1.0);
  result.client_latency_p50_us = Percentile(client_latency_us, 0.5);
  result.client_latency_p99_us = Percentile(client_latency_us, 0.99);
  result.client_latency_max_us = Percentile(client_latency_us, 1.0);
  result.step_p50_ms = Percentile(step_ms, 0.5);
  result.step_p95_ms = Percentile(step_ms, 0.95);
  result.step_p99_ms = Percentile(step_ms, 0.99);
  result.error_p50_m = Percentile(error_m, 0.5);
  result.error_max_m = Percentile(error_m, 1.0);

  log << "evloc-load: " << result.sessions << " sessions (" << result.normal_sessions << " normal, "
      << result.cancelled_sessions << " cancelled, " << result.bad_packet_sessions
      << " with a bad packet), " << result.sessions_as_planned << " ended as planned";
  for (const auto& [name, count] : result.unplanned) log << ", " << count << " " << name;
  log << "; " << result.poses << " poses, " << result.backpressure_notices
      << " backpressure notices, " << result.wall_s << " s\n"
      << "evloc-load: server latency p50 " << result.server_latency_p50_us << " us p99 "
      << result.server_latency_p99_us << " us max " << result.server_latency_max_us
      << " us; client latency p50 " << result.client_latency_p50_us << " us p99 "
      << result.client_latency_p99_us << " us max " << result.client_latency_max_us
      << " us; step p50 " << result.step_p50_ms << " ms p99 " << result.step_p99_ms << " ms\n";
  if (!error_m.empty()) {
    log << "evloc-load: TRACKING poses against the ground truth: median " << result.error_p50_m
        << " m, max " << result.error_max_m << " m\n";
  }
  for (const std::string& message : result.unplanned_messages) {
    log << "evloc-load: unplanned: " << message << "\n";
  }
  if (options.report) WriteFileAtomically(*options.report, ResultJson(options, result).dump(2));
  return result;
}

namespace {

// What the command line asks for.
struct LoadArguments {
  LoadOptions options;
  // --help was given.
  bool help = false;
};

// Applies --spread COLUMNSxROWS:PITCH.
void ApplySpread(const std::string& flag, const std::string& value, LoadOptions* options) {
  const size_t x = value.find('x');
  const size_t colon = value.find(':');
  if (x == std::string::npos || colon == std::string::npos || colon < x) {
    throw InvalidArgumentError("--spread expects COLUMNSxROWS:PITCH, e.g. 8x8:5");
  }
  options->spread_columns = ParseIntFlag(flag, value.substr(0, x));
  options->spread_rows = ParseIntFlag(flag, value.substr(x + 1, colon - x - 1));
  options->spread_pitch_m = ParseDoubleFlag(flag, value.substr(colon + 1));
  if (options->spread_columns < 1 || options->spread_rows < 1 || !(options->spread_pitch_m > 0)) {
    throw InvalidArgumentError("--spread needs positive columns, rows and pitch");
  }
}

// Applies --stagger COUNT:SECONDS.
void ApplyStagger(const std::string& flag, const std::string& value, LoadOptions* options) {
  const size_t colon = value.find(':');
  if (colon == std::string::npos) {
    throw InvalidArgumentError("--stagger expects COUNT:SECONDS, e.g. 20:2.5");
  }
  options->stagger_count = ParseIntFlag(flag, value.substr(0, colon));
  options->stagger_s = ParseDoubleFlag(flag, value.substr(colon + 1));
}

// The command line of evloc-load over `arguments`.
std::unique_ptr<CommandLine> DeclareLoadCommandLine(LoadArguments* arguments) {
  LoadOptions* options = &arguments->options;
  auto line = std::make_unique<CommandLine>(
      "evloc-load", "--server HOST:PORT --map NAME --dataset DIR [options]",
      "Runs many Track sessions at once against an evloc localizer (docs/benchmarks.md §4, "
      "docs/reliability.md §4): each session slot opens a session, streams the dataset's events "
      "as PACKED 1 ms packets, ends it and opens the next until --duration has elapsed. Prints "
      "sessions, how they ended, poses, backpressure notices and the latency percentiles.");
  line->Add("--server", "HOST:PORT", "localizer address (required)", &options->server)
      .Add("--map", "NAME", "map name on the server (required)", &options->map_name)
      .Add("--dataset", "DIR", "dataset folder with ground truth for the initial pose (required)",
           &options->dataset)
      .Add("--sessions", "N", "concurrent session slots (default 1)", &options->sessions)
      .Add("--session-s", "S",
           "session time streamed per session after the initial pose (default 1)",
           &options->session_s)
      .Add("--duration", "S",
           "keep opening sessions for S seconds of wall time (default 0: one session per slot)",
           &options->duration_s)
      .Add("--speed", "S|max",
           "playback speed relative to real time (default 1), or max: as fast as the server "
           "confirms packets (at most a quarter of its queue in flight)",
           [options](const std::string& flag, const std::string& value) {
             options->speed = ParseDoubleOrWordFlag(flag, value, "max");
           })
      .Add("--packet-us", "N", "time window per packet, microseconds (default 1000)",
           &options->packet_us)
      .Add("--rate", "HZ", "tracking steps per second (default: the server's)",
           &options->step_rate_hz)
      .Add("--cancel-fraction", "F",
           "fraction of sessions the client cancels at a random packet (default 0)",
           &options->cancel_fraction)
      .Add("--bad-fraction", "F",
           "fraction of sessions that send an event outside the sensor at a random packet, "
           "expecting INVALID_ARGUMENT (default 0)",
           &options->bad_fraction)
      .Add("--spread", "CxR:P",
           "the k-th session starts at its pose moved by ((k mod C) * P, ((k / C) mod R) * P, 0) "
           "metres: sessions spread over a site made of copies of the dataset's scene "
           "(docs/benchmarks.md, \"Sites\")",
           [options](const std::string& flag, const std::string& value) {
             ApplySpread(flag, value, options);
           })
      .Add("--stagger", "N:S",
           "the k-th session starts (k mod N) * S seconds into the dataset, from its ground "
           "truth there (50 ms of events before it prime): sessions along a long route "
           "(docs/benchmarks.md, \"Sites\")",
           [options](const std::string& flag, const std::string& value) {
             ApplyStagger(flag, value, options);
           })
      .Add("--initial-velocity", "rest|truth",
           "how each session starts: at rest (default), or moving with the ground truth's "
           "velocity at its start (SessionStart.initial_velocity), as a vehicle client that knows "
           "its speed can",
           [options](const std::string& flag, const std::string& value) {
             options->initial_velocity_from_truth = ParseTwoWordFlag(flag, value, "rest", "truth");
           })
      .Add("--seed", "N", "seed of those random choices (default 1)",
           [options](const std::string& flag, const std::string& value) {
             options->seed = static_cast<uint32_t>(ParseIntegerFlag(flag, value));
           })
      .Add("--report", "PATH", "write the figures as JSON", &options->report)
      .Footer(
          "Exit codes: 0 every session ended as planned, 1 some did not (or failure), 2 bad "
          "command line.");
  return line;
}

}  // namespace

std::string LoadUsage() { return HelpOfDeclaredCommandLine(&DeclareLoadCommandLine); }

LoadOptions ParseLoadCommandLine(const std::vector<std::string>& arguments, bool* help) {
  const LoadArguments parsed = ParseDeclaredCommandLine(&DeclareLoadCommandLine, arguments);
  *help = parsed.help;
  if (!parsed.help) parsed.options.Check();
  return parsed.options;
}

}  // namespace evloc::load
