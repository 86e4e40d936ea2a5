#include "localizer/service/viewer_http.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <set>
#include <thread>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/common/error.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/serve_command.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/service/testing/test_pki.h"
#include "localizer/service/viewer_board.h"
#include "maps/site.h"

namespace evloc::service {
namespace {

using nlohmann::json;

// Waits (at most 10 s) until `condition` holds.
bool Eventually(const std::function<bool()>& condition) {
  for (int i = 0; i < 1000; ++i) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return condition();
}

class ViewerTest : public ::testing::Test {
 protected:
  void StartServer(const std::function<void(LocalizerServerOptions&)>& adjust = {}) {
    testing::WriteTestMap(folder_.path() / "maps", testing::kTestMapName, testing::TestMap());
    LocalizerServerOptions options = testing::TestServerOptions(folder_.path() / "maps");
    options.viewer_address = "127.0.0.1:0";
    if (adjust) adjust(options);
    server_ = std::make_unique<LocalizerServer>(options);
    client_ = std::make_unique<httplib::Client>("127.0.0.1", server_->viewer_port());
    client_->set_read_timeout(10, 0);
  }

  // Streams one session in the background: 1 s of events, one 10 ms packet per 50 ms of wall
  // time (5 s), until the test ends.
  void StartSession(const std::string& name) {
    sessions_.emplace_back([this, name] {
      static const EventBuffer events = testing::TestEvents(1'000'000'000);
      testing::StreamPacedSession(server_->port(), events, 10'000'000,
                                  std::chrono::milliseconds(50), stop_, name);
    });
  }

  json GetJson(const std::string& path, const httplib::Headers& headers = {}) {
    const httplib::Result result = client_->Get(path.c_str(), headers);
    EXPECT_TRUE(result) << path;
    if (!result) return json();
    EXPECT_EQ(result->status, 200) << path << ": " << result->body;
    return json::parse(result->body, nullptr, false);
  }

  void TearDown() override {
    stop_ = true;
    for (std::thread& session : sessions_) session.join();
  }

  testing::TemporaryFolder folder_;
  std::unique_ptr<LocalizerServer> server_;
  std::unique_ptr<httplib::Client> client_;
  std::atomic<bool> stop_{false};
  std::vector<std::thread> sessions_;
};

TEST_F(ViewerTest, ServesThePageAndItsScriptsFromTheBinary) {
  StartServer();
  ASSERT_GT(server_->viewer_port(), 0);
  for (const char* path :
       {"/", "/app.js", "/vendor/three.module.min.js", "/vendor/OrbitControls.js"}) {
    const httplib::Result result = client_->Get(path);
    ASSERT_TRUE(result) << path;
    EXPECT_EQ(result->status, 200) << path;
    EXPECT_GT(result->body.size(), 1000u) << path;
  }
  EXPECT_NE(client_->Get("/")->body.find("importmap"), std::string::npos);
  EXPECT_EQ(client_->Get("/")->get_header_value("Content-Type"), "text/html");
  EXPECT_EQ(client_->Get("/vendor/nothing.js")->status, 404);
  EXPECT_EQ(client_->Get("/../etc/passwd")->status, 404);
}

TEST_F(ViewerTest, ServesMapsAndTheirPoints) {
  StartServer();
  const json maps = GetJson("/api/maps");
  ASSERT_EQ(maps["maps"], json::array({testing::kTestMapName}));
  const json map = GetJson(std::string("/api/maps/") + testing::kTestMapName);
  const Map expected = testing::TestMap();
  EXPECT_EQ(map["points"], expected.size());
  EXPECT_EQ(map["site"], false);
  const httplib::Result points =
      client_->Get((std::string("/api/maps/") + testing::kTestMapName + "/points").c_str());
  ASSERT_TRUE(points);
  ASSERT_EQ(points->status, 200);
  ASSERT_EQ(points->body.size(), expected.size() * kViewerFloatsPerPoint * sizeof(float));
  const auto* values = reinterpret_cast<const float*>(points->body.data());
  EXPECT_FLOAT_EQ(values[0], expected.positions[0].x());
  EXPECT_FLOAT_EQ(values[2], expected.positions[0].z());
  EXPECT_FLOAT_EQ(values[6], expected.gradients[0].z());
  // At most `max` points, evenly spread.
  const httplib::Result fewer =
      client_->Get((std::string("/api/maps/") + testing::kTestMapName + "/points?max=10").c_str());
  ASSERT_TRUE(fewer);
  EXPECT_LE(fewer->body.size(), 10 * kViewerFloatsPerPoint * sizeof(float));
  EXPECT_GT(fewer->body.size(), 5 * kViewerFloatsPerPoint * sizeof(float));
  EXPECT_EQ(client_->Get("/api/maps/atlantis")->status, 404);
  EXPECT_EQ(client_->Get("/api/maps/..")->status, 404);
  // "%F6": a byte that is not UTF-8, echoed in the error (found by evloc_viewer_requests_fuzzer:
  // the JSON of the error threw, a 500).
  for (const char* bad : {"?max=0", "?max=nan", "?max=1e300", "?max=12abc", "?max=%F6%F6100"}) {
    EXPECT_EQ(
        client_->Get((std::string("/api/maps/") + testing::kTestMapName + "/points" + bad).c_str())
            ->status,
        400)
        << bad;
  }
}

// A site: its tiles' core squares, no points (the sessions load the tiles they need).
TEST_F(ViewerTest, ShowsTheTilesOfASite) {
  StartServer();
  TilingOptions tiling;
  tiling.tile_size_m = 0.5;
  tiling.overlap_m = 0.1;
  const SiteManifest manifest =
      TileMap(testing::TestMap(), folder_.path() / "maps" / "site", tiling);
  ASSERT_GT(manifest.tiles.size(), 1u);
  EXPECT_EQ(GetJson("/api/maps")["maps"].size(), 2u);
  const json site = GetJson("/api/maps/site");
  EXPECT_EQ(site["site"], true);
  ASSERT_EQ(site["tiles"].size(), manifest.tiles.size());
  EXPECT_EQ(site["tiles"][0]["min"][0], manifest.tiles[0].core.min_x);
  EXPECT_EQ(site["tiles"][0]["max"][1], manifest.tiles[0].core.max_y);
  EXPECT_EQ(site["tiles"][0]["points"], manifest.tiles[0].num_points);
  const httplib::Result points = client_->Get("/api/maps/site/points");
  ASSERT_TRUE(points);
  EXPECT_EQ(points->status, 200);
  EXPECT_TRUE(points->body.empty());
}

TEST_F(ViewerTest, ShowsLiveSessionsTheirTrailsAndTimeSurfaces) {
  StartServer();
  StartSession("alpha");
  StartSession("beta");
  json sessions;
  ASSERT_TRUE(Eventually([&] {
    sessions = GetJson("/api/sessions")["sessions"];
    if (sessions.size() != 2) return false;
    for (const json& session : sessions) {
      if (session["status"] != "TRACKING" || session["trail"].size() < 3) return false;
    }
    return true;
  })) << sessions.dump();
  EXPECT_EQ((std::set<std::string>{sessions[0]["client"], sessions[1]["client"]}),
            (std::set<std::string>{"alpha", "beta"}));
  EXPECT_EQ(sessions[0]["map"], testing::kTestMapName);
  ASSERT_EQ(sessions[0]["position"].size(), 3u);
  ASSERT_EQ(sessions[0]["rotation"].size(), 4u);

  // The time surface with the reprojected map: the camera's size, with green (on-edge) dots.
  const std::string surface_path =
      "/api/sessions/" + std::to_string(sessions[0]["id"].get<uint64_t>()) + "/surface.png";
  const httplib::Result surface = client_->Get(surface_path.c_str());
  ASSERT_TRUE(surface);
  ASSERT_EQ(surface->status, 200) << surface->body;
  EXPECT_EQ(surface->get_header_value("Content-Type"), "image/png");
  const cv::Mat picture = cv::imdecode(
      std::vector<uint8_t>(surface->body.begin(), surface->body.end()), cv::IMREAD_COLOR);
  ASSERT_FALSE(picture.empty());
  EXPECT_EQ(picture.cols, testing::TestCamera().width);
  EXPECT_EQ(picture.rows, testing::TestCamera().height);
  int green = 0;
  int bright = 0;
  for (int y = 0; y < picture.rows; ++y) {
    for (int x = 0; x < picture.cols; ++x) {
      const cv::Vec3b pixel = picture.at<cv::Vec3b>(y, x);
      green += pixel[1] == 220 && pixel[0] == 0 && pixel[2] == 0;
      bright += pixel[0] == pixel[1] && pixel[1] == pixel[2] && pixel[0] > 0;
    }
  }
  EXPECT_GT(green, 50) << "reprojected points on edges";
  EXPECT_GT(bright, 50) << "active time-surface pixels (grey)";
  EXPECT_EQ(client_->Get("/api/sessions/999999/surface.png")->status, 404);

  // The event stream: rate-limited, with the poses moving.
  const auto start = std::chrono::steady_clock::now();
  int events = 0;
  std::map<uint64_t, std::vector<double>> first_x;
  std::map<uint64_t, double> last_x;
  std::string buffer;
  httplib::Client stream("127.0.0.1", server_->viewer_port());
  const httplib::Result ended =
      stream.Get("/api/events?rate=10", [&](const char* data, size_t size) {
        buffer.append(data, size);
        for (size_t end; (end = buffer.find("\n\n")) != std::string::npos;) {
          const std::string block = buffer.substr(0, end);
          buffer.erase(0, end + 2);
          const size_t data_at = block.find("data: ");
          if (data_at == std::string::npos) continue;
          const json event = json::parse(block.substr(data_at + 6));
          EXPECT_EQ(event["ids"].size(), 2u);
          for (const json& session : event["sessions"]) {
            last_x[session["id"]] = session["position"][0];
            first_x[session["id"]].push_back(session["position"][0]);
          }
          ++events;
        }
        return std::chrono::steady_clock::now() - start < std::chrono::milliseconds(1500);
      });
  EXPECT_GE(events, 5) << "the stream is live (about 15 on an idle machine)";
  EXPECT_LE(events, 17) << "10 Hz over 1.5 s";
  ASSERT_EQ(first_x.size(), 2u);
  for (const auto& [id, xs] : first_x) EXPECT_NE(xs.front(), last_x[id]) << "session " << id;
  EXPECT_EQ(client_->Get("/api/events?rate=1000")->status, 400);
}

TEST_F(ViewerTest, TokensGuardTheDataAndShowOnlyTheirMaps) {
  const std::filesystem::path tokens = folder_.path() / "tokens";
  {
    std::ofstream file(tokens);
    file << "all-maps *\nother-map other\n";
  }
  StartServer([&](LocalizerServerOptions& options) { options.auth_tokens_file = tokens; });
  EXPECT_EQ(client_->Get("/")->status, 200) << "the page holds no data";
  EXPECT_EQ(client_->Get("/api/maps")->status, 401);
  EXPECT_EQ(client_->Get("/api/sessions")->status, 401);
  EXPECT_EQ(client_->Get("/api/events")->status, 401);
  const httplib::Headers wrong = {{"Authorization", "Bearer nope"}};
  EXPECT_EQ(client_->Get("/api/maps", wrong)->status, 401);
  const httplib::Headers all = {{"Authorization", "Bearer all-maps"}};
  const httplib::Headers other = {{"Authorization", "Bearer other-map"}};
  EXPECT_EQ(GetJson("/api/maps", all)["maps"].size(), 1u);
  EXPECT_EQ(GetJson("/api/maps", other)["maps"].size(), 0u);
  const std::string map_path = std::string("/api/maps/") + testing::kTestMapName;
  EXPECT_EQ(client_->Get(map_path.c_str(), other)->status, 403);
  EXPECT_EQ(client_->Get((map_path + "/points").c_str(), other)->status, 403);
  EXPECT_EQ(client_->Get(map_path.c_str(), all)->status, 200);
}

TEST_F(ViewerTest, LimitsOpenPages) {
  StartServer([](LocalizerServerOptions& options) { options.viewer_max_clients = 1; });
  std::atomic<bool> first_open{false};
  std::atomic<bool> done{false};
  std::thread page([&] {
    httplib::Client stream("127.0.0.1", server_->viewer_port());
    stream.Get("/api/events?rate=5", [&](const char*, size_t) {
      first_open = true;
      return !done.load();
    });
  });
  ASSERT_TRUE(Eventually([&] { return first_open.load(); }));
  const httplib::Result second = client_->Get("/api/events");
  ASSERT_TRUE(second);
  EXPECT_EQ(second->status, 503);
  EXPECT_NE(second->body.find("--viewer-max-clients"), std::string::npos);
  done = true;
  page.join();
}

// With --tls-cert the viewer serves HTTPS with the API's certificate; with --tls-client-ca a
// browser without a client certificate of that CA gets no answer.
TEST_F(ViewerTest, ServesHttpsWithTheApisCertificateAndChecksClientCertificates) {
  if (!testing::HaveOpenssl()) GTEST_SKIP() << "the openssl command is missing (openssl package)";
  const testing::TestPki pki(folder_.path());
  ASSERT_TRUE(pki.MakeCa("ca") && pki.MakeLeaf("server", "ca") && pki.MakeCa("client-ca") &&
              pki.MakeLeaf("client", "client-ca") && pki.MakeCa("other-ca") &&
              pki.MakeLeaf("other", "other-ca"));
  StartServer([&](LocalizerServerOptions& options) {
    options.tls_cert_file = pki.Cert("server");
    options.tls_key_file = pki.Key("server");
    options.tls_client_ca_file = pki.Cert("client-ca");
  });
  const auto get = [&](const std::string& client) {
    httplib::SSLClient https("127.0.0.1", server_->viewer_port(), pki.Cert(client).string(),
                             pki.Key(client).string());
    https.set_ca_cert_path(pki.Cert("ca").string());
    https.enable_server_certificate_verification(true);
    return https.Get("/api/maps");
  };
  const httplib::Result good = get("client");
  ASSERT_TRUE(good) << httplib::to_string(good.error());
  EXPECT_EQ(good->status, 200);
  EXPECT_NE(good->body.find(testing::kTestMapName), std::string::npos);
  EXPECT_FALSE(get("other")) << "a client certificate of another CA was accepted";
  EXPECT_FALSE(client_->Get("/api/maps")) << "plaintext was answered on the TLS port";
}

TEST(ViewerOptions, TheCommandLineSetsTheViewer) {
  testing::TemporaryFolder folder;
  const ServeCommand command =
      ParseServeCommandLine({"serve", "--maps", folder.path().string(), "--viewer", "8080",
                             "--viewer-max-clients", "3", "--viewer-rate", "12.5"});
  EXPECT_EQ(command.server.viewer_address, "127.0.0.1:8080");
  EXPECT_EQ(command.server.viewer_max_clients, 3);
  EXPECT_EQ(command.server.viewer_rate_hz, 12.5);
  EXPECT_NE(ServeUsage().find("--viewer [IPV4:]PORT"), std::string::npos);
  EXPECT_THROW(ParseServeCommandLine(
                   {"serve", "--maps", folder.path().string(), "--viewer", "10.1.2.3:8080"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", folder.path().string(), "--viewer", "8080",
                                      "--viewer-max-clients", "0"}),
               InvalidArgumentError);
}

TEST(ViewerOptions, RefusesAnOpenNetworkAddress) {
  testing::TemporaryFolder folder;
  LocalizerServerOptions options;
  options.maps_dir = folder.path();
  options.viewer_address = "0.0.0.0:8080";
  try {
    options.Check();
    FAIL() << "an open viewer on 0.0.0.0 was accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("--insecure"), std::string::npos) << error.what();
  }
  options.insecure = true;
  EXPECT_NO_THROW(options.Check());
  options.viewer_address = "127.0.0.1:99999";
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options.viewer_address = "127.0.0.1:0";
  options.viewer_rate_hz = 0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

TEST(ViewerBoard, KeepsTheLatestPoseAndABoundedTrail) {
  ViewerBoard board;
  const auto session = board.Open(7, "map", "client");
  EXPECT_FALSE(session->View(true).latest);
  for (int i = 0; i < 1000; ++i) {
    session->Publish({i, Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(i, 0, 0)),
                      tracking::TrackingStatus::kTracking});
  }
  const ViewerSessionView view = session->View(true);
  EXPECT_EQ(view.poses, 1000u);
  ASSERT_TRUE(view.latest);
  EXPECT_EQ(view.latest->t_ns, 999);
  ASSERT_EQ(view.trail.size(), ViewerSession::kMaxTrail);
  EXPECT_EQ(view.trail.back().x(), 999);
  EXPECT_EQ(view.trail.front().x(), 1000 - static_cast<double>(ViewerSession::kMaxTrail));
  EXPECT_TRUE(session->View(false).trail.empty());
  // A surface request: the worker's picture reaches the waiting viewer; a closed session ends
  // the wait at once.
  std::thread worker([&] {
    while (!session->surface_requested()) std::this_thread::yield();
    session->PublishSurface(cv::Mat(2, 3, CV_8UC3, cv::Scalar(1, 2, 3)));
  });
  const cv::Mat picture = session->RequestSurface(std::chrono::seconds(10));
  worker.join();
  EXPECT_EQ(picture.cols, 3);
  const uint64_t membership = board.membership();
  board.Close(7);
  EXPECT_NE(board.membership(), membership);
  EXPECT_TRUE(session->closed());
  EXPECT_TRUE(session->RequestSurface(std::chrono::seconds(10)).empty());
  EXPECT_EQ(board.Find(7), nullptr);
}

}  // namespace
}  // namespace evloc::service
