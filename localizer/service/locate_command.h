// `evloc-localizer locate` (docs/api.md): locates one image in a map from nothing with the same
// library function as the service's Locate RPC (localizer/relocalization/image_locator.h), and
// prints the result as a readable summary or one JSON object. Exit codes: 0 FOUND, 3 NOT_FOUND,
// 2 a bad command line, 1 any other error.
#pragma once

#include <filesystem>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/camera/camera.h"
#include "localizer/relocalization/image_locator.h"
#include "localizer/service/session.h"
#include "maps/map.h"

namespace evloc::service {

// Exit code of `locate` when the image was not found (FOUND exits with kExitSuccess).
inline constexpr int kExitNotFound = 3;

// What the `locate` command line asks for.
struct LocateCommand {
  // Print the usage and exit.
  bool help = false;
  // The map: a .evmap file, or a folder holding map.evmap.
  std::filesystem::path map;
  // The query image (any format OpenCV reads; converted to grey).
  std::filesystem::path image;
  // The calibration: an evloc camera YAML (.yaml, .yml) or an ECD calib.txt.
  std::filesystem::path calib;
  // Image size of an ECD calib.txt, which has none (0: the image's size).
  int width = 0;
  // Height that goes with width.
  int height = 0;
  // Print one JSON object instead of the summary.
  bool json = false;
  // A GNSS fix where the image was taken (--gnss): only keyframes (and in a site, tiles) near it
  // are searched. Needs a map or site with a geo anchor.
  std::optional<GnssPrior> gnss;
};

// The usage text of `evloc-localizer locate`.
std::string LocateUsage();

// Parses the arguments after the program name (the first must be `locate`). Throws
// InvalidArgumentError naming the flag for an unknown flag, a missing or bad value, or a missing
// required flag.
LocateCommand ParseLocateCommandLine(const std::vector<std::string>& arguments);

// The camera of `calib` for an image of `image_width` x `image_height`: a YAML camera (its size
// must be the image's), or an ECD calib.txt with the command's size or else the image's. Throws
// IoError, ParseError or InvalidArgumentError.
Camera ReadLocateCalibration(const LocateCommand& command, int image_width, int image_height);

// The result as the one JSON object of docs/api.md (world_from_cam and covariance only when
// FOUND; tile, a site's tile file name, only when not empty), without a trailing newline.
std::string LocateResultJson(const relocalization::LocateResult& result,
                             const std::string& tile = "");

// Locates the command's image in `map` (near the --gnss fix, through the map's anchor) and
// prints the result on `out`; returns kExitSuccess when FOUND and kExitNotFound when not. Throws
// like LocateImage, IoError when the image cannot be read, and InvalidArgumentError for --gnss on
// a map without a geo anchor.
int RunLocate(const LocateCommand& command, const Map& map, std::ostream& out);

// Loads the command's map, then RunLocate; or, when --map is a site folder, locates in the site
// (LocateImageInSite, its tiles loaded by this call).
int RunLocate(const LocateCommand& command, std::ostream& out);

// The main() of `evloc-localizer locate ...` (argv[1] is "locate"): RunCommandTool over the
// parser and RunLocate, the result on std::cout.
int RunLocateTool(int argc, const char* const* argv);

}  // namespace evloc::service
