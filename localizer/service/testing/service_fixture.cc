#include "localizer/service/testing/service_fixture.h"

#include <algorithm>
#include <cmath>

#include <algorithm>
#include <atomic>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "core/dataset/dataset.h"
#include "core/events/evb.h"
#include "core/geometry/rigid3.h"
#include "core/trajectory/trajectory.h"
#include "localizer/service/session.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "localizer/wire/packed_events.h"
#include "maps/map_directory.h"
#include "proto/convert/proto_convert.h"

namespace evloc::service::testing {

Map TestMap() {
  return tracking::testing::MakeRectangleMap(tracking::testing::DefaultRectangles(), 0.01);
}

Map TestMapWithKeyframesBesideThePath() {
  Map map = TestMap();
  tracking::testing::AddKeyframesBesideThePath(
      &map, TestCamera(), 600'000'000, 150'000'000,
      (Vector6d() << 0.05, -0.03, 0.0, 0.0, 0.05, 0.0).finished());
  return map;
}

Camera TestCamera() { return Camera::Pinhole(320, 240, 250, 250, 159.5, 119.5); }

EventBuffer TestEvents(int64_t duration_ns, tracking::testing::EdgeEventTiming timing) {
  return tracking::testing::SimulateEdgeEvents(
      TestMap(), TestCamera(), [](int64_t t) { return tracking::testing::SmoothMotion(t); }, 0,
      duration_ns, 100'000, timing);
}

void WriteTestMap(const std::filesystem::path& maps_dir, const std::string& name, const Map& map) {
  MapDirectoryWriteOptions options;
  options.overwrite = true;
  options.write_ply = false;
  WriteMapDirectory(maps_dir / name, map, options);
}

std::filesystem::path WriteTestDataset(const std::filesystem::path& root, int64_t duration_ns,
                                       tracking::testing::EdgeEventTiming timing) {
  const std::filesystem::path out = root / "dataset";
  DatasetWriter writer(out, {});
  writer.WriteCamera(TestCamera());
  std::vector<TimedPose> poses;
  for (int64_t t = kInitialTimeNs; t <= duration_ns; t += 5'000'000) {
    poses.push_back({t, tracking::testing::SmoothMotion(t)});
  }
  writer.WriteGroundTruth(Trajectory(poses));
  EvbWriter events(writer.staging_dir() / dataset_files::kEventsEvb, SensorSize{320, 240});
  events.Write(TestEvents(duration_ns, timing));
  events.Close();
  writer.Commit();
  return out;
}

LocalizerServerOptions TestServerOptions(const std::filesystem::path& maps_dir) {
  LocalizerServerOptions options;
  options.maps_dir = maps_dir;
  options.listen_address = "127.0.0.1:0";
  options.max_sessions = 4;
  options.idle_timeout_s = 5.0;
  // Tests run beside other tests (ctest -j): at the default idle priority a searching session
  // would get no CPU while they are busy, and its idle timeout would end it. The priority
  // itself is tested by TrackingPool.BackgroundJobsRunOnTheirOwnWorkersAndNeverHoldATrackingWorker.
  options.search_priority = TrackingPool::BackgroundPriority::kNormal;
  return options;
}

std::unique_ptr<api::Localizer::Stub> ConnectStub(int port) {
  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(64 << 20);
  arguments.SetMaxSendMessageSize(64 << 20);
  return api::Localizer::NewStub(grpc::CreateCustomChannel(
      "127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials(), arguments));
}

api::TrackRequest TestSessionStart() {
  api::TrackRequest request;
  api::SessionStart* start = request.mutable_start();
  start->set_map_name(kTestMapName);
  *start->mutable_camera() = CameraToProto(TestCamera());
  *start->mutable_initial_world_from_cam() =
      RigidToProto(tracking::testing::SmoothMotion(kInitialTimeNs));
  start->set_initial_t_ns(kInitialTimeNs);
  start->mutable_options()->set_step_rate_hz(200);
  start->set_client_name("test");
  return request;
}

api::TrackRequest DepthFrameRequest(int64_t t_ns, const cv::Mat& depth_m) {
  api::TrackRequest request;
  api::DepthFrame* frame = request.mutable_depth();
  frame->set_t_ns(t_ns);
  frame->set_width(static_cast<uint32_t>(depth_m.cols));
  frame->set_height(static_cast<uint32_t>(depth_m.rows));
  std::string bytes(depth_m.total() * 2, '\0');
  for (int y = 0; y < depth_m.rows; ++y) {
    for (int x = 0; x < depth_m.cols; ++x) {
      const double value = std::round(depth_m.at<float>(y, x) * 1000.0);
      const auto millimetres = static_cast<uint16_t>(std::clamp(value, 0.0, 65535.0));
      const size_t i = static_cast<size_t>(y) * depth_m.cols + x;
      bytes[2 * i] = static_cast<char>(millimetres & 0xff);
      bytes[2 * i + 1] = static_cast<char>(millimetres >> 8);
    }
  }
  frame->set_depth_mm(std::move(bytes));
  return request;
}

std::vector<api::TrackRequest> PackedPackets(const EventBuffer& events, int64_t packet_ns) {
  std::vector<api::TrackRequest> requests;
  if (events.empty()) return requests;
  for (api::EventPacket& packet :
       wire::PackEventWindows(events, events.t_ns.front() - 1, packet_ns)) {
    *requests.emplace_back().mutable_events() = std::move(packet);
  }
  return requests;
}

int64_t StreamPacedSession(int port, const EventBuffer& events, int64_t packet_ns,
                           std::chrono::milliseconds wall_per_packet, const std::atomic<bool>& stop,
                           const std::string& client_name) {
  const auto stub = ConnectStub(port);
  grpc::ClientContext context;
  auto stream = stub->Track(&context);
  std::atomic<int64_t> poses{0};
  std::thread reader([&] {
    api::TrackResponse response;
    while (stream->Read(&response)) poses += response.has_pose() ? 1 : 0;
  });
  api::TrackRequest start = TestSessionStart();
  start.mutable_start()->set_client_name(client_name);
  bool ok = stream->Write(start);
  for (const api::TrackRequest& packet : PackedPackets(events, packet_ns)) {
    if (!ok || stop) break;
    ok = stream->Write(packet);
    std::this_thread::sleep_for(wall_per_packet);
  }
  stream->WritesDone();
  reader.join();
  stream->Finish();
  return poses;
}

}  // namespace evloc::service::testing
