#include "localizer/service/localizer_server.h"

#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <future>
#include <iostream>
#include <map>
#include <mutex>
#include <thread>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/log.h"
#include "core/events/event_reader.h"
#include "localizer/odometry/testing/handover_scene.h"
#include "localizer/offline/offline_tracking.h"
#include "localizer/service/session.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "localizer/wire/packed_events.h"
#include "localizer/wire/status_name.h"
#include "maps/site.h"
#include "proto/convert/proto_convert.h"

namespace evloc::service {
namespace {

using testing::TestSessionStart;

// What a Track call returned.
struct TrackOutcome {
  grpc::Status status;
  std::vector<api::TrackResponse> responses;
  // Requests the stream accepted before it closed.
  size_t written = 0;

  std::vector<api::PoseUpdate> Poses() const {
    std::vector<api::PoseUpdate> poses;
    for (const auto& response : responses) {
      if (response.has_pose()) poses.push_back(response.pose());
    }
    return poses;
  }
  int Count(api::TrackResponse::MessageCase which) const {
    int count = 0;
    for (const auto& response : responses) count += response.message_case() == which;
    return count;
  }
};

// Sends `requests`, half-closes, and reads every response (on a second thread, as a real
// client must, so that the server never waits for its writes).
TrackOutcome RunTrack(api::Localizer::Stub& stub, const std::vector<api::TrackRequest>& requests,
                      const std::string& token = "") {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  if (!token.empty()) context.AddMetadata("authorization", "Bearer " + token);
  auto stream = stub.Track(&context);
  TrackOutcome outcome;
  std::thread reader([&] {
    api::TrackResponse response;
    while (stream->Read(&response)) outcome.responses.push_back(response);
  });
  for (const auto& request : requests) {
    if (!stream->Write(request)) break;
    ++outcome.written;
  }
  stream->WritesDone();
  reader.join();
  outcome.status = stream->Finish();
  return outcome;
}

// Waits (at most 10 s) until `condition` holds.
bool Eventually(const std::function<bool()>& condition) {
  for (int i = 0; i < 1000; ++i) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return condition();
}

class LocalizerServerTest : public ::testing::Test {
 protected:
  void StartServer(const std::function<void(LocalizerServerOptions&)>& adjust = {}) {
    testing::WriteTestMap(folder_.path(), testing::kTestMapName, testing::TestMap());
    LocalizerServerOptions options = testing::TestServerOptions(folder_.path());
    if (adjust) adjust(options);
    server_ = std::make_unique<LocalizerServer>(options, [this](const std::string& line) {
      std::lock_guard<std::mutex> lock(log_mutex_);
      log_.push_back(line);
    });
    stub_ = testing::ConnectStub(server_->port());
  }

  std::vector<std::string> LogLines() {
    std::lock_guard<std::mutex> lock(log_mutex_);
    return log_;
  }

  // A short valid session: start and 50 ms of events in 1 ms packets.
  std::vector<api::TrackRequest> ShortSession() {
    std::vector<api::TrackRequest> requests{TestSessionStart()};
    static const EventBuffer events = testing::TestEvents(70'000'000);
    for (auto& packet : testing::PackedPackets(events, 1'000'000)) requests.push_back(packet);
    return requests;
  }

  // Declared before the server, which logs until it is destroyed.
  testing::TemporaryFolder folder_;
  std::mutex log_mutex_;
  std::vector<std::string> log_;
  std::unique_ptr<LocalizerServer> server_;
  std::unique_ptr<api::Localizer::Stub> stub_;
};

TEST_F(LocalizerServerTest, ListsAndDescribesMaps) {
  StartServer();
  grpc::ClientContext list_context;
  api::ListMapsResponse list;
  ASSERT_TRUE(stub_->ListMaps(&list_context, {}, &list).ok());
  ASSERT_EQ(list.maps_size(), 1);
  const Map map = testing::TestMap();
  EXPECT_EQ(list.maps(0).name(), testing::kTestMapName);
  EXPECT_EQ(list.maps(0).num_points(), map.size());
  EXPECT_EQ(list.maps(0).version(), MapVersionString(ComputeMapContentChecksum(map)));
  EXPECT_GT(list.maps(0).bounding_box_max().z(), list.maps(0).bounding_box_min().z());

  grpc::ClientContext get_context;
  api::GetMapRequest request;
  request.set_name("nowhere");
  api::MapDescription description;
  EXPECT_EQ(stub_->GetMap(&get_context, request, &description).error_code(),
            grpc::StatusCode::NOT_FOUND);
}

TEST_F(LocalizerServerTest, PosesEqualOfflineTrackingOfTheSameEvents) {
  // The client sends as fast as it can: a queue deep enough for the whole stream.
  StartServer([](LocalizerServerOptions& options) { options.queue_packets = 1024; });
  const EventBuffer events = testing::TestEvents(300'000'000);
  std::vector<api::TrackRequest> requests{TestSessionStart()};
  for (auto& packet : testing::PackedPackets(events, 1'000'000)) requests.push_back(packet);
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  ASSERT_TRUE(outcome.status.ok()) << outcome.status.error_message();
  ASSERT_GE(outcome.responses.size(), 2u);
  EXPECT_TRUE(outcome.responses.front().has_started());
  // The searching rate announced: 20 events per pixel and second (the default) of the camera.
  const api::SessionStart& start = requests.front().start();
  EXPECT_EQ(outcome.responses.front().started().searching_event_rate(),
            20u * start.camera().width() * start.camera().height());
  ASSERT_TRUE(outcome.responses.back().has_end());
  const api::SessionEnd& end = outcome.responses.back().end();
  EXPECT_EQ(end.events(), events.size());
  EXPECT_EQ(end.packets(), requests.size() - 1);

  tracking::OfflineTrackingOptions options;
  options.tracker.step_rate_hz = 200;
  testing::BufferEventReader reader(events);
  const Map map = testing::TestMap();
  const VisibilityIndex visibility(map);
  const auto offline = tracking::TrackEventStream(
      reader, map, &visibility, testing::TestCamera(),
      tracking::testing::SmoothMotion(testing::kInitialTimeNs), testing::kInitialTimeNs, options);

  const auto poses = outcome.Poses();
  EXPECT_EQ(end.poses(), poses.size());
  // Offline, a step runs once an event after its time arrives; the server also runs the steps up
  // to the last packet's end_t_ns (Tracker::AdvanceTo), i.e. after the last event.
  ASSERT_GE(poses.size(), offline.steps.size());
  for (size_t i = offline.steps.size(); i < poses.size(); ++i) {
    EXPECT_GE(poses[i].t_ns(), events.t_ns.back());
    EXPECT_LE(poses[i].t_ns(), requests.back().events().end_t_ns());
  }
  ASSERT_GE(offline.steps.size(), 50u);
  for (size_t i = 0; i < offline.steps.size(); ++i) {
    const tracking::PoseEstimate& expected = offline.steps[i];
    EXPECT_EQ(poses[i].t_ns(), expected.t_ns);
    const Rigid3d pose = RigidFromProto(poses[i].world_from_cam(), "pose");
    EXPECT_EQ(pose.translation, expected.world_from_cam.translation) << "step " << i;
    EXPECT_EQ(poses[i].world_from_cam().rotation().w(), expected.world_from_cam.rotation.w());
    EXPECT_EQ(poses[i].status(), api::TRACKING);
    ASSERT_EQ(poses[i].covariance_size(), 36);
    EXPECT_EQ(poses[i].covariance(7), expected.covariance(1, 1));
    EXPECT_GT(poses[i].latency_us(), 0);
    EXPECT_GT(poses[i].quality().points_used(), 50u);
  }
  // Tracking itself is right, too.
  const Rigid3d truth = tracking::testing::SmoothMotion(poses.back().t_ns());
  EXPECT_LT((RigidFromProto(poses.back().world_from_cam(), "pose").translation - truth.translation)
                .norm(),
            0.02);
  EXPECT_TRUE(Eventually([&] { return server_->counters().sessions_active == 0; }));
  const auto lines = LogLines();
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_NE(lines[0].find("session 1 start"), std::string::npos);
  EXPECT_NE(lines[1].find("session 1 end: OK"), std::string::npos);
}

// A packet's end_t_ns runs the steps it completes: the pose of step t arrives after the packet
// whose end_t_ns >= t, without any later packet (docs/api.md, "A Track session").
TEST_F(LocalizerServerTest, PoseArrivesAfterThePacketThatEndsItsStep) {
  StartServer();
  const auto requests = ShortSession();  // 200 Hz steps after kInitialTimeNs, 1 ms packets.
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
  auto stream = stub_->Track(&context);
  std::mutex mutex;
  std::condition_variable arrived;
  std::vector<int64_t> pose_times;
  std::thread reader([&] {
    api::TrackResponse response;
    while (stream->Read(&response)) {
      std::lock_guard<std::mutex> lock(mutex);
      if (response.has_pose()) pose_times.push_back(response.pose().t_ns());
      arrived.notify_all();
    }
  });
  EXPECT_TRUE(stream->Write(requests[0]));
  constexpr int64_t kPeriodNs = 5'000'000;
  int64_t next_step_t_ns = testing::kInitialTimeNs + kPeriodNs;
  size_t expected = 0;
  for (size_t i = 1; i < requests.size(); ++i) {
    EXPECT_TRUE(stream->Write(requests[i]));
    const int64_t end_t_ns = requests[i].events().end_t_ns();
    while (next_step_t_ns <= end_t_ns) {
      ++expected;
      next_step_t_ns += kPeriodNs;
    }
    std::unique_lock<std::mutex> lock(mutex);
    const bool complete = arrived.wait_for(lock, std::chrono::seconds(20),
                                           [&] { return pose_times.size() >= expected; });
    EXPECT_TRUE(complete) << "the pose of the step at " << next_step_t_ns - kPeriodNs
                          << " ns did not arrive after the packet ending at " << end_t_ns << " ns";
    EXPECT_EQ(pose_times.size(), expected) << "a step ran after the packet's end";
    if (!complete || pose_times.size() != expected) {
      context.TryCancel();
      break;
    }
    if (expected > 0) {
      EXPECT_EQ(pose_times.back(), next_step_t_ns - kPeriodNs);
    }
  }
  EXPECT_GE(expected, 9u);
  stream->WritesDone();
  reader.join();
  const grpc::Status status = stream->Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
}

TEST_F(LocalizerServerTest, HandsOverToOdometryAwayFromTheMapAndBackWithDepthFrames) {
  // The hand-over scene (localizer/odometry/testing): the map covers what the camera sees first;
  // it turns away for a while and comes back.
  testing::WriteTestMap(folder_.path(), "handover", odometry::testing::HandoverMap());
  // The client sends as fast as it can: a queue deep enough for the whole stream.
  StartServer([](LocalizerServerOptions& options) {
    options.queue_packets = 2048;
    options.queue_events = int64_t{1} << 24;
  });
  const int64_t start_ns = odometry::testing::kStartNs;
  api::TrackRequest start;
  api::SessionStart* session = start.mutable_start();
  session->set_map_name("handover");
  *session->mutable_camera() = CameraToProto(odometry::testing::HandoverEventCamera());
  *session->mutable_initial_world_from_cam() =
      RigidToProto(odometry::testing::HandoverMotion(start_ns));
  session->set_initial_t_ns(start_ns);
  session->mutable_options()->set_step_rate_hz(200);
  *session->mutable_depth_camera()->mutable_camera() =
      CameraToProto(odometry::testing::HandoverDepthCamera());
  *session->mutable_depth_camera()->mutable_event_from_depth() =
      RigidToProto(odometry::testing::HandoverEventFromDepth());
  std::vector<api::TrackRequest> requests{start};
  // 5 ms packets; each depth frame right after the packet that reaches its time.
  const std::vector<int64_t> depth_times = odometry::testing::HandoverDepthTimes();
  size_t next_depth = 0;
  for (api::TrackRequest& packet :
       testing::PackedPackets(odometry::testing::HandoverEvents(), 5'000'000)) {
    const int64_t end_ns = packet.events().end_t_ns();
    requests.push_back(std::move(packet));
    while (next_depth < depth_times.size() && depth_times[next_depth] <= end_ns) {
      requests.push_back(testing::DepthFrameRequest(
          depth_times[next_depth], odometry::testing::HandoverDepthFrame(depth_times[next_depth])));
      ++next_depth;
    }
  }
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  ASSERT_TRUE(outcome.status.ok()) << outcome.status.error_message();
  int64_t previous_t = -1;
  int odometry_poses = 0;
  int away_poses = 0;
  api::PoseSource last_source = api::POSE_SOURCE_UNSPECIFIED;
  Rigid3d last_pose;
  int64_t last_t = 0;
  for (const api::TrackResponse& response : outcome.responses) {
    if (!response.has_pose()) continue;
    const api::PoseUpdate& pose = response.pose();
    if (previous_t >= 0) {
      EXPECT_EQ(pose.t_ns() - previous_t, 5'000'000) << "a gap";
    }
    previous_t = pose.t_ns();
    EXPECT_NE(pose.source(), api::POSE_SOURCE_UNSPECIFIED);
    ASSERT_TRUE(pose.has_world_from_cam()) << "every step has a pose at " << pose.t_ns();
    if (pose.source() == api::POSE_SOURCE_ODOMETRY) ++odometry_poses;
    if (pose.t_ns() >= odometry::testing::kAwayNs && pose.t_ns() <= odometry::testing::kReturnNs) {
      ++away_poses;
      EXPECT_EQ(pose.source(), api::POSE_SOURCE_ODOMETRY) << pose.t_ns();
    }
    last_source = pose.source();
    last_pose = RigidFromProto(pose.world_from_cam(), "pose");
    last_t = pose.t_ns();
  }
  EXPECT_GT(away_poses, 90);
  EXPECT_EQ(last_source, api::POSE_SOURCE_MAP) << "back on the map at the end";
  EXPECT_LT((last_pose.translation - odometry::testing::HandoverMotion(last_t).translation).norm(),
            0.02);
  ASSERT_EQ(outcome.Count(api::TrackResponse::kEnd), 1);
  const api::SessionEnd& end = outcome.responses.back().end();
  EXPECT_EQ(end.depth_frames(), depth_times.size());
  EXPECT_EQ(end.odometry_poses(), static_cast<uint64_t>(odometry_poses));
}

TEST_F(LocalizerServerTest, DepthFramesNeedADepthCameraAndTheirEvents) {
  StartServer();
  cv::Mat depth(4, 6, CV_32FC1, cv::Scalar(1.5));
  // No depth camera in the SessionStart.
  TrackOutcome outcome = RunTrack(
      *stub_, std::vector<api::TrackRequest>{
                  TestSessionStart(), testing::DepthFrameRequest(testing::kInitialTimeNs, depth)});
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(outcome.status.error_message().find("depth_camera"), std::string::npos)
      << outcome.status.error_message();
  // A frame of the wrong size, and one after the events sent.
  api::TrackRequest start = TestSessionStart();
  *start.mutable_start()->mutable_depth_camera()->mutable_camera() =
      CameraToProto(Camera::Pinhole(6, 4, 5, 5, 2.5, 1.5));
  *start.mutable_start()->mutable_depth_camera()->mutable_event_from_depth() =
      RigidToProto(Rigid3d());
  outcome = RunTrack(
      *stub_, std::vector<api::TrackRequest>{
                  start, testing::DepthFrameRequest(testing::kInitialTimeNs,
                                                    cv::Mat(5, 6, CV_32FC1, cv::Scalar(1)))});
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  outcome =
      RunTrack(*stub_, std::vector<api::TrackRequest>{
                           start, testing::DepthFrameRequest(testing::kInitialTimeNs + 1, depth)});
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(outcome.status.error_message().find("send the events up to its time first"),
            std::string::npos)
      << outcome.status.error_message();
  // Accepted at the session time.
  outcome =
      RunTrack(*stub_, std::vector<api::TrackRequest>{
                           start, testing::DepthFrameRequest(testing::kInitialTimeNs, depth)});
  EXPECT_TRUE(outcome.status.ok()) << outcome.status.error_message();
}

TEST_F(LocalizerServerTest, FirstMessageMustBeSessionStart) {
  StartServer();
  auto requests = ShortSession();
  requests.erase(requests.begin());
  EXPECT_EQ(RunTrack(*stub_, requests).status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
}

TEST_F(LocalizerServerTest, UnknownMapIsNotFound) {
  StartServer();
  auto requests = ShortSession();
  requests[0].mutable_start()->set_map_name("atlantis");
  EXPECT_EQ(RunTrack(*stub_, requests).status.error_code(), grpc::StatusCode::NOT_FOUND);
  ASSERT_EQ(LogLines().size(), 1u);
  EXPECT_NE(LogLines()[0].find("refused: NOT_FOUND"), std::string::npos) << LogLines()[0];
  requests[0].mutable_start()->set_map_name(testing::kTestMapName);
  requests[0].mutable_start()->set_map_version("deadbeef");
  EXPECT_EQ(RunTrack(*stub_, requests).status.error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(LocalizerServerTest, InvalidCameraIsInvalidArgument) {
  StartServer();
  auto requests = ShortSession();
  requests[0].mutable_start()->mutable_camera()->set_fy(0);
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(outcome.status.error_message().find("camera"), std::string::npos);
}

TEST_F(LocalizerServerTest, EventOutsideTheSensorIsInvalidArgument) {
  StartServer();
  auto requests = ShortSession();
  // The test camera is 320x240; shrink the declared sensor so that events fall outside.
  requests[0].mutable_start()->mutable_camera()->set_width(100);
  requests[0].mutable_start()->mutable_camera()->set_cx(49.5);
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(outcome.status.error_message().find("outside"), std::string::npos);
}

TEST_F(LocalizerServerTest, TimeGoingBackIsInvalidArgument) {
  StartServer();
  auto requests = ShortSession();
  std::swap(requests[10], requests[20]);
  EXPECT_EQ(RunTrack(*stub_, requests).status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

// A packet ending far after the session time would make the tracker run a step per period up to
// it (hours of steps for a wrong clock): refused (found by evloc_session_requests_fuzzer).
TEST_F(LocalizerServerTest, PacketEndingFarAheadIsInvalidArgument) {
  StartServer();
  auto requests = ShortSession();
  requests[30].mutable_events()->set_end_t_ns(requests[29].events().end_t_ns() + 3'000'000'000);
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(outcome.status.error_message().find("--max-packet-span"), std::string::npos)
      << outcome.status.error_message();
  EXPECT_LT(outcome.Poses().size(), 20u);
}

TEST_F(LocalizerServerTest, MalformedPacketIsInvalidArgument) {
  StartServer();
  auto requests = ShortSession();
  requests[5].mutable_events()->mutable_data()->append("xyz");
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(outcome.status.error_message().find("event packet 4"), std::string::npos);
}

TEST_F(LocalizerServerTest, OversizedPacketIsResourceExhausted) {
  StartServer([](LocalizerServerOptions& options) { options.max_message_bytes = 64 << 10; });
  auto requests = ShortSession();
  requests[3].mutable_events()->mutable_data()->append(std::string(128 << 10, '\0'));
  EXPECT_EQ(RunTrack(*stub_, requests).status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
}

TEST_F(LocalizerServerTest, TooManySessionsAreRefusedWhileOthersKeepTracking) {
  StartServer([](LocalizerServerOptions& options) { options.max_sessions = 1; });
  const auto requests = ShortSession();
  grpc::ClientContext context;
  auto first = stub_->Track(&context);
  ASSERT_TRUE(first->Write(requests[0]));
  api::TrackResponse response;
  ASSERT_TRUE(first->Read(&response));
  ASSERT_TRUE(response.has_started());

  EXPECT_EQ(RunTrack(*stub_, requests).status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);

  for (size_t i = 1; i < requests.size(); ++i) ASSERT_TRUE(first->Write(requests[i]));
  first->WritesDone();
  int poses = 0;
  while (first->Read(&response)) poses += response.has_pose();
  EXPECT_TRUE(first->Finish().ok());
  EXPECT_GT(poses, 5);
}

TEST_F(LocalizerServerTest, VanishedClientIsCleanedUp) {
  StartServer();
  const auto requests = ShortSession();
  {
    grpc::ClientContext context;
    auto stream = stub_->Track(&context);
    for (size_t i = 0; i < 10; ++i) ASSERT_TRUE(stream->Write(requests[i]));
    api::TrackResponse response;
    ASSERT_TRUE(stream->Read(&response));
    ASSERT_TRUE(Eventually([&] { return server_->counters().sessions_active == 1; }));
    context.TryCancel();
  }
  EXPECT_TRUE(Eventually([&] { return server_->counters().sessions_active == 0; }));
  EXPECT_TRUE(RunTrack(*stub_, requests).status.ok());
}

TEST_F(LocalizerServerTest, IdleSessionIsCancelled) {
  StartServer([](LocalizerServerOptions& options) { options.idle_timeout_s = 0.2; });
  grpc::ClientContext context;
  auto stream = stub_->Track(&context);
  ASSERT_TRUE(stream->Write(TestSessionStart()));
  api::TrackResponse response;
  ASSERT_TRUE(stream->Read(&response));
  EXPECT_FALSE(stream->Read(&response));  // The server ends the idle stream by itself.
  EXPECT_FALSE(stream->Finish().ok());
  EXPECT_TRUE(Eventually([&] { return server_->counters().sessions_active == 0; }));
  EXPECT_TRUE(Eventually([&] {
    const auto lines = LogLines();
    return !lines.empty() && lines.back().find("idle timeout") != std::string::npos;
  }));
}

// A client that stops reading its responses and sends nothing more, without ending the stream:
// the server's writes block once gRPC's flow-control window is full, and the watchdog ends the
// session after the idle timeout (it would otherwise hold its slot forever).
TEST_F(LocalizerServerTest, ClientThatStopsReadingIsCancelled) {
  StartServer([](LocalizerServerOptions& options) {
    options.idle_timeout_s = 0.5;
    options.max_step_rate_hz = 5000;
  });
  std::vector<api::TrackRequest> requests{TestSessionStart()};
  requests[0].mutable_start()->mutable_options()->set_step_rate_hz(5000);
  for (auto& packet : testing::PackedPackets(testing::TestEvents(300'000'000), 10'000'000)) {
    requests.push_back(packet);
  }
  grpc::ClientContext context;
  auto stream = stub_->Track(&context);
  for (const api::TrackRequest& request : requests) ASSERT_TRUE(stream->Write(request));
  ASSERT_TRUE(Eventually([&] { return server_->counters().sessions_active == 1; }));
  // Neither read nor half-close: only the watchdog can end the session.
  EXPECT_TRUE(Eventually([&] { return server_->counters().sessions_active == 0; }));
  EXPECT_TRUE(Eventually([&] {
    const auto lines = LogLines();
    return !lines.empty() && lines.back().find("stopped reading") != std::string::npos;
  }));
  // Far fewer poses were written than the 1500 steps of the stream (the writes blocked).
  EXPECT_LT(server_->counters().poses.load(), 1500);
  context.TryCancel();
}

// A SessionStart and one empty packet that completes `steps` steps at 1 kHz (the server's
// per-request limits raised in the test to allow it).
std::vector<api::TrackRequest> LongPacketSession(int64_t steps) {
  std::vector<api::TrackRequest> requests{TestSessionStart()};
  requests[0].mutable_start()->mutable_options()->set_step_rate_hz(1000);
  api::TrackRequest packet;
  packet.mutable_events()->set_end_t_ns(testing::kInitialTimeNs + steps * 1'000'000);
  requests.push_back(packet);
  return requests;
}

void AllowLongPackets(LocalizerServerOptions& options) {
  options.max_packet_span_s = 1000;
  options.max_steps_per_request = 1'000'000;
}

// Finding 1 of issue 14: a request's steps could not be interrupted, so a cancelled session kept
// its worker (and a core) busy for the whole packet. The worker now stops within one step of the
// cancellation: the slot is free long before the 1M steps could have run.
TEST_F(LocalizerServerTest, CancelledSessionStopsItsWorkerWithinOneStep) {
  StartServer(AllowLongPackets);
  const auto requests = LongPacketSession(900'000);
  {
    grpc::ClientContext context;
    auto stream = stub_->Track(&context);
    for (const auto& request : requests) ASSERT_TRUE(stream->Write(request));
    api::TrackResponse response;
    ASSERT_TRUE(stream->Read(&response));
    ASSERT_TRUE(response.has_started());
    ASSERT_TRUE(Eventually([&] { return server_->counters().sessions_active == 1; }));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // The long packet's steps run.
    context.TryCancel();
  }
  EXPECT_TRUE(Eventually([&] { return server_->counters().sessions_active == 0; }));
  EXPECT_LT(server_->counters().poses.load(), 900'000);
}

// Finding 1: a session over its CPU budget (CPU seconds per second of session time, after the
// grace) is ended with RESOURCE_EXHAUSTED within a step.
TEST_F(LocalizerServerTest, SessionOverItsCpuBudgetIsResourceExhausted) {
  StartServer([](LocalizerServerOptions& options) {
    AllowLongPackets(options);
    options.session_cpu_grace_s = 0.2;
    options.session_cpu_per_second = 1e-4;
  });
  const TrackOutcome outcome = RunTrack(*stub_, LongPacketSession(900'000));
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
      << outcome.status.error_message();
  EXPECT_NE(outcome.status.error_message().find("--session-cpu-budget"), std::string::npos)
      << outcome.status.error_message();
  EXPECT_LT(outcome.Poses().size(), 900'000u);
  EXPECT_GE(server_->counters().limited.load(), 1);
}

// A PACKED packet of `count` events in the first microsecond after `after_ns`, ending at
// `end_ns`.
api::TrackRequest DensePacket(size_t count, int64_t after_ns, int64_t end_ns) {
  EventBuffer events;
  for (size_t i = 0; i < count; ++i) {
    events.push_back({after_ns + 1 + static_cast<int64_t>(i % 1000), static_cast<uint16_t>(i % 320),
                      static_cast<uint16_t>(i / 320 % 240), 1});
  }
  api::TrackRequest request;
  api::EventPacket* packet = request.mutable_events();
  packet->set_encoding(api::EVENT_ENCODING_PACKED);
  packet->set_time_base_ns(after_ns);
  packet->set_end_t_ns(end_ns);
  packet->set_data(wire::EncodePackedEvents(events, 0, events.size(), after_ns));
  return request;
}

// A session whose first packet keeps the worker busy (900k steps) while dense packets follow.
std::vector<api::TrackRequest> BusyWorkerThenDensePackets(size_t packets, size_t events) {
  std::vector<api::TrackRequest> requests{TestSessionStart()};
  requests[0].mutable_start()->mutable_options()->set_step_rate_hz(1000);
  int64_t end = testing::kInitialTimeNs + 900'000'000'000;
  requests.push_back(DensePacket(events, testing::kInitialTimeNs, end));
  for (size_t i = 0; i < packets; ++i) {
    requests.push_back(DensePacket(events, end, end + 1'000'000));
    end += 1'000'000;
  }
  return requests;
}

// Finding 2 of issue 14: the queue counted packets, not events (a packet may decode to millions):
// it is bounded in events too.
TEST_F(LocalizerServerTest, QueueBoundedInEventsOverflows) {
  StartServer([](LocalizerServerOptions& options) {
    AllowLongPackets(options);
    options.max_packet_events = 1000;
    options.queue_events = 2500;
  });
  const TrackOutcome outcome = RunTrack(*stub_, BusyWorkerThenDensePackets(10, 1000));
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
      << outcome.status.error_message();
  EXPECT_NE(outcome.status.error_message().find("2500 events overflowed"), std::string::npos)
      << outcome.status.error_message();
}

// Finding 2: the server's own accounting of queued decoded events refuses packets (and new
// sessions) before the process runs out of memory.
TEST_F(LocalizerServerTest, PacketsBeyondTheServerMemoryBudgetAreRefused) {
  StartServer([](LocalizerServerOptions& options) {
    AllowLongPackets(options);
    // The queue takes 3 packets; the budget too, and the packet being tracked counts in it.
    options.max_packet_events = 1000;
    options.queue_events = 3000;
    options.max_memory_bytes = 3000 * kDecodedEventBytes;
  });
  const TrackOutcome outcome = RunTrack(*stub_, BusyWorkerThenDensePackets(10, 1000));
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
      << outcome.status.error_message();
  EXPECT_NE(outcome.status.error_message().find("--max-memory"), std::string::npos)
      << outcome.status.error_message();
  EXPECT_TRUE(Eventually([&] { return server_->counters().sessions_active == 0; }));
}

// Finding 3 of issue 14: a stream that never sent its SessionStart held a handler thread
// forever; it is cancelled after --handshake-timeout.
TEST_F(LocalizerServerTest, StreamWithoutSessionStartIsCancelledAfterTheHandshakeTimeout) {
  StartServer([](LocalizerServerOptions& options) { options.handshake_timeout_s = 0.3; });
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  auto stream = stub_->Track(&context);
  api::TrackResponse response;
  EXPECT_FALSE(stream->Read(&response));
  EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_GE(server_->counters().limited.load(), 1);
  EXPECT_TRUE(Eventually([&] {
    for (const std::string& line : LogLines()) {
      if (line.find("--handshake-timeout") != std::string::npos) return true;
    }
    return false;
  }));
}

// Finding 3: one peer may not hold every handler thread with streams (sessions or not).
TEST_F(LocalizerServerTest, StreamsPerPeerAreLimited) {
  StartServer([](LocalizerServerOptions& options) {
    options.max_sessions = 2;
    options.handshake_timeout_s = 30;
  });
  grpc::ClientContext first_context;
  grpc::ClientContext second_context;
  auto first = stub_->Track(&first_context);
  auto second = stub_->Track(&second_context);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // Both calls reached the server.
  grpc::ClientContext third_context;
  third_context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  auto third = stub_->Track(&third_context);
  api::TrackResponse response;
  EXPECT_FALSE(third->Read(&response));
  const grpc::Status status = third->Finish();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
  EXPECT_NE(status.error_message().find("--max-streams-per-peer"), std::string::npos);
  first_context.TryCancel();
  second_context.TryCancel();
}

// Issue 16: a stream holds no thread of the server (gRPC's callback API, the tracking pool, one
// timer): 24 silent streams and 12 running sessions add far fewer threads to the process than
// the 3 per session and 1 per stream of a thread-per-stream server (72 here).
int ThreadsOfThisProcess() {
  int count = 0;
  for ([[maybe_unused]] const auto& entry :
       std::filesystem::directory_iterator("/proc/self/task")) {
    ++count;
  }
  return count;
}

TEST_F(LocalizerServerTest, StreamsAndSessionsHoldNoThreads) {
  StartServer([](LocalizerServerOptions& options) {
    options.max_sessions = 12;
    options.max_streams_per_peer = 64;
    options.max_streams_per_connection = 64;
    options.handshake_timeout_s = 30;
    options.tracking_threads = 2;
  });
  // A first session: gRPC's own threads and the server's first-call costs are counted before.
  EXPECT_TRUE(RunTrack(*stub_, ShortSession()).status.ok());
  const int before = ThreadsOfThisProcess();
  constexpr int kSilent = 24;
  constexpr int kSessions = 12;
  std::vector<std::unique_ptr<grpc::ClientContext>> contexts;
  std::vector<std::unique_ptr<grpc::ClientReaderWriter<api::TrackRequest, api::TrackResponse>>>
      streams;
  for (int i = 0; i < kSilent + kSessions; ++i) {
    contexts.push_back(std::make_unique<grpc::ClientContext>());
    contexts.back()->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    streams.push_back(stub_->Track(contexts.back().get()));
  }
  for (int i = kSilent; i < kSilent + kSessions; ++i) {
    ASSERT_TRUE(streams[i]->Write(TestSessionStart()));
    api::TrackResponse response;
    ASSERT_TRUE(streams[i]->Read(&response));
    ASSERT_TRUE(response.has_started());
  }
  ASSERT_TRUE(Eventually([&] { return server_->counters().sessions_active == kSessions; }));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // The silent streams arrived.
  const int during = ThreadsOfThisProcess();
  std::cout << "threads of the test process: " << before << " before, " << during << " with "
            << kSilent << " silent streams and " << kSessions << " sessions" << std::endl;
  EXPECT_LT(during - before, 12) << before << " threads before, " << during << " with " << kSilent
                                 << " silent streams and " << kSessions << " sessions";
  for (auto& context : contexts) context->TryCancel();
  for (auto& stream : streams) stream->Finish();
  EXPECT_TRUE(Eventually([&] { return server_->counters().sessions_active == 0; }));
}

// The health of service `name` on the test server: 1 SERVING, 2 NOT_SERVING, -1 when the call
// failed (the status in `status`).
int HealthOf(int port, const std::string& name, grpc::Status* status) {
  auto channel =
      grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials());
  grpc::GenericStub generic(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  // HealthCheckRequest{service = name}: field 1, length-delimited.
  const std::string bytes =
      name.empty() ? std::string() : std::string("\x0a") + static_cast<char>(name.size()) + name;
  const grpc::Slice slice(bytes.data(), bytes.size());
  const grpc::ByteBuffer request(&slice, 1);
  grpc::ByteBuffer response;
  std::promise<grpc::Status> done;
  generic.UnaryCall(&context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request,
                    &response, [&done](grpc::Status result) { done.set_value(result); });
  *status = done.get_future().get();
  if (!status->ok()) return -1;
  std::vector<grpc::Slice> slices;
  if (!response.Dump(&slices).ok()) return -1;
  std::string answer;
  for (const auto& part : slices) {
    answer.append(reinterpret_cast<const char*>(part.begin()), part.size());
  }
  return answer.size() == 2 && answer[0] == '\x08' ? answer[1] : -1;
}

constexpr int kServing = 1;
constexpr int kNotServing = 2;

// Finding 3: health stayed SERVING while the server could admit nothing; the Localizer
// service's health (what readiness asks) now follows admission, the overall health (liveness)
// stays SERVING.
TEST_F(LocalizerServerTest, LocalizerHealthIsNotServingWhileNoSessionCanBeAdmitted) {
  StartServer([](LocalizerServerOptions& options) { options.max_sessions = 1; });
  const std::string service = api::Localizer::service_full_name();
  grpc::Status status;
  EXPECT_EQ(HealthOf(server_->port(), service, &status), kServing) << status.error_message();
  grpc::ClientContext context;
  auto stream = stub_->Track(&context);
  ASSERT_TRUE(stream->Write(TestSessionStart()));
  api::TrackResponse response;
  ASSERT_TRUE(stream->Read(&response));
  EXPECT_EQ(HealthOf(server_->port(), service, &status), kNotServing);
  EXPECT_EQ(HealthOf(server_->port(), "", &status), kServing);
  stream->WritesDone();
  while (stream->Read(&response)) {
  }
  EXPECT_TRUE(stream->Finish().ok());
  EXPECT_TRUE(Eventually([&] { return HealthOf(server_->port(), service, &status) == kServing; }));
}

// Finding 3: sessions per token are limited (--max-sessions-per-token, the per-token hook).
TEST_F(LocalizerServerTest, SessionsPerTokenAreLimited) {
  const auto tokens = folder_.path() / "tokens.txt";
  std::ofstream(tokens) << "alpha *\nbeta *\n";
  StartServer([&](LocalizerServerOptions& options) {
    options.auth_tokens_file = tokens;
    options.max_sessions_per_token = 1;
  });
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer alpha");
  auto first = stub_->Track(&context);
  ASSERT_TRUE(first->Write(TestSessionStart()));
  api::TrackResponse response;
  ASSERT_TRUE(first->Read(&response));
  ASSERT_TRUE(response.has_started());
  const auto requests = ShortSession();
  const grpc::Status refused = RunTrack(*stub_, requests, "alpha").status;
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(refused.error_message().find("--max-sessions-per-token"), std::string::npos)
      << refused.error_message();
  EXPECT_TRUE(RunTrack(*stub_, requests, "beta").status.ok());
  first->WritesDone();
  while (first->Read(&response)) {
  }
  EXPECT_TRUE(first->Finish().ok());
  EXPECT_TRUE(RunTrack(*stub_, requests, "alpha").status.ok());
}

// Finding 3: a connection has a maximum age (GOAWAY, then its streams are cut after the
// grace): a session on it ends, and a new one (a new connection) is served.
TEST_F(LocalizerServerTest, ConnectionsOlderThanTheMaximumAgeAreClosed) {
  StartServer([](LocalizerServerOptions& options) {
    options.max_connection_age_s = 0.3;
    options.max_connection_age_grace_s = 0.3;
  });
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto stream = stub_->Track(&context);
  ASSERT_TRUE(stream->Write(TestSessionStart()));
  api::TrackResponse response;
  ASSERT_TRUE(stream->Read(&response));
  // Keep the session busy with empty packets (time passes) until the server cuts the stream.
  std::thread reader([&] {
    while (stream->Read(&response)) {
    }
  });
  const auto start = std::chrono::steady_clock::now();
  int64_t end_t_ns = testing::kInitialTimeNs;
  while (std::chrono::steady_clock::now() - start < std::chrono::seconds(10)) {
    api::TrackRequest packet;
    end_t_ns += 1'000'000;
    packet.mutable_events()->set_end_t_ns(end_t_ns);
    if (!stream->Write(packet)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  const auto cut = std::chrono::steady_clock::now() - start;
  stream->WritesDone();
  reader.join();
  const grpc::Status status = stream->Finish();
  EXPECT_FALSE(status.ok());
  EXPECT_LT(cut, std::chrono::seconds(5));
  EXPECT_TRUE(Eventually([&] { return server_->counters().sessions_active == 0; }));
}

// Finding 13 of issue 14: a newline in client_name forged log lines.
TEST_F(LocalizerServerTest, ClientNameCannotForgeLogLines) {
  StartServer();
  auto requests = ShortSession();
  requests[0].mutable_start()->set_client_name("replay\nsession 99 end: OK; forged" +
                                               std::string(1000, 'x'));
  EXPECT_TRUE(RunTrack(*stub_, requests).status.ok());
  bool logged = false;
  for (const std::string& line : LogLines()) {
    EXPECT_EQ(line.find('\n'), std::string::npos) << line;
    EXPECT_LT(line.size(), 800u) << line;
    logged |= line.find("replay\\x0asession 99") != std::string::npos;
  }
  EXPECT_TRUE(logged);
}

// Finding 13: statuses carried absolute server paths (the map folder, a map file).
TEST_F(LocalizerServerTest, StatusesCarryNoServerPaths) {
  StartServer();
  std::filesystem::create_directories(folder_.path() / "broken");
  std::ofstream(folder_.path() / "broken" / "map.evmap") << "not a map";
  const std::string folder = folder_.path().string();
  {
    grpc::ClientContext context;
    api::GetMapRequest request;
    request.set_name("broken");
    api::MapDescription description;
    const grpc::Status status = stub_->GetMap(&context, request, &description);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_EQ(status.error_message().find(folder), std::string::npos) << status.error_message();
    EXPECT_EQ(status.error_message().find("/tmp"), std::string::npos) << status.error_message();
  }
  for (const std::string name : {"broken", "absent"}) {
    auto requests = ShortSession();
    requests[0].mutable_start()->set_map_name(name);
    const grpc::Status status = RunTrack(*stub_, requests).status;
    EXPECT_FALSE(status.ok());
    EXPECT_EQ(status.error_message().find(folder), std::string::npos) << status.error_message();
    EXPECT_EQ(status.error_message().find("/tmp"), std::string::npos) << status.error_message();
  }
}

TEST_F(LocalizerServerTest, OverflowingSessionIsToldThenStopped) {
  StartServer([](LocalizerServerOptions& options) {
    options.queue_packets = 4;
    options.backpressure_fraction = 0.5;
  });
  std::vector<api::TrackRequest> requests{TestSessionStart()};
  requests[0].mutable_start()->mutable_options()->set_step_rate_hz(2000);
  const EventBuffer events = testing::TestEvents(300'000'000);
  for (auto& packet : testing::PackedPackets(events, 50'000)) requests.push_back(packet);
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(outcome.status.error_message().find("overflowed"), std::string::npos);
  EXPECT_GE(outcome.Count(api::TrackResponse::kBackpressure), 1);
  // (The client's writes may all have been accepted by gRPC's buffers before the status came.)
}

// A session that searches the map (no pose) and falls behind its stream thins its queued event
// packets (and when that is not enough drops the oldest) instead of overflowing: the overflow
// test above with the pose taken away ended RESOURCE_EXHAUSTED while still searching. The map's
// keyframes are a metre and tens of degrees off the path, beyond the search's reach, so the
// session searches to the end (found, it would keep every packet and could overflow then).
TEST_F(LocalizerServerTest, ASearchingSessionBehindItsStreamShedsEventsInsteadOfOverflowing) {
  StartServer([](LocalizerServerOptions& options) {
    options.queue_packets = 4;
    options.backpressure_fraction = 0.5;
  });
  Map far = testing::TestMap();
  far.cameras.push_back(testing::TestCamera());
  for (int64_t t_ns = 0; t_ns <= 600'000'000; t_ns += 150'000'000) {
    Keyframe keyframe;
    keyframe.cam_from_world = (tracking::testing::SmoothMotion(t_ns) *
                               ExpSE3((Vector6d() << 1.0, 0.5, -0.8, 0.3, 0.6, 0.2).finished()))
                                  .Inverse();
    keyframe.t_ns = t_ns;
    far.keyframes.push_back(keyframe);
  }
  testing::WriteTestMap(folder_.path(), "far", far);
  std::vector<api::TrackRequest> requests{TestSessionStart()};
  requests[0].mutable_start()->set_map_name("far");
  requests[0].mutable_start()->clear_initial_world_from_cam();
  requests[0].mutable_start()->mutable_options()->set_step_rate_hz(2000);
  const EventBuffer events = testing::TestEvents(300'000'000);
  for (auto& packet : testing::PackedPackets(events, 50'000)) requests.push_back(packet);
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  for (const api::PoseUpdate& pose : outcome.Poses()) {
    ASSERT_NE(pose.status(), api::TRACKING) << "found: the map must be out of the search's reach";
  }
  EXPECT_TRUE(outcome.status.ok()) << wire::StatusCodeName(outcome.status.error_code()) << ": "
                                   << outcome.status.error_message();
  EXPECT_GT(server_->counters().packets_shed.load(), 0);
  ASSERT_EQ(outcome.Count(api::TrackResponse::kEnd), 1);
  EXPECT_GT(outcome.responses.back().end().packets_shed(), 0u);
  EXPECT_GT(outcome.responses.back().end().events_shed(), 0u);
}

TEST_F(LocalizerServerTest, ServesHealthChecks) {
  StartServer();
  auto channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(server_->port()),
                                     grpc::InsecureChannelCredentials());
  grpc::GenericStub generic(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  const grpc::Slice empty_request("", 0);
  const grpc::ByteBuffer request(&empty_request, 1);  // HealthCheckRequest{service = ""}
  grpc::ByteBuffer response;
  std::promise<grpc::Status> done;
  generic.UnaryCall(&context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request,
                    &response, [&done](grpc::Status status) { done.set_value(status); });
  ASSERT_TRUE(done.get_future().get().ok());
  std::vector<grpc::Slice> slices;
  ASSERT_TRUE(response.Dump(&slices).ok());
  std::string bytes;
  for (const auto& slice : slices)
    bytes.append(reinterpret_cast<const char*>(slice.begin()), slice.size());
  EXPECT_EQ(bytes, std::string("\x08\x01", 2));  // status: SERVING
}

TEST_F(LocalizerServerTest, BearerTokensGuardMaps) {
  const auto tokens = folder_.path() / "tokens.txt";
  {
    std::ofstream file(tokens);
    file << "# tokens\nalpha *\nbeta other_map,third_map  # limited\n";
  }
  StartServer([&](LocalizerServerOptions& options) { options.auth_tokens_file = tokens; });
  const auto requests = ShortSession();
  EXPECT_EQ(RunTrack(*stub_, requests).status.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(RunTrack(*stub_, requests, "gamma").status.error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(RunTrack(*stub_, requests, "beta").status.error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_TRUE(RunTrack(*stub_, requests, "alpha").status.ok());
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer beta");
  api::ListMapsResponse list;
  ASSERT_TRUE(stub_->ListMaps(&context, {}, &list).ok());
  EXPECT_EQ(list.maps_size(), 0);
  EXPECT_GE(server_->counters().rejected, 3);
}

TEST_F(LocalizerServerTest, FrameSessionTracksFramesAndRefusesEvents) {
  StartServer();
  api::TrackRequest start = TestSessionStart();
  start.mutable_start()->mutable_options()->set_frames(true);
  std::vector<api::TrackRequest> requests{start};
  const auto rectangles = tracking::testing::DefaultRectangles();
  const Camera camera = testing::TestCamera();
  for (int64_t t = testing::kInitialTimeNs + 20'000'000; t <= 220'000'000; t += 20'000'000) {
    const cv::Mat gray =
        tracking::testing::RenderRectangles(rectangles, camera, tracking::testing::SmoothMotion(t));
    api::TrackRequest request;
    request.mutable_frame()->set_t_ns(t);
    request.mutable_frame()->set_width(static_cast<uint32_t>(camera.width));
    request.mutable_frame()->set_height(static_cast<uint32_t>(camera.height));
    request.mutable_frame()->set_gray(
        std::string(reinterpret_cast<const char*>(gray.data), gray.total()));
    requests.push_back(request);
  }
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  ASSERT_TRUE(outcome.status.ok()) << outcome.status.error_message();
  const auto poses = outcome.Poses();
  ASSERT_EQ(poses.size(), 10u);
  const Rigid3d truth = tracking::testing::SmoothMotion(poses.back().t_ns());
  EXPECT_LT((RigidFromProto(poses.back().world_from_cam(), "pose").translation - truth.translation)
                .norm(),
            0.03);
  EXPECT_EQ(outcome.responses.back().end().frames(), 10u);

  requests.push_back(ShortSession()[1]);
  EXPECT_EQ(RunTrack(*stub_, requests).status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(LocalizerServerTest, PoseHintResetsTheTracker) {
  StartServer();
  auto requests = ShortSession();
  // After 30 packets (30 ms of events), reset to a pose 5 cm off the truth at that time.
  const int64_t hint_t_ns = requests[30].events().end_t_ns();
  Rigid3d hint = tracking::testing::SmoothMotion(hint_t_ns);
  hint.translation.x() += 0.05;
  api::TrackRequest request;
  request.mutable_pose_hint()->set_t_ns(hint_t_ns);
  *request.mutable_pose_hint()->mutable_world_from_cam() = RigidToProto(hint);
  requests.insert(requests.begin() + 31, request);
  const TrackOutcome outcome = RunTrack(*stub_, requests);
  ASSERT_TRUE(outcome.status.ok()) << outcome.status.error_message();
  // The first step after the hint starts from the hinted pose and pulls it back towards the truth.
  const auto poses = outcome.Poses();
  const auto after = std::find_if(poses.begin(), poses.end(), [&](const api::PoseUpdate& pose) {
    return pose.t_ns() > hint_t_ns;
  });
  ASSERT_NE(after, poses.end());
  const double error = (RigidFromProto(after->world_from_cam(), "pose").translation -
                        tracking::testing::SmoothMotion(after->t_ns()).translation)
                           .norm();
  EXPECT_GT(error, 0.005) << "the hint was ignored";
  EXPECT_LT(error, 0.05);

  // A hint before the end of the last packet goes back in time.
  request.mutable_pose_hint()->set_t_ns(hint_t_ns - 2'000'000);
  auto backwards = ShortSession();
  backwards.insert(backwards.begin() + 31, request);
  EXPECT_EQ(RunTrack(*stub_, backwards).status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

// GET `path` from 127.0.0.1:port over HTTP/1.0; the whole response.
std::string HttpGet(int port, const std::string& path) {
  const int connection = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  std::string response;
  if (::connect(connection, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0) {
    const std::string request = "GET " + path + " HTTP/1.0\r\n\r\n";
    ::send(connection, request.data(), request.size(), 0);
    char buffer[4096];
    ssize_t count = 0;
    while ((count = ::recv(connection, buffer, sizeof(buffer), 0)) > 0) {
      response.append(buffer, static_cast<size_t>(count));
    }
  }
  ::close(connection);
  return response;
}

// The value of an unlabelled metric line "NAME VALUE".
double MetricValue(const std::string& text, const std::string& name) {
  const size_t at = text.find("\n" + name + " ");
  if (at == std::string::npos) return -1;
  return std::stod(text.substr(at + name.size() + 2));
}

TEST_F(LocalizerServerTest, ServesPrometheusMetrics) {
  StartServer([](LocalizerServerOptions& options) { options.metrics_address = "127.0.0.1:0"; });
  ASSERT_GT(server_->metrics_port(), 0);
  ASSERT_TRUE(RunTrack(*stub_, ShortSession()).status.ok());
  auto requests = ShortSession();
  requests[0].mutable_start()->set_map_name("atlantis");
  ASSERT_FALSE(RunTrack(*stub_, requests).status.ok());

  const std::string response = HttpGet(server_->metrics_port(), "/metrics");
  ASSERT_EQ(response.rfind("HTTP/1.1 200 OK", 0), 0u) << response;
  const double poses = MetricValue(response, "evloc_poses_total");
  EXPECT_GT(poses, 5);
  EXPECT_EQ(MetricValue(response, "evloc_sessions_started_total"), 1);
  EXPECT_EQ(MetricValue(response, "evloc_sessions_active"), 0);
  EXPECT_EQ(MetricValue(response, "evloc_requests_rejected_total"), 1);
  EXPECT_GT(MetricValue(response, "evloc_events_total"), 1000);
  EXPECT_EQ(MetricValue(response, "evloc_lost_poses_total"), 0);
  EXPECT_EQ(MetricValue(response, "evloc_pose_latency_microseconds_count"), poses);
  EXPECT_NE(response.find("evloc_pose_latency_microseconds_bucket{le=\"+Inf\"} "),
            std::string::npos);
  EXPECT_EQ(HttpGet(server_->metrics_port(), "/other").rfind("HTTP/1.1 404", 0), 0u);
}

// JSON logs (--log-format json): every line the service writes is one JSON object with time,
// level, logger and message; the records of a session carry its id, a refused stream none; the
// drops of the log's queue are a metric.
TEST(LocalizerServerLogTest, JsonLinesParseAndCarryTheSessionIds) {
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), testing::kTestMapName, testing::TestMap());
  LocalizerServerOptions options = testing::TestServerOptions(folder.path());
  options.metrics_address = "127.0.0.1:0";
  std::mutex mutex;
  std::vector<std::string> lines;
  LoggerOptions log_options;
  log_options.format = LogFormat::kJson;
  const auto logger =
      std::make_shared<Logger>("evloc-localizer", log_options, [&](std::string_view line) {
        std::lock_guard<std::mutex> lock(mutex);
        lines.emplace_back(line);
      });
  LocalizerServer server(options, logger);
  auto stub = testing::ConnectStub(server.port());
  std::vector<api::TrackRequest> requests{TestSessionStart()};
  for (auto& packet : testing::PackedPackets(testing::TestEvents(70'000'000), 1'000'000)) {
    requests.push_back(packet);
  }
  ASSERT_TRUE(RunTrack(*stub, requests).status.ok());
  ASSERT_TRUE(RunTrack(*stub, requests).status.ok());
  requests[0].mutable_start()->set_map_name("atlantis\n\"quoted\"");
  ASSERT_EQ(RunTrack(*stub, requests).status.error_code(), grpc::StatusCode::NOT_FOUND);
  const std::string metrics = HttpGet(server.metrics_port(), "/metrics");
  EXPECT_EQ(MetricValue(metrics, "evloc_log_records_dropped_total"), 0) << metrics;
  logger->Flush();

  std::lock_guard<std::mutex> lock(mutex);
  ASSERT_EQ(lines.size(), 5u);  // Two sessions' start and end, one refusal.
  std::map<uint64_t, std::vector<std::string>> events_of_session;
  int refusals = 0;
  for (const std::string& line : lines) {
    nlohmann::json record;
    ASSERT_NO_THROW(record = nlohmann::json::parse(line)) << line;
    for (const char* key : {"time", "level", "logger", "message", "fields"}) {
      ASSERT_TRUE(record.contains(key)) << key << " in " << line;
    }
    EXPECT_EQ(record["logger"], "evloc-localizer");
    EXPECT_EQ(record["level"], "info");
    const std::string event = record["fields"]["event"];
    if (event == "refused") {
      ++refusals;
      EXPECT_FALSE(record.contains("session")) << line;
      EXPECT_EQ(record["fields"]["code"], "NOT_FOUND");
      EXPECT_NE(record["message"].get<std::string>().find("refused: NOT_FOUND"), std::string::npos);
      continue;
    }
    ASSERT_TRUE(record.contains("session")) << line;
    const uint64_t session = record["session"];
    EXPECT_EQ(record["message"].get<std::string>().rfind("session " + std::to_string(session), 0),
              0u)
        << line;
    events_of_session[session].push_back(event);
    if (event == "start") {
      EXPECT_EQ(record["fields"]["map"], testing::kTestMapName);
      EXPECT_GT(record["fields"]["map_points"].get<int64_t>(), 0);
    } else {
      EXPECT_EQ(record["fields"]["code"], "OK");
      EXPECT_GT(record["fields"]["poses"].get<int64_t>(), 5);
      EXPECT_GT(record["fields"]["latency_p99_us"].get<double>(), 0);
    }
  }
  EXPECT_EQ(refusals, 1);
  const std::vector<std::string> start_end{"start", "end"};
  EXPECT_EQ(events_of_session,
            (std::map<uint64_t, std::vector<std::string>>{{1, start_end}, {2, start_end}}));
}

// --log-level warning: a session that goes well writes nothing; a refused stream neither (info).
TEST(LocalizerServerLogTest, TheLevelFiltersTheServicesRecords) {
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), testing::kTestMapName, testing::TestMap());
  std::vector<std::string> lines;
  LoggerOptions log_options;
  log_options.level = LogLevel::kWarning;
  log_options.asynchronous = false;
  const auto logger = std::make_shared<Logger>(
      "evloc-localizer", log_options, [&](std::string_view line) { lines.emplace_back(line); });
  LocalizerServer server(testing::TestServerOptions(folder.path()), logger);
  auto stub = testing::ConnectStub(server.port());
  std::vector<api::TrackRequest> requests{TestSessionStart()};
  for (auto& packet : testing::PackedPackets(testing::TestEvents(70'000'000), 1'000'000)) {
    requests.push_back(packet);
  }
  ASSERT_TRUE(RunTrack(*stub, requests).status.ok());
  requests[0].mutable_start()->set_map_name("atlantis");
  ASSERT_EQ(RunTrack(*stub, requests).status.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(lines.empty()) << lines.front();
}

TEST_F(LocalizerServerTest, ServesTlsWhenGivenACertificate) {
  if (std::system("openssl version > /dev/null 2>&1") != 0) {
    GTEST_SKIP() << "the openssl command is not installed: cannot make a test certificate";
  }
  const auto cert = folder_.path() / "cert.pem";
  const auto key = folder_.path() / "key.pem";
  const std::string command =
      "openssl req -x509 -newkey rsa:2048 -nodes -days 1 -subj /CN=localhost -addext "
      "subjectAltName=DNS:localhost,IP:127.0.0.1 -keyout '" +
      key.string() + "' -out '" + cert.string() + "' > /dev/null 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0);
  StartServer([&](LocalizerServerOptions& options) {
    options.tls_cert_file = cert;
    options.tls_key_file = key;
  });
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs = ReadFileToString(cert);
  grpc::ChannelArguments arguments;
  arguments.SetSslTargetNameOverride("localhost");
  auto secure = api::Localizer::NewStub(grpc::CreateCustomChannel(
      "127.0.0.1:" + std::to_string(server_->port()), grpc::SslCredentials(ssl), arguments));
  grpc::ClientContext secure_context;
  secure_context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  api::ListMapsResponse list;
  const grpc::Status status = secure->ListMaps(&secure_context, {}, &list);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(list.maps_size(), 1);
  EXPECT_TRUE(RunTrack(*secure, ShortSession()).status.ok());

  grpc::ClientContext plain_context;
  plain_context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(2));
  EXPECT_FALSE(stub_->ListMaps(&plain_context, {}, &list).ok());
}

// A site of the test map (0.4 m tiles, 0.1 m overlap) beside the map itself.
constexpr char kTestSiteName[] = "rectangles_site";

SiteManifest WriteTestSite(const std::filesystem::path& maps_dir) {
  TilingOptions tiling;
  tiling.tile_size_m = 0.4;
  tiling.overlap_m = 0.1;
  return TileMap(testing::TestMap(), maps_dir / kTestSiteName, tiling);
}

TEST_F(LocalizerServerTest, ServesASiteOfTilesLikeItsWholeMap) {
  StartServer([](LocalizerServerOptions& options) {
    options.queue_packets = 1024;
    options.metrics_address = "127.0.0.1:0";
  });
  const SiteManifest manifest = WriteTestSite(folder_.path());
  ASSERT_GE(manifest.tiles.size(), 12u);

  grpc::ClientContext list_context;
  api::ListMapsResponse list;
  ASSERT_TRUE(stub_->ListMaps(&list_context, {}, &list).ok());
  ASSERT_EQ(list.maps_size(), 2);
  EXPECT_EQ(list.maps(1).name(), kTestSiteName);
  EXPECT_EQ(list.maps(1).version(), manifest.version);
  EXPECT_EQ(list.maps(1).num_points(), testing::TestMap().size());  // Core points: each once.

  const EventBuffer events = testing::TestEvents(300'000'000);
  std::vector<api::TrackRequest> whole{TestSessionStart()};
  for (auto& packet : testing::PackedPackets(events, 1'000'000)) whole.push_back(packet);
  std::vector<api::TrackRequest> tiled = whole;
  tiled[0].mutable_start()->set_map_name(kTestSiteName);
  const TrackOutcome whole_outcome = RunTrack(*stub_, whole);
  const TrackOutcome tiled_outcome = RunTrack(*stub_, tiled);
  ASSERT_TRUE(whole_outcome.status.ok()) << whole_outcome.status.error_message();
  ASSERT_TRUE(tiled_outcome.status.ok()) << tiled_outcome.status.error_message();
  EXPECT_EQ(tiled_outcome.responses.front().started().map().version(), manifest.version);
  const auto whole_poses = whole_outcome.Poses();
  const auto tiled_poses = tiled_outcome.Poses();
  ASSERT_EQ(tiled_poses.size(), whole_poses.size());
  ASSERT_GE(tiled_poses.size(), 50u);
  double worst_m = 0;
  for (size_t i = 0; i < tiled_poses.size(); ++i) {
    EXPECT_EQ(tiled_poses[i].status(), api::TRACKING) << "step " << i;
    const Rigid3d truth = tracking::testing::SmoothMotion(tiled_poses[i].t_ns());
    worst_m = std::max(
        worst_m,
        (RigidFromProto(tiled_poses[i].world_from_cam(), "pose").translation - truth.translation)
            .norm());
  }
  // The whole map tracks within about a centimetre here; the tiles (voxel visibility, tiles
  // coming and going) within 2 cm at every step.
  EXPECT_LT(worst_m, 0.02);

  const std::string response = HttpGet(server_->metrics_port(), "/metrics");
  EXPECT_GE(MetricValue(response, "evloc_tile_loads_total"), 4);
  EXPECT_EQ(MetricValue(response, "evloc_tile_load_failures_total"), 0);
  EXPECT_GT(MetricValue(response, "evloc_tile_resident_bytes"), 0);
  EXPECT_GE(MetricValue(response, "evloc_tile_misses_total"), 4);
  EXPECT_EQ(MetricValue(response, "evloc_tile_budget_bytes"), 1 << 30);
}

// A session without a pose on a site searches only the tiles near its GnssFix: without one (and
// this site has no anchor to take one) it stays INITIALIZING and loads no tile. A site's tiles
// must be intact.
TEST_F(LocalizerServerTest, ASiteSessionWithoutAPoseWaitsForAFixAndTilesMustBeIntact) {
  StartServer([](LocalizerServerOptions& options) { options.metrics_address = "127.0.0.1:0"; });
  const SiteManifest manifest = WriteTestSite(folder_.path());
  std::vector<api::TrackRequest> requests = ShortSession();
  requests[0].mutable_start()->set_map_name(kTestSiteName);
  requests[0].mutable_start()->clear_initial_world_from_cam();
  TrackOutcome outcome = RunTrack(*stub_, requests);
  ASSERT_TRUE(outcome.status.ok()) << outcome.status.error_message();
  ASSERT_FALSE(outcome.Poses().empty());
  for (const api::PoseUpdate& pose : outcome.Poses()) {
    EXPECT_EQ(pose.status(), api::INITIALIZING);
  }
  EXPECT_EQ(MetricValue(HttpGet(server_->metrics_port(), "/metrics"), "evloc_tile_loads_total"), 0);
  // A damaged tile needed at the start: the session cannot open, and says which map.
  for (const SiteTile& tile : manifest.tiles) {
    std::filesystem::resize_file(folder_.path() / kTestSiteName / tile.file_name, 100);
  }
  requests = ShortSession();
  requests[0].mutable_start()->set_map_name(kTestSiteName);
  outcome = RunTrack(*stub_, requests);
  EXPECT_EQ(outcome.status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(outcome.status.error_message().find(kTestSiteName), std::string::npos);
}

}  // namespace
}  // namespace evloc::service

namespace evloc::service {
namespace {

// A GnssFix on a map without a geo anchor ends the session with FAILED_PRECONDITION naming the
// remedy (docs/api.md, docs/geo.md); the test map has no anchor, and SessionStarted says so.
TEST_F(LocalizerServerTest, GnssFixOnAMapWithoutAnAnchorIsRefused) {
  StartServer();
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  auto stream = stub_->Track(&context);
  ASSERT_TRUE(stream->Write(TestSessionStart()));
  api::TrackRequest fix;
  fix.mutable_gnss_fix()->set_latitude_deg(46.5);
  fix.mutable_gnss_fix()->set_longitude_deg(6.5);
  fix.mutable_gnss_fix()->set_altitude_m(400);
  fix.mutable_gnss_fix()->set_horizontal_accuracy_m(3);
  fix.mutable_gnss_fix()->set_vertical_accuracy_m(5);
  fix.mutable_gnss_fix()->set_t_ns(testing::kInitialTimeNs);
  stream->Write(fix);
  stream->WritesDone();
  api::TrackResponse response;
  bool started = false;
  while (stream->Read(&response)) {
    if (response.has_started()) {
      started = true;
      EXPECT_FALSE(response.started().map().has_geo_anchor());
    }
    EXPECT_FALSE(response.has_pose());
  }
  EXPECT_TRUE(started);
  const grpc::Status status = stream->Finish();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(status.error_message().find("has no geo anchor"), std::string::npos)
      << status.error_message();
  EXPECT_NE(status.error_message().find("evloc-mapper georef"), std::string::npos);
}

}  // namespace
}  // namespace evloc::service
