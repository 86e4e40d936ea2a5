// The live viewer in a real browser (issue 19): headless Chromium, driven by Selenium
// (testing/viewer_browser_check.py), loads the page of a running server with two live sessions,
// checks the DOM (sessions listed, statuses, poses updating, the map's points, a time surface)
// and saves a screenshot, which this test inspects: the 3D view is not empty and the map's
// points are drawn in it. The screenshot is kept as viewer_browser.png in the test's build
// folder (docs/viewer.md shows one).
#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"

namespace evloc::service {
namespace {

// Runs `command` and returns its exit status and its standard output.
std::pair<int, std::string> RunCommand(const std::string& command) {
  std::string output;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return {-1, ""};
  char buffer[4096];
  while (size_t count = std::fread(buffer, 1, sizeof(buffer), pipe)) output.append(buffer, count);
  const int status = ::pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

TEST(ViewerBrowserTest, TwoLiveSessionsInHeadlessChromium) {
  for (const char* program : {"/usr/bin/chromium", "/usr/bin/chromedriver", "/usr/bin/python3"}) {
    if (!std::filesystem::exists(program)) {
      GTEST_SKIP() << program << " is missing: run scripts/install-deps.sh (chromium, "
                   << "chromium-driver, python3-selenium)";
    }
  }
  if (RunCommand("/usr/bin/python3 -c 'import selenium' 2>&1").first != 0) {
    GTEST_SKIP() << "python3-selenium is missing: run scripts/install-deps.sh";
  }
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path() / "maps", testing::kTestMapName, testing::TestMap());
  LocalizerServerOptions options = testing::TestServerOptions(folder.path() / "maps");
  options.viewer_address = "127.0.0.1:0";
  LocalizerServer server(options);

  // Two clients streaming sessions of 2 s of events, played at a tenth of real time (20 s each),
  // a new session after each one ends, so that two sessions are live whenever the browser
  // looks, however long a loaded machine takes to start it.
  std::atomic<bool> stop{false};
  const EventBuffer events = testing::TestEvents(2'000'000'000);
  std::vector<std::thread> sessions;
  for (const char* name : {"camera-left", "camera-right"}) {
    sessions.emplace_back([&, name] {
      while (!stop) {
        testing::StreamPacedSession(server.port(), events, 10'000'000,
                                    std::chrono::milliseconds(100), stop, name);
      }
    });
  }

  const std::filesystem::path screenshot = EVLOC_VIEWER_SCREENSHOT;
  std::filesystem::remove(screenshot);
  const std::string url = "http://127.0.0.1:" + std::to_string(server.viewer_port()) + "/";
  const auto [status, output] = RunCommand("/usr/bin/python3 " EVLOC_VIEWER_BROWSER_CHECK " '" +
                                           url + "' '" + screenshot.string() + "' 2");
  stop = true;
  for (std::thread& session : sessions) session.join();
  std::printf("browser check: %s\nscreenshot: %s\n", output.c_str(), screenshot.c_str());
  ASSERT_EQ(status, 0) << "the browser check failed (its reason is on stderr above): " << output;

  // The screenshot: the 3D view (right of the 380 px side panel) shows the map's points,
  // coloured by depth (saturated colours), on the dark background.
  const cv::Mat picture = cv::imread(screenshot.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(picture.empty()) << screenshot;
  ASSERT_GT(picture.cols, 500);
  const cv::Mat view = picture(cv::Rect(400, 0, picture.cols - 400, picture.rows));
  int background = 0;
  int coloured = 0;
  for (int y = 0; y < view.rows; ++y) {
    for (int x = 0; x < view.cols; ++x) {
      const cv::Vec3b pixel = view.at<cv::Vec3b>(y, x);  // BGR
      const int high = std::max({pixel[0], pixel[1], pixel[2]});
      const int low = std::min({pixel[0], pixel[1], pixel[2]});
      if (std::abs(pixel[0] - 0x18) + std::abs(pixel[1] - 0x14) + std::abs(pixel[2] - 0x10) < 12) {
        ++background;
      } else if (high - low > 80) {
        ++coloured;
      }
    }
  }
  const int total = view.rows * view.cols;
  std::printf("3D view: %d px, background %d, coloured %d\n", total, background, coloured);
  EXPECT_GT(background, total / 4) << "the view is not the page's dark background";
  EXPECT_GT(coloured, 2000) << "too few coloured pixels: the map's points are not drawn";
}

}  // namespace
}  // namespace evloc::service
