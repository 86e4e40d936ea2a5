#include "localizer/service/locate_command.h"

#include <cmath>
#include <functional>
#include <iomanip>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/camera/calibration_file.h"
#include "core/common/cli.h"
#include "core/common/error.h"
#include "core/geo/geo_trajectory.h"
#include "core/geo/gnss_prior.h"
#include "localizer/service/locate_rpc.h"
#include "maps/site.h"
#include "maps/tile_cache.h"

namespace evloc::service {

std::string LocateUsage() {
  return R"(Usage: evloc-localizer locate --map MAP --image IMAGE --calib CALIB [options]

Locates one image in a map from nothing (docs/relocalization.md): retrieval of the map's most
similar keyframes, 2D-3D matches, PnP + RANSAC and refinement, then verification against the
map's edges. The map needs relocalization data (map format v2). In a site of tiles, the tiles
that keep keyframes (near the --gnss fix, when given) are searched together.

Options:
  --map MAP       the map: a .evmap file, a folder holding map.evmap, or a site folder
                  (site.manifest) (required)
  --image IMAGE   the query image, any format OpenCV reads (converted to grey) (required)
  --calib CALIB   the camera file, its format detected from the content (docs/camera.md): evloc
                  YAML, Kalibr camchain (CALIB#cam1 picks a camera), ROS camera_info, OpenCV
                  YAML/XML, COLMAP cameras.txt (CALIB#ID), ECD calib.txt; a size the file
                  states must be the image's (required)
  --size WxH      the image size of a file without one (calib.txt; default: the image's size)
  --gnss LAT,LON,ALT,SIGMA[,SIGMA_V]
                  a GNSS fix where the image was taken (WGS84 degrees, metres; one-sigma
                  accuracy, horizontal and optionally vertical): only the keyframes within 3
                  sigma are searched (docs/geo.md); the map or site needs a geo anchor
  --json          print one JSON object: status, world_from_cam [tx ty tz qx qy qz qw] and
                  covariance (36, row-major) when FOUND, inliers, keyframe, tile (a site's tile
                  file), score, reason
  --help          print this help

Exit codes: 0 FOUND, 3 NOT_FOUND, 2 bad command line, 1 any other error.
)";
}

LocateCommand ParseLocateCommandLine(const std::vector<std::string>& arguments) {
  LocateCommand command;
  if (arguments.empty() || arguments[0] != "locate") {
    throw InvalidArgumentError("the first argument must be the command 'locate' (see --help)");
  }
  for (size_t i = 1; i < arguments.size(); ++i) {
    const std::string& flag = arguments[i];
    if (flag == "--help" || flag == "-h") {
      command.help = true;
    } else if (flag == "--json") {
      command.json = true;
    } else if (flag == "--map") {
      command.map = TakeFlagValue(arguments, &i);
    } else if (flag == "--image") {
      command.image = TakeFlagValue(arguments, &i);
    } else if (flag == "--calib") {
      command.calib = TakeFlagValue(arguments, &i);
    } else if (flag == "--size") {
      ParseSizeFlag(flag, TakeFlagValue(arguments, &i), &command.width, &command.height);
    } else if (flag == "--gnss") {
      command.gnss = ParseGnssPrior(flag, TakeFlagValue(arguments, &i));
    } else {
      throw InvalidArgumentError("unknown flag '" + flag + "' (see --help)");
    }
  }
  if (command.help) return command;
  for (const auto& [flag, value] :
       {std::pair{"--map", &command.map}, std::pair{"--image", &command.image},
        std::pair{"--calib", &command.calib}}) {
    if (value->empty()) throw InvalidArgumentError(std::string(flag) + " is required");
  }
  return command;
}

Camera ReadLocateCalibration(const LocateCommand& command, int image_width, int image_height) {
  const int width = command.width > 0 ? command.width : image_width;
  const int height = command.height > 0 ? command.height : image_height;
  const Calibration calibration = ReadCalibration(command.calib, width, height);
  // On stderr: standard output holds the result (JSON with --json).
  for (const std::string& note : CalibrationNotes(command.calib, calibration)) {
    std::cerr << "evloc-localizer locate: note: " << note << "\n";
  }
  const Camera& camera = calibration.selected.camera;
  if (calibration.size_from_file &&
      (camera.width != image_width || camera.height != image_height)) {
    throw InvalidArgumentError("the camera of '" + command.calib.string() + "' is " +
                               std::to_string(camera.width) + "x" + std::to_string(camera.height) +
                               ", the image " + std::to_string(image_width) + "x" +
                               std::to_string(image_height));
  }
  return camera;
}

std::string LocateResultJson(const relocalization::LocateResult& result, const std::string& tile) {
  nlohmann::ordered_json json;
  json["status"] = relocalization::LocateStatusName(result.status);
  if (result.status == relocalization::LocateStatus::kFound) {
    const Eigen::Vector3d& t = result.world_from_cam.translation;
    const Eigen::Quaterniond& q = result.world_from_cam.rotation;
    json["world_from_cam"] = {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()};
    std::vector<double> covariance;
    for (int r = 0; r < 6; ++r) {
      for (int c = 0; c < 6; ++c) covariance.push_back(result.covariance(r, c));
    }
    json["covariance"] = covariance;
  }
  json["inliers"] = result.inliers;
  json["keyframe"] = result.keyframe;
  if (!tile.empty()) json["tile"] = tile;
  json["score"] = result.score;
  json["reason"] = result.reason;
  return json.dump();
}

namespace {

// Locates the command's image in a map or site: given the camera, the image and the options
// (with the --gnss prior), returns the result and sets the tile file name for a site.
using Locator = std::function<relocalization::LocateResult(
    const Camera&, const cv::Mat&, const relocalization::LocateOptions&, std::string* tile)>;

// Reads the image and the camera, turns --gnss into a search prior through `anchor`, locates with
// `locate` and prints the result; the exit code.
int LocateAndReport(const LocateCommand& command, const std::optional<GeoAnchor>& anchor,
                    const Locator& locate, std::ostream& out) {
  const cv::Mat gray = cv::imread(command.image.string(), cv::IMREAD_GRAYSCALE);
  if (gray.empty()) {
    throw IoError("cannot read the image '" + command.image.string() +
                  "' (missing, or not an image OpenCV reads)");
  }
  const Camera camera = ReadLocateCalibration(command, gray.cols, gray.rows);
  relocalization::LocateOptions options;
  if (command.gnss) {
    if (!anchor) {
      throw InvalidArgumentError("--gnss: " + MissingGeoAnchorMessage(command.map.string()));
    }
    options = NearGnssFix(options, *command.gnss, *anchor);
  }
  std::string tile;
  const relocalization::LocateResult result = locate(camera, gray, options, &tile);
  const bool found = result.status == relocalization::LocateStatus::kFound;
  if (command.json) {
    out << LocateResultJson(result, tile) << "\n";
  } else {
    out << relocalization::LocateStatusName(result.status) << "\n";
    if (found) {
      const Eigen::Vector3d& t = result.world_from_cam.translation;
      const Eigen::Quaterniond& q = result.world_from_cam.rotation;
      out << std::setprecision(9) << "world_from_cam: t = (" << t.x() << ", " << t.y() << ", "
          << t.z() << ") m, q = (" << q.x() << ", " << q.y() << ", " << q.z() << ", " << q.w()
          << ") (x, y, z, w)\n"
          << std::setprecision(3) << "translation sigma: "
          << std::sqrt(result.covariance.topLeftCorner<3, 3>().trace()) * 1000 << " mm\n";
    }
    out << std::setprecision(6) << "inliers: " << result.inliers
        << ", keyframe: " << result.keyframe << (tile.empty() ? "" : " of tile " + tile)
        << ", score: " << result.score << "\n"
        << "reason: " << result.reason << "\n";
  }
  return found ? kExitSuccess : kExitNotFound;
}

}  // namespace

int RunLocate(const LocateCommand& command, const Map& map, std::ostream& out) {
  return LocateAndReport(
      command, map.geo_anchor,
      [&](const Camera& camera, const cv::Mat& gray, const relocalization::LocateOptions& options,
          std::string*) { return relocalization::LocateImage(map, camera, gray, options); },
      out);
}

int RunLocate(const LocateCommand& command, std::ostream& out) {
  if (!IsSiteDirectory(command.map)) {
    const std::filesystem::path path =
        std::filesystem::is_directory(command.map) ? command.map / "map.evmap" : command.map;
    return RunLocate(command, LoadMap(path), out);
  }
  const std::shared_ptr<const Site> site = OpenSite(command.map);
  return LocateAndReport(
      command, SiteGeoAnchor(site->manifest),
      [&](const Camera& camera, const cv::Mat& gray, const relocalization::LocateOptions& options,
          std::string* tile) {
        const relocalization::LocateResult result = relocalization::LocateImageInSite(
            site, std::make_shared<TileCache>(), camera, gray, options);
        if (result.tile >= 0) {
          *tile = site->manifest.tiles[static_cast<size_t>(result.tile)].file_name;
        }
        return result;
      },
      out);
}

int RunLocateTool(int argc, const char* const* argv) {
  return RunCommandTool("evloc-localizer locate", argc, argv, ParseLocateCommandLine, LocateUsage,
                        [](const LocateCommand& command) { return RunLocate(command, std::cout); });
}

}  // namespace evloc::service
