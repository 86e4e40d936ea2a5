// libFuzzer target: the request handling of a Track session without the network
// (docs/reliability.md §4): the SessionStart through OpenSession (validation, map registry,
// tracker), then every later TrackRequest through RequestValidator and SessionTracker::Process,
// exactly as the server's reader and tracking worker run them.
//
// Input: records, each a LEB128 length and a serialized TrackRequest (at most 64); the first must
// be a SessionStart (the server refuses anything else before this code runs). Seeds:
// evloc_session_fuzz_seeds (fuzz/write_seeds.cc).
// Oracles (abort): OpenSession answers OK, NOT_FOUND or INVALID_ARGUMENT (the registry's only map
// loads, so never FAILED_PRECONDITION); a later request is accepted or refused with
// INVALID_ARGUMENT (FAILED_PRECONDITION only for a second SessionStart); Process never throws
// on an accepted request (the server would answer INTERNAL); step times increase; an EventPacket
// runs every step up to its end_t_ns and none after it; poses are finite unit-quaternion poses.
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>

#include "localizer/service/fuzz/session_fuzz_common.h"
#include "localizer/service/map_registry.h"
#include "localizer/service/testing/service_fixture.h"

namespace evloc::service::fuzz {
namespace {

constexpr int kMaxRequests = 64;

// A registry of the test map in a temporary map folder, made once per process (the folder is
// removed at exit).
MapRegistry& Registry() {
  static testing::TemporaryFolder folder;
  static MapRegistry registry = [] {
    testing::WriteTestMap(folder.path(), testing::kTestMapName, testing::TestMap());
    // The same map with a geo anchor, for GnssFix requests (docs/geo.md).
    testing::WriteTestMap(folder.path(), kAnchoredTestMapName, AnchoredTestMap());
    return MapRegistry(MapRegistryOptions{folder.path()});
  }();
  return registry;
}

void CheckPose(const tracking::PoseEstimate& estimate) {
  const Rigid3d& pose = estimate.world_from_cam;
  EVLOC_FUZZ_REQUIRE(pose.translation.allFinite());
  EVLOC_FUZZ_REQUIRE(pose.rotation.coeffs().allFinite());
  EVLOC_FUZZ_REQUIRE(std::abs(pose.rotation.norm() - 1.0) < 1e-6);
  EVLOC_FUZZ_REQUIRE(estimate.status == tracking::TrackingStatus::kTracking ||
                     estimate.status == tracking::TrackingStatus::kLost ||
                     estimate.status == tracking::TrackingStatus::kRelocalizing ||
                     estimate.status == tracking::TrackingStatus::kInitializing);
}

int Run(const uint8_t* data, size_t size) {
  FuzzInput input(data, size);
  std::string record;
  api::TrackRequest request;
  if (!input.Record(&record) || !request.ParseFromString(record) || !request.has_start()) {
    return 0;
  }
  // Small sensors and few points keep an execution fast (the server's defaults are larger; the
  // request handling does not depend on them).
  SessionLimits limits;
  limits.max_camera_pixels = 320 * 240;
  limits.tracker.max_points = 300;
  // At most 20 steps per request (a step takes tens of ms under the sanitizers).
  limits.max_step_rate_hz = 2000;
  limits.max_packet_span_ns = 10'000'000;
  OpenedSession session;
  const grpc::Status opened = OpenSession(request.start(), Registry(), limits, &session);
  CheckStatus(opened, {grpc::StatusCode::NOT_FOUND, grpc::StatusCode::INVALID_ARGUMENT});
  if (!opened.ok()) return 0;
  EVLOC_FUZZ_REQUIRE(session.tracker != nullptr);

  RequestValidator validator(session.settings, limits);
  const double period_ns = 1e9 / session.settings.tracker.step_rate_hz;
  std::optional<int64_t> last_step_t_ns;
  SessionItem item;
  for (int count = 1; count < kMaxRequests && input.Record(&record); ++count) {
    // A message gRPC cannot parse never reaches the session.
    if (!request.ParseFromString(record)) return 0;
    const grpc::Status status = validator.Accept(request, &item);
    CheckStatus(status,
                {grpc::StatusCode::INVALID_ARGUMENT, grpc::StatusCode::FAILED_PRECONDITION});
    EVLOC_FUZZ_REQUIRE(status.error_code() != grpc::StatusCode::FAILED_PRECONDITION ||
                       request.has_start());
    if (!status.ok()) return 0;  // The session ends with the first error.
    // The server ends a session whose map has no anchor at a GnssFix (FAILED_PRECONDITION).
    if (item.kind == SessionItem::Kind::kGnssFix && !session.tracker->geo()) return 0;
    std::vector<tracking::PoseEstimate> estimates;
    try {
      estimates = session.tracker->Process(item);
    } catch (...) {
      std::abort();  // The server would end the session with INTERNAL: a bug.
    }
    if (item.kind == SessionItem::Kind::kPoseHint) last_step_t_ns = item.t_ns;
    for (const tracking::PoseEstimate& estimate : estimates) {
      CheckPose(estimate);
      EVLOC_FUZZ_REQUIRE(!last_step_t_ns || estimate.t_ns > *last_step_t_ns);
      EVLOC_FUZZ_REQUIRE(estimate.t_ns <= item.t_ns);
      last_step_t_ns = estimate.t_ns;
    }
    // After a packet every step up to its end ran: the next one is later than the end.
    if (item.kind == SessionItem::Kind::kEvents && !estimates.empty()) {
      EVLOC_FUZZ_REQUIRE(static_cast<double>(estimates.back().t_ns) + period_ns >
                         static_cast<double>(item.t_ns) - 1);
    }
  }
  return 0;
}

}  // namespace
}  // namespace evloc::service::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return evloc::service::fuzz::Run(data, size);
}
