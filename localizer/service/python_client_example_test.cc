// Runs the Python examples (examples/python/localizer_client.py, locate_client.py) with
// /usr/bin/python3 and the evloc package (python/, built here into a temporary folder by its
// setup.py: the module of this build and stubs generated from proto/) against a real server on
// loopback (skipped, with the reason, when Python lacks grpcio, protobuf or numpy, or when the
// package cannot be built: no pybind11 module or stub generator; the Locate example also needs
// the shared data's temple photos).
#include <gtest/gtest.h>

#include <fstream>

#include <nlohmann/json.hpp>

#include <opencv2/imgcodecs.hpp>

#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "localizer/relocalization/testing/temple_map.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"

namespace evloc::service {
namespace {

constexpr char kPython[] = "/usr/bin/python3";

// The reason the Python examples cannot run here, or "" when they can: Python without grpcio,
// protobuf or numpy, or a build without the package's module (no pybind11-dev).
std::string MissingPython() {
  std::string output;
  if (::evloc::testing::RunShellCommand(
          std::string(kPython) + " -c 'import grpc, google.protobuf, numpy' 2>&1", &output) != 0) {
    return std::string(kPython) + " lacks grpcio, protobuf or numpy (Debian: python3-grpcio " +
           "python3-protobuf python3-numpy): " + output;
  }
  if (::evloc::testing::RunShellCommand("ls '" EVLOC_BUILD_DIR "'/python/_evloc*.so 2>&1",
                                        &output) != 0) {
    return "this build has no evloc Python module (build/python/_evloc*.so; needs pybind11-dev "
           "and python3-dev, scripts/install-deps.sh)";
  }
  return "";
}

// The start of a command line running an example with the evloc package, built (once per test
// program) into a temporary folder by the package's setup.py; a failure to build it fails the
// test.
std::string PythonWithPackage() {
  static const testing::TemporaryFolder folder;  // removed when the program ends
  static const std::string failure = [] {
    const std::string command = "cd python && EVLOC_BUILD_DIR='" EVLOC_BUILD_DIR "' " +
                                std::string(kPython) + " setup.py -q build_py --build-lib '" +
                                folder.path().string() + "' 2>&1";
    std::string output;
    if (::evloc::testing::RunShellCommand(command, &output) == 0) return std::string();
    return "the evloc package cannot be built (" + command + "): " + output;
  }();
  EXPECT_EQ(failure, "");
  return "PYTHONPATH='" + folder.path().string() + "' " + kPython;
}

// The "camera" object of the examples' JSON for a pinhole camera.
nlohmann::json CameraJson(const Camera& camera) {
  EXPECT_EQ(camera.model, CameraModel::kPinhole);
  return {{"model", "pinhole"}, {"width", camera.width}, {"height", camera.height},
          {"fx", camera.fx},    {"fy", camera.fy},       {"cx", camera.cx},
          {"cy", camera.cy}};
}

// Writes the synthetic events over [0, duration_ns] as folder/events.txt, the session JSON
// (with `pose` at kInitialTimeNs, or without a pose) as folder/session.json, runs
// localizer_client.py against `server` on `map_name` and returns its exit status and output.
int RunLocalizerClient(const std::filesystem::path& folder, const LocalizerServer& server,
                       const std::string& map_name, const std::optional<Rigid3d>& pose,
                       int64_t duration_ns, std::string* output) {
  nlohmann::json session = {{"camera", CameraJson(testing::TestCamera())},
                            {"initial_t_ns", testing::kInitialTimeNs}};
  if (pose) {
    session["initial_world_from_cam"] = {
        {"t", {pose->translation.x(), pose->translation.y(), pose->translation.z()}},
        {"q", {pose->rotation.w(), pose->rotation.x(), pose->rotation.y(), pose->rotation.z()}}};
  }
  std::ofstream(folder / "session.json") << session.dump();
  const EventBuffer events = testing::TestEvents(duration_ns);
  {
    std::ofstream text(folder / "events.txt");
    for (size_t i = 0; i < events.size(); ++i) {
      text << events.t_ns[i] << " " << events.x[i] << " " << events.y[i] << " "
           << static_cast<int>(events.polarity[i]) << "\n";
    }
  }
  const std::string command =
      PythonWithPackage() +
      " examples/python/localizer_client.py --server 127.0.0.1:" + std::to_string(server.port()) +
      " --map " + map_name + " --session '" + (folder / "session.json").string() + "' --events '" +
      (folder / "events.txt").string() + "' --rate 200 2>&1";
  return ::evloc::testing::RunShellCommand(command, output);
}

TEST(PythonClientExample, StreamsEventsAndPrintsPoses) {
  if (const std::string missing = MissingPython(); !missing.empty()) GTEST_SKIP() << missing;
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path() / "maps", testing::kTestMapName, testing::TestMap());
  LocalizerServer server(testing::TestServerOptions(folder.path() / "maps"));

  // The session description and 200 ms of synthetic events.
  const EventBuffer events = testing::TestEvents(200'000'000);
  std::string output;
  ASSERT_EQ(RunLocalizerClient(folder.path(), server, testing::kTestMapName,
                               tracking::testing::SmoothMotion(testing::kInitialTimeNs),
                               200'000'000, &output),
            0)
      << output;
  EXPECT_NE(output.find("session 1: map rectangles"), std::string::npos) << output;
  EXPECT_NE(output.find("end: " + std::to_string(events.size()) + " events"), std::string::npos)
      << output;
  // The session starts at 20 ms; at 200 Hz the steps are at 25, 30, ..., 200 ms (the last one
  // once the end of the stream advances the tracker to the last event): 36, all TRACKING.
  EXPECT_NE(output.find("received 36 poses"), std::string::npos) << output;
  EXPECT_EQ(output.find("LOST "), std::string::npos) << output;
  EXPECT_NE(output.find("(0 LOST)"), std::string::npos) << output;
}

// A session JSON without a pose: the service searches (updates without a pose, INITIALIZING),
// then tracks.
TEST(PythonClientExample, StartsWithoutAPoseAndTheServiceFindsTheCamera) {
  if (const std::string missing = MissingPython(); !missing.empty()) GTEST_SKIP() << missing;
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path() / "maps", "beside",
                        testing::TestMapWithKeyframesBesideThePath());
  LocalizerServer server(testing::TestServerOptions(folder.path() / "maps"));
  std::string output;
  ASSERT_EQ(RunLocalizerClient(folder.path(), server, "beside", std::nullopt, 600'000'000, &output),
            0)
      << output;
  EXPECT_NE(output.find("INITIALIZING"), std::string::npos) << output;
  EXPECT_NE(output.find("TRACKING"), std::string::npos) << output;
  EXPECT_NE(output.find("updates without a pose (searching)"), std::string::npos) << output;
}

// locate_client.py: a held-out temple view is FOUND near its calibrated pose and a session JSON
// is written at it; a photo of another scene is NOT_FOUND with exit code 3.
TEST(PythonLocateExample, FindsAHeldOutViewAndNotAnotherScene) {
  if (const std::string missing = MissingPython(); !missing.empty()) GTEST_SKIP() << missing;
  const auto* temple = relocalization::testing::SharedTemple();
  const auto dino = evloc::testing::SharedDataFile("middlebury/dinoSparseRing/dinoSR0001.png");
  if (temple == nullptr || !dino) {
    GTEST_SKIP() << evloc::testing::MissingDataReason(relocalization::testing::kTempleParameters);
  }
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path() / "maps", "temple", temple->map);
  LocalizerServer server(testing::TestServerOptions(folder.path() / "maps"));
  std::ofstream(folder.path() / "camera.json")
      << nlohmann::json{{"camera", CameraJson(temple->temple.camera)}}.dump();
  cv::imwrite((folder.path() / "query.png").string(), temple->temple.images[7]);
  const auto locate = [&](const std::filesystem::path& image, std::string* output) {
    return ::evloc::testing::RunShellCommand(
        PythonWithPackage() + " examples/python/locate_client.py --server 127.0.0.1:" +
            std::to_string(server.port()) + " --map temple --image '" + image.string() +
            "' --camera '" + (folder.path() / "camera.json").string() + "' --write-session '" +
            (folder.path() / "session.json").string() + "' 2>&1",
        output);
  };
  std::string output;
  ASSERT_EQ(WEXITSTATUS(locate(folder.path() / "query.png", &output)), 0) << output;
  const nlohmann::json answer = nlohmann::json::parse(output);
  EXPECT_EQ(answer["status"], "FOUND");
  const Rigid3d truth = temple->temple.views[7].cam_from_world.Inverse();
  const std::vector<double> pose = answer["world_from_cam"];
  ASSERT_EQ(pose.size(), 7u);
  EXPECT_LT((Eigen::Vector3d(pose[0], pose[1], pose[2]) - truth.translation).norm(), 0.02);
  EXPECT_EQ(answer["covariance"].size(), 36u);
  const nlohmann::json session =
      nlohmann::json::parse(ReadFileToString(folder.path() / "session.json"));
  EXPECT_EQ(session["initial_world_from_cam"]["t"][0], pose[0]);
  EXPECT_EQ(session["initial_world_from_cam"]["q"][0], pose[6]) << "qw first";

  output.clear();
  std::filesystem::remove(folder.path() / "session.json");
  ASSERT_EQ(WEXITSTATUS(locate(*dino, &output)), 3) << output;
  EXPECT_EQ(nlohmann::json::parse(output)["status"], "NOT_FOUND") << output;
  EXPECT_FALSE(std::filesystem::exists(folder.path() / "session.json"));
}

}  // namespace
}  // namespace evloc::service
