// The Locate RPC: its request handling on the in-memory temple map (FOUND for a held-out view as
// PNG and as raw pixels, NOT_FOUND for another scene as a result, bad images and cameras), and
// through a running server (map without relocalization data, unknown map, the server serving on).
#include "localizer/service/locate_rpc.h"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "localizer/relocalization/testing/temple_map.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/session.h"
#include "localizer/service/testing/service_fixture.h"
#include "maps/site.h"
#include "maps/tile_cache.h"
#include "proto/convert/proto_convert.h"

namespace evloc::service {
namespace {

using relocalization::testing::SharedTemple;

#define REQUIRE_TEMPLE()         \
  if (SharedTemple() == nullptr) \
  GTEST_SKIP() << evloc::testing::MissingDataReason(relocalization::testing::kTempleParameters)

// The temple map as the registry would hold it.
const LoadedMap& TempleLoadedMap() {
  static const LoadedMap* loaded = [] {
    auto* map = new LoadedMap;
    map->name = "temple";
    map->map = SharedTemple()->map;
    map->content_crc32c = ComputeMapContentChecksum(map->map);
    map->version = MapVersionString(map->content_crc32c);
    map->info = SummarizeMap(map->map);
    map->visibility = std::make_unique<VisibilityIndex>(map->map);
    return map;
  }();
  return *loaded;
}

// A request for `image` (grey) with the temple camera: PNG bytes or raw pixels.
api::LocateRequest Request(const cv::Mat& image, bool encoded) {
  api::LocateRequest request;
  request.set_map_name("temple");
  *request.mutable_camera() = CameraToProto(SharedTemple()->temple.camera);
  if (encoded) {
    std::vector<uint8_t> png;
    cv::imencode(".png", image, png);
    request.set_encoded(std::string(png.begin(), png.end()));
  } else {
    request.mutable_gray()->set_width(image.cols);
    request.mutable_gray()->set_height(image.rows);
    request.mutable_gray()->set_pixels(std::string(image.datastart, image.dataend));
  }
  return request;
}

constexpr int64_t kMaxPixels = int64_t{1} << 22;

TEST(LocateRpc, HeldOutTempleViewIsFoundAsPngAndAsRawPixels) {
  REQUIRE_TEMPLE();
  const auto& fixture = *SharedTemple();
  const Rigid3d truth = fixture.temple.views[7].cam_from_world.Inverse();
  for (const bool encoded : {true, false}) {
    api::LocateResponse response;
    const grpc::Status status =
        LocateInLoadedMap(Request(fixture.temple.images[7], encoded), TempleLoadedMap(), kMaxPixels,
                          relocalization::LocateOptions(), &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(response.status(), api::FOUND) << response.reason();
    const Rigid3d pose = RigidFromProto(response.world_from_cam(), "pose");
    // Measured: 0.6 mm (templeSR0008), the same as LocateImage.
    EXPECT_LT((pose.translation - truth.translation).norm(), 0.02);
    EXPECT_EQ(response.covariance_size(), 36);
    EXPECT_GE(response.inliers(), 20u);
    EXPECT_GE(response.score(), 0.2);
    EXPECT_EQ(response.map().version(), TempleLoadedMap().version);
    EXPECT_GT(response.locate_ms(), 0);
  }
}

TEST(LocateRpc, AnotherSceneIsANotFoundResultNotAnError) {
  REQUIRE_TEMPLE();
  const auto dino = evloc::testing::SharedDataFile("middlebury/dinoSparseRing/dinoSR0005.png");
  if (!dino) GTEST_SKIP() << evloc::testing::MissingDataReason("middlebury/dinoSparseRing");
  api::LocateResponse response;
  const grpc::Status status =
      LocateInLoadedMap(Request(cv::imread(dino->string(), cv::IMREAD_GRAYSCALE), true),
                        TempleLoadedMap(), kMaxPixels, relocalization::LocateOptions(), &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(response.status(), api::NOT_FOUND);
  EXPECT_FALSE(response.has_world_from_cam());
  EXPECT_EQ(response.covariance_size(), 0);
  EXPECT_FALSE(response.reason().empty());
}

TEST(LocateRpc, BadImagesAndCamerasAreInvalidArguments) {
  REQUIRE_TEMPLE();
  const cv::Mat& image = SharedTemple()->temple.images[7];
  const auto code = [](const api::LocateRequest& request, int64_t max_pixels = kMaxPixels) {
    api::LocateResponse response;
    const grpc::Status status = LocateInLoadedMap(request, TempleLoadedMap(), max_pixels,
                                                  relocalization::LocateOptions(), &response);
    return status.error_code();
  };
  api::LocateRequest request = Request(image, true);
  request.set_encoded("not an image at all");
  EXPECT_EQ(code(request), grpc::StatusCode::INVALID_ARGUMENT);
  // A PNG header that declares the camera's size over garbage.
  request = Request(image, true);
  request.set_encoded(request.encoded().substr(0, 64));
  EXPECT_EQ(code(request), grpc::StatusCode::INVALID_ARGUMENT);
  // Another size.
  cv::Mat small;
  cv::resize(image, small, cv::Size(320, 240));
  EXPECT_EQ(code(Request(small, true)), grpc::StatusCode::INVALID_ARGUMENT);
  request = Request(image, false);
  request.mutable_gray()->mutable_pixels()->pop_back();
  EXPECT_EQ(code(request), grpc::StatusCode::INVALID_ARGUMENT);
  request = Request(image, false);
  request.clear_gray();
  EXPECT_EQ(code(request), grpc::StatusCode::INVALID_ARGUMENT);
  request = Request(image, false);
  request.clear_camera();
  EXPECT_EQ(code(request), grpc::StatusCode::INVALID_ARGUMENT);
  request = Request(image, false);
  request.mutable_camera()->set_fx(-1);
  EXPECT_EQ(code(request), grpc::StatusCode::INVALID_ARGUMENT);
  // Larger than the server allows.
  EXPECT_EQ(code(Request(image, false), 640 * 480 - 1), grpc::StatusCode::INVALID_ARGUMENT);
}

TEST(LocateRpc, EncodedImageSizesAreReadFromTheHeaders) {
  const cv::Mat image(37, 53, CV_8UC1, cv::Scalar(7));
  for (const char* extension : {".png", ".jpg"}) {
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(cv::imencode(extension, image, bytes));
    const auto size = ReadEncodedImageSize(std::string(bytes.begin(), bytes.end()));
    ASSERT_TRUE(size.has_value()) << extension;
    EXPECT_EQ(size->width, 53) << extension;
    EXPECT_EQ(size->height, 37) << extension;
  }
  EXPECT_FALSE(ReadEncodedImageSize("").has_value());
  EXPECT_FALSE(ReadEncodedImageSize(std::string("\xff\xd8\xff\xd9", 4)).has_value());
  EXPECT_FALSE(ReadEncodedImageSize("GIF89a....").has_value());
}

// Through a running server: the rectangle test map (saved, so no relocalization data until map
// format v2 storage lands) gives FAILED_PRECONDITION with the upgrade advice; an unknown map
// NOT_FOUND; a bad image INVALID_ARGUMENT; and the server goes on serving.
TEST(LocateRpc, ServerAnswersWithStatusesAndKeepsServing) {
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), testing::kTestMapName, testing::TestMap());
  LocalizerServer server(testing::TestServerOptions(folder.path()));
  const auto stub = testing::ConnectStub(server.port());
  const Camera camera = testing::TestCamera();
  const auto call = [&](const api::LocateRequest& request, api::LocateResponse* response) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    return stub->Locate(&context, request, response);
  };
  api::LocateRequest request;
  request.set_map_name(testing::kTestMapName);
  *request.mutable_camera() = CameraToProto(camera);
  request.mutable_gray()->set_width(camera.width);
  request.mutable_gray()->set_height(camera.height);
  request.mutable_gray()->set_pixels(std::string(size_t(camera.width) * camera.height, '\0'));
  api::LocateResponse response;
  grpc::Status status = call(request, &response);
  if (LoadMap(folder.path() / testing::kTestMapName / "map.evmap").relocalization) {
    EXPECT_TRUE(status.ok()) << status.error_message();
  } else {
    EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_NE(status.error_message().find("evloc-mapper upgrade --map MAP --images DIR"),
              std::string::npos)
        << status.error_message();
  }
  api::LocateRequest bad = request;
  bad.mutable_gray()->set_width(camera.width + 1);
  EXPECT_EQ(call(bad, &response).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  bad = request;
  bad.set_map_name("nowhere");
  EXPECT_EQ(call(bad, &response).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(server.counters().rejected.load(), status.ok() ? 2 : 3);
  grpc::ClientContext list_context;
  api::ListMapsResponse list;
  EXPECT_TRUE(stub->ListMaps(&list_context, {}, &list).ok());
  EXPECT_EQ(list.maps_size(), 1);
}

}  // namespace
}  // namespace evloc::service

namespace evloc::service {
namespace {

// LocateRequest.gnss_fix (docs/geo.md): on an anchored map the view is found with a fix at its
// true position; a fix 20 m away retrieves nothing (NOT_FOUND, with the reason); a map without an
// anchor answers FAILED_PRECONDITION, and a malformed fix INVALID_ARGUMENT.
TEST(LocateRpc, AGnssFixRestrictsRetrievalOnAnAnchoredMap) {
  REQUIRE_TEMPLE();
  const auto& fixture = *SharedTemple();
  LoadedMap anchored;
  anchored.name = "temple_geo";
  anchored.map = fixture.map;
  GeoAnchor anchor;
  anchor.origin = {46.5191, 6.5668, 372.0};
  anchored.map.geo_anchor = anchor;
  anchored.info = SummarizeMap(anchored.map);
  anchored.visibility = std::make_unique<VisibilityIndex>(anchored.map);
  const GeoReference reference(anchor);
  const Rigid3d truth = fixture.temple.views[7].cam_from_world.Inverse();
  const auto locate = [&](const LoadedMap& map, const Eigen::Vector3d& at, double accuracy,
                          api::LocateResponse* response) {
    api::LocateRequest request = Request(fixture.temple.images[7], true);
    const GeodeticPoint position = reference.GeodeticFromMap(at);
    request.mutable_gnss_fix()->set_latitude_deg(position.latitude_deg);
    request.mutable_gnss_fix()->set_longitude_deg(position.longitude_deg);
    request.mutable_gnss_fix()->set_altitude_m(position.altitude_m);
    request.mutable_gnss_fix()->set_horizontal_accuracy_m(accuracy);
    request.mutable_gnss_fix()->set_vertical_accuracy_m(accuracy);
    return LocateInLoadedMap(request, map, kMaxPixels, relocalization::LocateOptions(), response);
  };
  api::LocateResponse response;
  grpc::Status status = locate(anchored, truth.translation, 0.1, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(response.status(), api::FOUND) << response.reason();
  EXPECT_TRUE(response.map().has_geo_anchor());
  status = locate(anchored, truth.translation + Eigen::Vector3d(20, 0, 0), 0.1, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(response.status(), api::NOT_FOUND);
  EXPECT_NE(response.reason().find("search prior"), std::string::npos) << response.reason();
  status = locate(TempleLoadedMap(), truth.translation, 0.1, &response);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(status.error_message().find("has no geo anchor"), std::string::npos);
  status = locate(anchored, truth.translation, -1.0, &response);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("LocateRequest.gnss_fix.horizontal_accuracy_m"),
            std::string::npos)
      << status.error_message();
}

// Locate on a site (docs/relocalization.md, "Sites"): the z-up temple, anchored, tiled into
// 0.4 m squares and held as the registry holds a site. The view is found with and without a GNSS
// fix, the response names the tile of the keyframe, and a fix 20 m away finds nothing.
TEST(LocateRpc, FindsAViewInASiteOfTilesWithAndWithoutAGnssFix) {
  REQUIRE_TEMPLE();
  const auto& fixture = *SharedTemple();
  const PrivateTempFolder folder("evloc-locate-rpc-site", "a tiled temple map");
  Map map = relocalization::testing::ZUpTempleMap(fixture.map);
  GeoAnchor anchor;
  anchor.origin = {46.5191, 6.5668, 372.0};
  map.geo_anchor = anchor;
  const TilingOptions tiling = relocalization::testing::TempleTiling();
  TileMap(map, folder.path() / "temple_site", tiling);
  LoadedMap site;
  site.name = "temple_site";
  site.site = OpenSite(folder.path() / "temple_site");
  site.tiles = std::make_shared<TileCache>();
  site.info = SummarizeSite(site.site->manifest);
  site.version = site.site->manifest.version;
  site.map.geo_anchor = site.info.geo_anchor;
  ASSERT_TRUE(site.map.geo_anchor.has_value());
  const GeoReference reference(anchor);
  const Rigid3d truth =
      relocalization::testing::kZUpFromTemple * fixture.temple.views[7].cam_from_world.Inverse();
  const auto locate = [&](std::optional<Eigen::Vector3d> at, api::LocateResponse* response) {
    api::LocateRequest request = Request(fixture.temple.images[7], true);
    request.set_map_name("temple_site");
    if (at) {
      const GeodeticPoint position = reference.GeodeticFromMap(*at);
      request.mutable_gnss_fix()->set_latitude_deg(position.latitude_deg);
      request.mutable_gnss_fix()->set_longitude_deg(position.longitude_deg);
      request.mutable_gnss_fix()->set_altitude_m(position.altitude_m);
      request.mutable_gnss_fix()->set_horizontal_accuracy_m(0.2);
      request.mutable_gnss_fix()->set_vertical_accuracy_m(0.2);
    }
    return LocateInLoadedMap(request, site, kMaxPixels, relocalization::LocateOptions(), response);
  };
  for (const bool with_fix : {false, true}) {
    api::LocateResponse response;
    const grpc::Status status =
        locate(with_fix ? std::optional(truth.translation) : std::nullopt, &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    ASSERT_EQ(response.status(), api::FOUND) << response.reason();
    EXPECT_LT(
        (RigidFromProto(response.world_from_cam(), "pose").translation - truth.translation).norm(),
        0.02);
    EXPECT_NE(response.tile(), "");
    EXPECT_NE(response.tile().find(".evmap"), std::string::npos) << response.tile();
    EXPECT_EQ(response.map().version(), site.site->manifest.version);
    EXPECT_TRUE(response.map().has_geo_anchor());
  }
  api::LocateResponse response;
  ASSERT_TRUE(locate(truth.translation + Eigen::Vector3d(20, 0, 0), &response).ok());
  EXPECT_EQ(response.status(), api::NOT_FOUND);
  EXPECT_EQ(response.tile(), "");
  EXPECT_NE(response.reason().find("no keyframe of the site"), std::string::npos)
      << response.reason();
}

}  // namespace
}  // namespace evloc::service
