// `evloc-localizer locate` end to end, in process: the temple map of the even views (built in
// memory with its relocalization data), a held-out odd view FOUND, photos of another scene
// NOT_FOUND with exit 3, bad command lines exit 2.
#include "localizer/service/locate_command.h"

#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/common/cli.h"
#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/geo/geodetic.h"
#include "localizer/relocalization/testing/temple_map.h"
#include "maps/site.h"

namespace evloc::service {
namespace {

namespace fs = std::filesystem;
using relocalization::testing::SharedTemple;

#define REQUIRE_TEMPLE()         \
  if (SharedTemple() == nullptr) \
  GTEST_SKIP() << evloc::testing::MissingDataReason(relocalization::testing::kTempleParameters)

// Runs the tool's main on `arguments` (after the program name); returns the exit code.
int RunTool(std::vector<std::string> arguments) {
  arguments.insert(arguments.begin(), "evloc-localizer");
  std::vector<const char*> argv;
  for (const std::string& argument : arguments) argv.push_back(argument.c_str());
  return RunLocateTool(static_cast<int>(argv.size()), argv.data());
}

// Runs RunLocate on the in-memory map with `arguments`; returns the exit code and the output.
std::pair<int, std::string> Locate(const Map& map, const std::vector<std::string>& arguments) {
  std::ostringstream out;
  const int code = RunLocate(ParseLocateCommandLine(arguments), map, out);
  return {code, out.str()};
}

TEST(LocateCommand, HeldOutTempleViewIsFoundWithEveryCalibrationFormat) {
  REQUIRE_TEMPLE();
  const auto& fixture = *SharedTemple();
  const fs::path directory = evloc::testing::MakeTempDir("locate_command");
  WriteCameraYaml(directory / "camera.yaml", fixture.temple.camera);
  {
    const Camera& camera = fixture.temple.camera;
    std::ofstream calib(directory / "calib.txt");
    calib.precision(17);
    calib << camera.fx << " " << camera.fy << " " << camera.cx << " " << camera.cy
          << " 0 0 0 0 0\n";
    // The same camera in the calibration files of other tools (docs/camera.md): cam1 of a
    // Kalibr rig, a ROS camera_info, an OpenCV FileStorage XML written by cv::FileStorage.
    std::ofstream kalibr(directory / "camchain.yaml");
    kalibr.precision(17);
    for (int i = 0; i < 2; ++i) {
      kalibr << "cam" << i << ":\n  camera_model: pinhole\n  distortion_model: none\n"
             << "  distortion_coeffs: []\n  intrinsics: [" << (i == 0 ? 100.0 : camera.fx) << ", "
             << camera.fy << ", " << camera.cx << ", " << camera.cy << "]\n  resolution: ["
             << camera.width << ", " << camera.height << "]\n";
    }
    std::ofstream ros(directory / "ost.yaml");
    ros.precision(17);
    ros << "image_width: " << camera.width << "\nimage_height: " << camera.height
        << "\ncamera_name: temple\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [" << camera.fx
        << ", 0, " << camera.cx << ", 0, " << camera.fy << ", " << camera.cy
        << ", 0, 0, 1]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n"
        << "  cols: 5\n  data: [0, 0, 0, 0, 0]\n";
    cv::FileStorage opencv((directory / "out_camera_data.xml").string(), cv::FileStorage::WRITE);
    opencv << "image_width" << camera.width << "image_height" << camera.height << "camera_matrix"
           << cv::Mat(cv::Matx33d(camera.CalibrationMatrix().data()).t())
           << "distortion_coefficients" << cv::Mat::zeros(5, 1, CV_64F);
  }
  const auto parameters =
      evloc::testing::SharedDataFile(relocalization::testing::kTempleParameters);
  const fs::path image = parameters->parent_path() / fixture.temple.views[7].name;
  for (const char* calib :
       {"camera.yaml", "calib.txt", "camchain.yaml#cam1", "ost.yaml", "out_camera_data.xml"}) {
    const auto [code, out] =
        Locate(fixture.map, {"locate", "--map", "unused", "--image", image.string(), "--calib",
                             (directory / calib).string(), "--json"});
    EXPECT_EQ(code, kExitSuccess) << out;
    const nlohmann::json json = nlohmann::json::parse(out);
    EXPECT_EQ(json["status"], "FOUND");
    ASSERT_EQ(json["world_from_cam"].size(), 7u);
    EXPECT_EQ(json["covariance"].size(), 36u);
    const Rigid3d truth = fixture.temple.views[7].cam_from_world.Inverse();
    const Eigen::Vector3d t(json["world_from_cam"][0], json["world_from_cam"][1],
                            json["world_from_cam"][2]);
    // Measured: 0.6 mm from the calibrated position (templeSR0008).
    EXPECT_LT((t - truth.translation).norm(), 0.02) << out;
    EXPECT_GE(json["inliers"].get<int>(), 20);
    EXPECT_GE(json["keyframe"].get<int>(), 0);
    EXPECT_GE(json["score"].get<double>(), 0.2);
  }
  // The readable summary.
  const auto [code, out] =
      Locate(fixture.map, {"locate", "--map", "unused", "--image", image.string(), "--calib",
                           (directory / "camera.yaml").string()});
  EXPECT_EQ(code, kExitSuccess);
  EXPECT_EQ(out.rfind("FOUND\nworld_from_cam: t = (", 0), 0u) << out;
  fs::remove_all(directory);
}

TEST(LocateCommand, PhotoOfAnotherSceneIsNotFoundWithExitThree) {
  REQUIRE_TEMPLE();
  const auto& fixture = *SharedTemple();
  const auto dino = evloc::testing::SharedDataFile("middlebury/dinoSparseRing/dinoSR0005.png");
  if (!dino) GTEST_SKIP() << evloc::testing::MissingDataReason("middlebury/dinoSparseRing");
  const fs::path directory = evloc::testing::MakeTempDir("locate_command_other");
  WriteCameraYaml(directory / "camera.yaml", fixture.temple.camera);
  const auto [code, out] =
      Locate(fixture.map, {"locate", "--map", "unused", "--image", dino->string(), "--calib",
                           (directory / "camera.yaml").string(), "--json"});
  EXPECT_EQ(code, kExitNotFound) << out;
  const nlohmann::json json = nlohmann::json::parse(out);
  EXPECT_EQ(json["status"], "NOT_FOUND");
  EXPECT_FALSE(json.contains("world_from_cam"));
  EXPECT_FALSE(json.contains("covariance"));
  EXPECT_FALSE(json["reason"].get<std::string>().empty());
  fs::remove_all(directory);
}

TEST(LocateCommand, BadCommandLinesExitTwoAndOtherErrorsOne) {
  EXPECT_EQ(RunTool({"locate", "--map", "m", "--image", "i.png"}), kExitUsage);  // no --calib
  EXPECT_EQ(RunTool({"locate", "--map", "m", "--image", "i.png", "--calib", "c.yaml", "--bogus"}),
            kExitUsage);
  EXPECT_EQ(RunTool({"locate", "--map", "m", "--image", "i.png", "--calib", "c.txt", "--size",
                     "640by480"}),
            kExitUsage);
  EXPECT_EQ(RunTool({"locate", "--map"}), kExitUsage);
  EXPECT_EQ(RunTool({"locate", "--help"}), kExitSuccess);
  // A missing map is no usage error.
  EXPECT_EQ(RunTool({"locate", "--map", "/nonexistent/map.evmap", "--image", "i.png", "--calib",
                     "c.yaml"}),
            kExitFailure);
  EXPECT_THROW(ParseLocateCommandLine({"serve"}), InvalidArgumentError);
}

// A map file without relocalization data (every map SaveMap writes until format v2 storage
// lands): exit 1 with the upgrade advice. With v2 storage the saved map keeps the data and the
// held-out view is FOUND through the file, which this test then checks instead.
TEST(LocateCommand, SavedMapIsLocatedOrSaysHowToUpgrade) {
  REQUIRE_TEMPLE();
  const auto& fixture = *SharedTemple();
  const fs::path directory = evloc::testing::MakeTempDir("locate_command_file");
  SaveMap(directory / "map.evmap", fixture.map);
  WriteCameraYaml(directory / "camera.yaml", fixture.temple.camera);
  const auto parameters =
      evloc::testing::SharedDataFile(relocalization::testing::kTempleParameters);
  const std::vector<std::string> arguments = {
      "locate",
      "--map",
      directory.string(),
      "--image",
      (parameters->parent_path() / fixture.temple.views[7].name).string(),
      "--calib",
      (directory / "camera.yaml").string(),
      "--json"};
  if (LoadMap(directory / "map.evmap").relocalization) {
    EXPECT_EQ(RunTool(arguments), kExitSuccess);
  } else {
    EXPECT_EQ(RunTool(arguments), kExitFailure);
    try {
      RunLocate(ParseLocateCommandLine(arguments), std::cout);
      FAIL() << "no error";
    } catch (const InvalidArgumentError& error) {
      EXPECT_NE(std::string(error.what()).find("evloc-mapper upgrade --map MAP --images DIR"),
                std::string::npos);
    }
  }
  fs::remove_all(directory);
}

// `locate --map SITE`: the z-up temple, anchored and tiled into 0.4 m squares. A held-out view is
// FOUND with a GNSS fix at its position (the JSON names the tile), NOT_FOUND with a fix 20 m away
// (exit 3); --gnss on a site without an anchor and a malformed --gnss are errors.
TEST(LocateCommand, ASiteIsSearchedNearTheGnssFix) {
  REQUIRE_TEMPLE();
  const auto& fixture = *SharedTemple();
  const fs::path directory = evloc::testing::MakeTempDir("locate_command_site");
  WriteCameraYaml(directory / "camera.yaml", fixture.temple.camera);
  Map map = relocalization::testing::ZUpTempleMap(fixture.map);
  const TilingOptions tiling = relocalization::testing::TempleTiling();
  TileMap(map, directory / "plain", tiling);
  GeoAnchor anchor;
  anchor.origin = {46.5191, 6.5668, 372.0};
  map.geo_anchor = anchor;
  TileMap(map, directory / "site", tiling);
  const GeoReference reference(anchor);
  const Rigid3d truth =
      relocalization::testing::kZUpFromTemple * fixture.temple.views[7].cam_from_world.Inverse();
  const auto parameters =
      evloc::testing::SharedDataFile(relocalization::testing::kTempleParameters);
  const auto arguments = [&](const std::string& site, const Eigen::Vector3d& at) {
    const GeodeticPoint fix = reference.GeodeticFromMap(at);
    std::ostringstream gnss;
    gnss.precision(12);
    gnss << fix.latitude_deg << "," << fix.longitude_deg << "," << fix.altitude_m << ",0.2";
    return std::vector<std::string>{
        "locate",
        "--map",
        (directory / site).string(),
        "--image",
        (parameters->parent_path() / fixture.temple.views[7].name).string(),
        "--calib",
        (directory / "camera.yaml").string(),
        "--gnss",
        gnss.str(),
        "--json"};
  };
  std::ostringstream out;
  ASSERT_EQ(RunLocate(ParseLocateCommandLine(arguments("site", truth.translation)), out),
            kExitSuccess)
      << out.str();
  const nlohmann::json found = nlohmann::json::parse(out.str());
  EXPECT_EQ(found["status"], "FOUND");
  ASSERT_TRUE(found.contains("tile")) << out.str();
  EXPECT_NE(found["tile"].get<std::string>().find(".evmap"), std::string::npos);
  const Eigen::Vector3d position(found["world_from_cam"][0], found["world_from_cam"][1],
                                 found["world_from_cam"][2]);
  EXPECT_LT((position - truth.translation).norm(), 0.02);
  std::ostringstream far;
  EXPECT_EQ(RunLocate(ParseLocateCommandLine(
                          arguments("site", truth.translation + Eigen::Vector3d(20, 0, 0))),
                      far),
            kExitNotFound)
      << far.str();
  EXPECT_EQ(RunTool(arguments("plain", truth.translation)), kExitFailure);
  try {
    std::ostringstream ignored;
    RunLocate(ParseLocateCommandLine(arguments("plain", truth.translation)), ignored);
    ADD_FAILURE() << "--gnss on a site without an anchor was accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("has no geo anchor"), std::string::npos)
        << error.what();
  }
  std::vector<std::string> bad = arguments("site", truth.translation);
  bad[8] = "46.5,6.5";
  EXPECT_EQ(RunTool(bad), kExitUsage);
  bad[8] = "46.5,6.5,372,-1";
  EXPECT_EQ(RunTool(bad), kExitUsage);
  fs::remove_all(directory);
}

}  // namespace
}  // namespace evloc::service
