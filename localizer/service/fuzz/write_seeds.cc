// evloc_session_fuzz_seeds OUT_DIR: writes the seed corpora of the session fuzz targets
// (docs/reliability.md §4) into OUT_DIR/packets and OUT_DIR/requests, in the input formats the
// targets read (session_packets_fuzzer.cc, session_requests_fuzzer.cc), from the synthetic test
// scene: PACKED, EVT 3.0 and EVT 2.0 packet streams; event sessions (PACKED and EVT 3.0, with a
// pose hint and empty packets; with a depth camera and DepthFrames) and a frame session; and
// OUT_DIR/locate, the Locate requests of locate_request_fuzzer.cc (locate_fuzz_common.h); and
// OUT_DIR/viewer, HTTP requests of every route of the live viewer (viewer_requests_fuzzer.cc).
#include <filesystem>
#include <fstream>
#include <iostream>

#include "core/common/error.h"
#include "core/events/evt3_encoder.h"
#include "localizer/service/fuzz/locate_fuzz_common.h"
#include "localizer/service/fuzz/session_fuzz_common.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "localizer/wire/packed_events.h"
#include "localizer/wire/twist.h"
#include "proto/convert/proto_convert.h"

namespace evloc::service::fuzz {
namespace {

namespace fs = std::filesystem;

constexpr int64_t kWindowNs = 100'000;
constexpr int kWindows = 12;
// Every kSubsample-th test event only: small seeds (libFuzzer's -max_len) that stay valid.
constexpr size_t kSubsample = 8;

// The test events in kWindows windows of kWindowNs after `start_ns`, subsampled.
std::vector<EventBuffer> Windows(int64_t start_ns) {
  static const EventBuffer events = testing::TestEvents(testing::kInitialTimeNs + 10'000'000);
  std::vector<EventBuffer> windows(kWindows);
  for (size_t i = 0; i < events.size(); i += kSubsample) {
    if (events.t_ns[i] <= start_ns) continue;
    const int64_t index = (events.t_ns[i] - start_ns - 1) / kWindowNs;
    if (index < kWindows) windows[static_cast<size_t>(index)].push_back(events[i]);
  }
  return windows;
}

// EVT 2.0 words of `events` (times in whole microseconds); `time_high` carries across calls.
std::string EncodeEvt2(const EventBuffer& events, std::optional<int64_t>* time_high) {
  std::string out;
  for (size_t i = 0; i < events.size(); ++i) {
    const int64_t t_us = events.t_ns[i] / 1000;
    if (!*time_high || **time_high != t_us >> 6) {
      *time_high = t_us >> 6;
      AppendLittleEndian(0x80000000u | (static_cast<uint32_t>(**time_high) & 0x0fffffffu), 4, &out);
    }
    const uint32_t type = events.polarity[i] > 0 ? 1u : 0u;
    AppendLittleEndian(type << 28 | (static_cast<uint32_t>(t_us) & 0x3fu) << 22 |
                           (static_cast<uint32_t>(events.x[i]) & 0x7ffu) << 11 |
                           (static_cast<uint32_t>(events.y[i]) & 0x7ffu),
                       4, &out);
  }
  return out;
}

// Encodes the windows in `encoding`; PACKED offsets count from each window's start.
std::vector<std::string> EncodeWindows(const std::vector<EventBuffer>& windows, int64_t start_ns,
                                       api::EventEncoding encoding) {
  std::vector<std::string> packets;
  Evt3Encoder evt3;
  std::optional<int64_t> evt2_time_high;
  for (size_t i = 0; i < windows.size(); ++i) {
    std::string data;
    if (encoding == api::EVENT_ENCODING_PACKED) {
      data = wire::EncodePackedEvents(windows[i], 0, windows[i].size(),
                                      start_ns + static_cast<int64_t>(i) * kWindowNs);
    } else if (encoding == api::EVENT_ENCODING_EVT3) {
      evt3.Encode(windows[i], &data);
    } else {
      data = EncodeEvt2(windows[i], &evt2_time_high);
    }
    packets.push_back(std::move(data));
  }
  return packets;
}

// A seed of the packets target: 320x240, sensor offset 0.
std::string PacketsSeed(api::EventEncoding encoding) {
  const int64_t start_ns = testing::kInitialTimeNs;
  std::string seed;
  AppendLittleEndian(319, 2, &seed);
  AppendLittleEndian(239, 2, &seed);
  AppendLittleEndian(0, 8, &seed);
  AppendLittleEndian(static_cast<uint64_t>(start_ns), 8, &seed);
  for (const std::string& data : EncodeWindows(Windows(start_ns), start_ns, encoding)) {
    seed.push_back(static_cast<char>(encoding));
    AppendLittleEndian(0, 4, &seed);          // time_base_ns = previous end
    AppendLittleEndian(kWindowNs, 4, &seed);  // end_t_ns = previous end + window
    AppendLittleEndian(data.size(), 2, &seed);
    seed += data;
  }
  return seed;
}

// The camera of the requests seeds: the test camera scaled down 4 times (fast executions).
Camera SmallCamera() { return Camera::Pinhole(80, 60, 62.5, 62.5, 39.5, 29.5); }

// A seed of the requests target: the test SessionStart with SmallCamera(), then the windows as
// EventPackets (coordinates scaled to the small camera; from 0.1 ms before the initial time, so
// that the first one primes the surfaces); with `pose_hint` a PoseHint and an empty packet in the
// middle; with `filters` every noise filter on, the hot-pixel learning period (1 ms) ending within
// the seed's windows; with `velocity` an initial velocity (a resumed session) and the motion
// prior; with `gnss_fix` the session tracks the anchored map; with `depth` the session has a
// depth camera (16x12) and a DepthFrame follows every third packet (TrackRequest.depth, the
// hand-over to odometry).
std::string RequestsSeed(api::EventEncoding encoding, bool pose_hint, bool filters = false,
                         bool velocity = false, bool gnss_fix = false, bool depth = false) {
  const int64_t start_ns = testing::kInitialTimeNs - kWindowNs;
  std::string seed;
  api::TrackRequest start = testing::TestSessionStart();
  *start.mutable_start()->mutable_camera() = CameraToProto(SmallCamera());
  // Steps every 250 us, so that the few windows run several.
  start.mutable_start()->mutable_options()->set_step_rate_hz(4000);
  if (filters) {
    api::EventFilterOptions* filter =
        start.mutable_start()->mutable_options()->mutable_event_filter();
    filter->set_hot_pixels(true);
    filter->set_hot_pixel_window_s(0.001);
    filter->set_hot_pixel_rate_factor(4);
    filter->set_hot_pixel_min_rate_hz(5000);
    filter->set_refractory_period_s(0.0002);
    filter->set_background_activity_window_s(0.0005);
    filter->set_background_activity_include_self(true);
  }
  if (velocity) {
    *start.mutable_start()->mutable_initial_velocity() =
        wire::TwistToProto((Vector6d() << 0.2, -0.1, 0.05, 0.3, 0.1, -0.2).finished());
    // A resumed session's velocity spans the smooth window at once: its motion prior applies
    // from the first step.
    start.mutable_start()->mutable_options()->set_motion_prior_velocity_sigma_mps(2);
    start.mutable_start()->mutable_options()->set_motion_prior_angular_velocity_sigma_dps(20);
  }
  if (gnss_fix) start.mutable_start()->set_map_name(kAnchoredTestMapName);
  const Camera depth_camera = Camera::Pinhole(16, 12, 14, 14, 7.5, 5.5);
  if (depth) {
    *start.mutable_start()->mutable_depth_camera()->mutable_camera() = CameraToProto(depth_camera);
    *start.mutable_start()->mutable_depth_camera()->mutable_event_from_depth() =
        RigidToProto(Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.02, Eigen::Vector3d::UnitY())),
                             Eigen::Vector3d(0.04, 0.0, 0.0)));
  }
  AppendRecord(start.SerializeAsString(), &seed);
  std::vector<EventBuffer> windows = Windows(start_ns);
  for (EventBuffer& window : windows) {
    for (size_t i = 0; i < window.size(); ++i) {
      window.x[i] = static_cast<uint16_t>(window.x[i] / 4);
      window.y[i] = static_cast<uint16_t>(window.y[i] / 4);
    }
  }
  const std::vector<std::string> packets = EncodeWindows(windows, start_ns, encoding);
  for (size_t i = 0; i < packets.size(); ++i) {
    const int64_t window_start = start_ns + static_cast<int64_t>(i) * kWindowNs;
    api::TrackRequest request;
    api::EventPacket* packet = request.mutable_events();
    packet->set_encoding(encoding);
    packet->set_data(packets[i]);
    packet->set_time_base_ns(window_start);
    packet->set_end_t_ns(window_start + kWindowNs);
    AppendRecord(request.SerializeAsString(), &seed);
    if (gnss_fix && i == 0) {
      // A fix at the true position (through the anchor), 3 m horizontal, 5 m vertical.
      const GeoReference reference(*AnchoredTestMap().geo_anchor);
      const GeodeticPoint position = reference.GeodeticFromMap(
          tracking::testing::SmoothMotion(window_start + kWindowNs).translation);
      api::TrackRequest fix;
      fix.mutable_gnss_fix()->set_latitude_deg(position.latitude_deg);
      fix.mutable_gnss_fix()->set_longitude_deg(position.longitude_deg);
      fix.mutable_gnss_fix()->set_altitude_m(position.altitude_m);
      fix.mutable_gnss_fix()->set_horizontal_accuracy_m(3.0);
      fix.mutable_gnss_fix()->set_vertical_accuracy_m(5.0);
      fix.mutable_gnss_fix()->set_t_ns(window_start + kWindowNs);
      AppendRecord(fix.SerializeAsString(), &seed);
    }
    if (depth && i % 3 == 2) {
      // A plane 2 m away with a hole.
      cv::Mat depth_m(depth_camera.height, depth_camera.width, CV_32FC1, cv::Scalar(2.0));
      depth_m(cv::Rect(3, 2, 4, 3)).setTo(0.0f);
      AppendRecord(
          testing::DepthFrameRequest(window_start + kWindowNs, depth_m).SerializeAsString(), &seed);
    }
    if (pose_hint && i == packets.size() / 2) {
      api::TrackRequest hint;
      hint.mutable_pose_hint()->set_t_ns(window_start + kWindowNs);
      *hint.mutable_pose_hint()->mutable_world_from_cam() =
          RigidToProto(tracking::testing::SmoothMotion(window_start + kWindowNs));
      AppendRecord(hint.SerializeAsString(), &seed);
      api::TrackRequest empty;
      empty.mutable_events()->set_end_t_ns(window_start + kWindowNs + 1);
      AppendRecord(empty.SerializeAsString(), &seed);
    }
  }
  return seed;
}

// A seed of the requests target: a frame session with SmallCamera() and three frames.
std::string FrameSeed() {
  const Camera camera = SmallCamera();
  api::TrackRequest start = testing::TestSessionStart();
  *start.mutable_start()->mutable_camera() = CameraToProto(camera);
  start.mutable_start()->mutable_options()->set_frames(true);
  std::string seed;
  AppendRecord(start.SerializeAsString(), &seed);
  for (int i = 1; i <= 3; ++i) {
    const int64_t t_ns = testing::kInitialTimeNs + i * 5'000'000;
    const cv::Mat gray = tracking::testing::RenderRectangles(
        tracking::testing::DefaultRectangles(), camera, tracking::testing::SmoothMotion(t_ns));
    api::TrackRequest request;
    request.mutable_frame()->set_t_ns(t_ns);
    request.mutable_frame()->set_width(80);
    request.mutable_frame()->set_height(60);
    request.mutable_frame()->set_gray(
        std::string(reinterpret_cast<const char*>(gray.data), gray.total()));
    AppendRecord(request.SerializeAsString(), &seed);
  }
  return seed;
}

void WriteFile(const fs::path& path, const std::string& bytes) {
  std::ofstream file(path, std::ios::binary);
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!file) throw IoError("cannot write " + path.string());
}

int Main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: evloc_session_fuzz_seeds OUT_DIR\n";
    return 2;
  }
  const fs::path out = argv[1];
  fs::create_directories(out / "packets");
  fs::create_directories(out / "requests");
  WriteFile(out / "packets" / "packed", PacketsSeed(api::EVENT_ENCODING_PACKED));
  WriteFile(out / "packets" / "evt3", PacketsSeed(api::EVENT_ENCODING_EVT3));
  WriteFile(out / "packets" / "evt2", PacketsSeed(api::EVENT_ENCODING_EVT2));
  WriteFile(out / "requests" / "packed", RequestsSeed(api::EVENT_ENCODING_PACKED, false));
  WriteFile(out / "requests" / "packed_hint", RequestsSeed(api::EVENT_ENCODING_PACKED, true));
  WriteFile(out / "requests" / "evt3", RequestsSeed(api::EVENT_ENCODING_EVT3, false));
  WriteFile(out / "requests" / "packed_filters",
            RequestsSeed(api::EVENT_ENCODING_PACKED, true, /*filters=*/true));
  WriteFile(out / "requests" / "packed_velocity",
            RequestsSeed(api::EVENT_ENCODING_PACKED, false, /*filters=*/false,
                         /*velocity=*/true));
  WriteFile(out / "requests" / "frames", FrameSeed());
  WriteFile(out / "requests" / "packed_depth",
            RequestsSeed(api::EVENT_ENCODING_PACKED, false, /*filters=*/false, /*velocity=*/false,
                         /*gnss_fix=*/false, /*depth=*/true));
  WriteFile(out / "requests" / "packed_gnss_fix",
            RequestsSeed(api::EVENT_ENCODING_PACKED, false, /*filters=*/false, /*velocity=*/false,
                         /*gnss_fix=*/true));
  fs::create_directories(out / "locate");
  const std::vector<api::LocateRequest> locate = LocateSeedRequests();
  for (size_t i = 0; i < locate.size(); ++i) {
    WriteFile(out / "locate" / ("request" + std::to_string(i)), locate[i].SerializeAsString());
  }
  fs::create_directories(out / "viewer");
  const char* const viewer_requests[] = {
      "GET / HTTP/1.1\r\nHost: x\r\n\r\n",
      "GET /app.js HTTP/1.1\r\n\r\n",
      "GET /api/maps HTTP/1.1\r\nAuthorization: Bearer abc\r\n\r\n",
      "GET /api/maps/rectangles HTTP/1.1\r\n\r\n",
      "GET /api/maps/rectangles/points?max=100 HTTP/1.1\r\n\r\n",
      "GET /api/sessions HTTP/1.1\r\n\r\n",
      "GET /api/events?rate=30 HTTP/1.1\r\n\r\n",
      "GET /api/sessions/1/surface.png HTTP/1.1\r\n\r\n",
      "POST /api/maps HTTP/1.1\r\nContent-Length: 4\r\n\r\nabcd",
  };
  for (size_t i = 0; i < std::size(viewer_requests); ++i) {
    WriteFile(out / "viewer" / ("request" + std::to_string(i)), viewer_requests[i]);
  }
  for (const auto& entry : fs::recursive_directory_iterator(out)) {
    if (entry.is_regular_file()) {
      std::cout << entry.path().string() << ": " << entry.file_size() << " bytes\n";
    }
  }
  return 0;
}

}  // namespace
}  // namespace evloc::service::fuzz

int main(int argc, char** argv) {
  try {
    return evloc::service::fuzz::Main(argc, argv);
  } catch (const std::exception& error) {
    std::cerr << "evloc_session_fuzz_seeds: " << error.what() << "\n";
    return 1;
  }
}
