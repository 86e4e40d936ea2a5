// libFuzzer target: the live viewer's HTTP request handling (docs/viewer.md, docs/reliability.md
// §4): the input is a raw HTTP request (request line, headers, body) run through httplib's
// parser and the viewer's routes by HttpServer::HandleRawRequest, as a connection would, over a
// map folder with the service's test map and a board with one session that has a pose; the
// event stream ends after its first event. Seeds: evloc_session_fuzz_seeds OUT_DIR/viewer.
// Oracles (abort): no exception escapes; the answer is an HTTP/1.1 response whose status is
// neither 5xx from a route's exception (500) nor outside 200..599, except the 503 of a surface
// that did not come (no worker renders it here).
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>

#include "localizer/service/fuzz/session_fuzz_common.h"
#include "localizer/service/map_registry.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/service/viewer_board.h"
#include "localizer/service/viewer_http.h"

namespace evloc::service::fuzz {
namespace {

// The viewer under test, made once.
struct Viewer {
  Viewer() {
    testing::WriteTestMap(folder.path() / "maps", testing::kTestMapName, testing::TestMap());
    MapRegistryOptions options;
    options.maps_dir = folder.path() / "maps";
    registry = std::make_unique<MapRegistry>(options);
    session = board.Open(1, testing::kTestMapName, "fuzz");
    session->Publish({5, Rigid3d(), tracking::TrackingStatus::kTracking});
    ViewerOptions viewer_options;
    viewer_options.address = "127.0.0.1:0";
    viewer_options.surface_timeout_s = 0.001;
    viewer = std::make_unique<ViewerServer>(viewer_options, board, *registry, nullptr);
  }
  testing::TemporaryFolder folder;
  std::unique_ptr<MapRegistry> registry;
  ViewerBoard board;
  std::shared_ptr<ViewerSession> session;
  std::unique_ptr<ViewerServer> viewer;
};

int Run(const uint8_t* data, size_t size) {
  static Viewer* viewer = new Viewer();  // Never destroyed: libFuzzer exits without unwinding.
  const std::string request(reinterpret_cast<const char*>(data), size);
  const std::string response = viewer->viewer->http().HandleRawRequest(request);
  if (response.empty()) return 0;  // httplib drops a request it cannot read at all.
  EVLOC_FUZZ_REQUIRE(response.rfind("HTTP/1.1 ", 0) == 0);
  const int status = std::atoi(response.c_str() + 9);
  EVLOC_FUZZ_REQUIRE(status >= 200 && status <= 599);
  EVLOC_FUZZ_REQUIRE(status != 500);
  return 0;
}

}  // namespace
}  // namespace evloc::service::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return evloc::service::fuzz::Run(data, size);
}
