// Helpers for tests of the localizer service and its clients: a map folder with the synthetic
// rectangle map, a server on loopback, the synthetic event stream and the Track requests for it.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/common/file_util.h"
#include "core/events/event.h"
#include "core/events/event_reader.h"
#include "evloc/localizer.grpc.pb.h"
#include "localizer/service/localizer_server.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "maps/map.h"

namespace evloc::service::testing {

// Name of the map the fixture writes.
inline constexpr char kTestMapName[] = "rectangles";
// Start of the tracked part of the synthetic stream, ns (earlier events prime the surfaces).
inline constexpr int64_t kInitialTimeNs = 20'000'000;

// The synthetic rectangle map (outline points every centimetre).
Map TestMap();
// TestMap() with keyframes every 150 ms over [0, 600 ms] of testing::SmoothMotion, each moved
// 6 cm and 3 degrees off the path (a map built from another pass): what a session started
// without a pose searches from.
Map TestMapWithKeyframesBesideThePath();
// The 320x240 pinhole camera of the synthetic scene.
Camera TestCamera();
// Ideal edge events of TestMap() seen along testing::SmoothMotion over [0, duration_ns], fired
// as `timing` says.
EventBuffer TestEvents(int64_t duration_ns, tracking::testing::EdgeEventTiming timing =
                                                tracking::testing::EdgeEventTiming::kEnterPixel);

// The reader of in-memory events (core/events).
using evloc::BufferEventReader;

// A fresh temporary folder (evloc-service-test-XXXXXX under the system temporary directory)
// removed on destruction.
class TemporaryFolder : public PrivateTempFolder {
 public:
  TemporaryFolder() : PrivateTempFolder("evloc-service-test", "a test") {}
};

// Writes `map` as maps_dir/name/map.evmap (and map.ply).
void WriteTestMap(const std::filesystem::path& maps_dir, const std::string& name, const Map& map);

// Writes a dataset folder root/dataset (calib.yaml, events.evb, groundtruth.txt) of the test
// scene over [kInitialTimeNs, duration_ns], its events fired as `timing` says, and returns its
// path.
std::filesystem::path WriteTestDataset(
    const std::filesystem::path& root, int64_t duration_ns,
    tracking::testing::EdgeEventTiming timing = tracking::testing::EdgeEventTiming::kEnterPixel);

// Server options for tests: the given map folder, 127.0.0.1 port 0, short idle timeout, the
// search workers at normal priority.
LocalizerServerOptions TestServerOptions(const std::filesystem::path& maps_dir);

// A stub connected to 127.0.0.1:port.
std::unique_ptr<api::Localizer::Stub> ConnectStub(int port);

// A SessionStart for the test map and camera at the synthetic motion's pose at kInitialTimeNs,
// 200 Hz steps.
api::TrackRequest TestSessionStart();

// A DepthFrame request of `depth_m` (CV_32FC1 metres, 0 = none) taken at t_ns: little-endian
// uint16 millimetres.
api::TrackRequest DepthFrameRequest(int64_t t_ns, const cv::Mat& depth_m);

// PACKED EventPackets of `events`, one per `packet_ns` window starting at the first event.
std::vector<api::TrackRequest> PackedPackets(const EventBuffer& events, int64_t packet_ns);

// Streams one session (TestSessionStart named `client_name`, then the PackedPackets of `events`
// in `packet_ns` windows) to 127.0.0.1:port, one packet every `wall_per_packet`, until the
// packets run out or `stop` is set; returns the PoseUpdates received. For tests that watch live
// sessions (the viewer).
int64_t StreamPacedSession(int port, const EventBuffer& events, int64_t packet_ns,
                           std::chrono::milliseconds wall_per_packet, const std::atomic<bool>& stop,
                           const std::string& client_name = "test");

}  // namespace evloc::service::testing
