// `evloc-mapper build`: the command line of the offline mapper (docs/mapper.md, "CLI").
#pragma once

#include <string>
#include <vector>

#include "mapper/chunked_build.h"
#include "mapper/map_builder.h"

namespace evloc::mapper {

// The result of parsing the flags of `evloc-mapper build`.
struct BuildCommandLine {
  // The pipeline options the flags map to.
  MapBuilderOptions options;
  // --quiet: no progress output.
  bool quiet = false;
  // --help: print the usage and exit 0.
  bool help = false;
  // --chunked (or more photos than chunked_above): the chunked build into a site
  // (mapper/chunked_build.h); chunked.build is `options` then.
  bool chunked = false;
  // The chunked build's own options (chunk size and overlap, workers, memory budget, chunk
  // workspace, --chunk-index, --merge-only, tiles).
  ChunkedBuildOptions chunked_options;
  // The arguments after `build` as given, for the worker processes.
  std::vector<std::string> arguments;
};

// A build of more photos than this is chunked without --chunked.
inline constexpr size_t kChunkedBuildAbovePhotos = 1000;

// Parses the flags after `build` (argv[0] is the program or subcommand name and is skipped).
// Throws InvalidArgumentError naming the flag for an unknown flag, a missing or malformed value.
BuildCommandLine ParseBuildCommandLine(const std::vector<std::string>& arguments);

// Parses a --camera value `MODEL:p1,p2,...`: `pinhole:fx,fy,cx,cy`,
// `radtan:fx,fy,cx,cy,k1,k2,p1,p2,k3` or `equidistant:fx,fy,cx,cy,k1,k2,k3,k4` (evloc pixel
// convention: top-left pixel centre at 0, 0). The size comes from the images, so the returned
// camera has width and height 0 until `width` and `height` are set. Throws InvalidArgumentError.
Camera ParseCameraFlag(const std::string& value, int width, int height);

// The usage text of `evloc-mapper build`.
std::string BuildCommandUsage();

// Runs `evloc-mapper build` with argv as given to the subcommand (argv[0] = "build" or the
// program name). Prints progress to stderr (unless --quiet) and a summary to stdout. Returns 0 on
// success, 2 for a bad command line, 1 when the build fails (the message is printed to stderr).
int RunBuildCommand(int argc, char** argv);

}  // namespace evloc::mapper
