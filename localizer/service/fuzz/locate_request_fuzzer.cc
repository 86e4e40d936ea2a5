// libFuzzer target: the Locate RPC's request handling without the network (docs/reliability.md
// §4): a serialized LocateRequest through LocateInLoadedMap, exactly as the server's handler runs
// it after the registry found the map; map_name "v1" picks the map without relocalization data,
// any other name the map with it and a geo anchor (locate_fuzz_common.h). Seeds:
// evloc_session_fuzz_seeds OUT_DIR/locate. Oracles (abort): no exception escapes; the status is OK,
// INVALID_ARGUMENT or (only for the v1 map, which has neither relocalization data nor a geo anchor)
// FAILED_PRECONDITION; an OK response is FOUND with a finite unit-quaternion pose and 36 finite
// covariance values, or NOT_FOUND without a pose and with a reason.
#include <cmath>
#include <cstdint>

#include "localizer/service/fuzz/locate_fuzz_common.h"
#include "localizer/service/fuzz/session_fuzz_common.h"
#include "localizer/service/locate_rpc.h"

namespace evloc::service::fuzz {
namespace {

int Run(const uint8_t* data, size_t size) {
  static const std::shared_ptr<const LoadedMap> v2 = LocateFuzzMap(true);
  static const std::shared_ptr<const LoadedMap> v1 = LocateFuzzMap(false);
  api::LocateRequest request;
  if (!request.ParseFromArray(data, static_cast<int>(size))) return 0;
  const bool is_v1 = request.map_name() == "v1";
  // Twice the fuzz camera's pixels: larger requests are refused before any decoding.
  constexpr int64_t kMaxCameraPixels = 2 * 160 * 120;
  api::LocateResponse response;
  const grpc::Status status = LocateInLoadedMap(request, is_v1 ? *v1 : *v2, kMaxCameraPixels,
                                                relocalization::LocateOptions(), &response);
  if (!status.ok()) {
    EVLOC_FUZZ_REQUIRE(status.error_code() == grpc::StatusCode::INVALID_ARGUMENT ||
                       (is_v1 && status.error_code() == grpc::StatusCode::FAILED_PRECONDITION));
    EVLOC_FUZZ_REQUIRE(!status.error_message().empty());
    return 0;
  }
  EVLOC_FUZZ_REQUIRE(!is_v1);
  if (response.status() == api::FOUND) {
    const Rigid3d pose = RigidFromProto(response.world_from_cam(), "pose");
    EVLOC_FUZZ_REQUIRE(pose.translation.allFinite());
    EVLOC_FUZZ_REQUIRE(std::abs(pose.rotation.norm() - 1.0) < 1e-6);
    EVLOC_FUZZ_REQUIRE(response.covariance_size() == 36);
    for (const double value : response.covariance()) EVLOC_FUZZ_REQUIRE(std::isfinite(value));
  } else {
    EVLOC_FUZZ_REQUIRE(response.status() == api::NOT_FOUND);
    EVLOC_FUZZ_REQUIRE(!response.has_world_from_cam());
    EVLOC_FUZZ_REQUIRE(response.covariance_size() == 0);
    EVLOC_FUZZ_REQUIRE(!response.reason().empty());
  }
  return 0;
}

}  // namespace
}  // namespace evloc::service::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return evloc::service::fuzz::Run(data, size);
}
