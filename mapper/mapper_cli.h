// The `evloc-mapper` command line: a dispatcher over subcommands (import-pcd, info). Kept out of
// main() so that tests run it in-process. Every subcommand has --help.
#pragma once

#include <functional>
#include <ostream>
#include <string>
#include <vector>

namespace evloc {

// One subcommand of evloc-mapper.
struct MapperSubcommand {
  // Name on the command line, e.g. "info".
  std::string name;
  // One-line summary for the top-level --help.
  std::string summary;
  // Runs the subcommand on its arguments (after the name); `command_line` is the whole command
  // line for provenance. Returns the process exit code; writes results to `out`, errors to `err`.
  std::function<int(const std::vector<std::string>& arguments, const std::string& command_line,
                    std::ostream& out, std::ostream& err)>
      run;
};

// The subcommands, in the order of the help text.
const std::vector<MapperSubcommand>& MapperSubcommands();

// Runs evloc-mapper with argv; returns the exit code: 0 success, 1 failure (bad input, I/O), 2
// usage error. Never throws.
int RunMapperCli(int argc, const char* const* argv, std::ostream& out, std::ostream& err);

// `evloc-mapper import-pcd FILE.pcd --out MAPDIR [--force] [--min-gradient-offset M]`.
int RunImportPcdCommand(const std::vector<std::string>& arguments, const std::string& command_line,
                        std::ostream& out, std::ostream& err);

// `evloc-mapper upgrade --map MAP --images DIR [--out OUT] [--force] [--threads N]`: adds the
// relocalization data of format v2 to a map (in place, keeping MAP.v1.bak, or into OUT).
int RunUpgradeCommand(const std::vector<std::string>& arguments, const std::string& command_line,
                      std::ostream& out, std::ostream& err);

// `evloc-mapper tile --map MAP --out SITE [...]`: splits a map into a site of tiles (maps/site.h).
int RunTileCommand(const std::vector<std::string>& arguments, const std::string& command_line,
                   std::ostream& out, std::ostream& err);
// `evloc-mapper georef --map MAP (--geo-anchor ... | --geo-points FILE | --geo-exif --images DIR)
// [--out OUT] [--force]`: adds or replaces a map's geo anchor (docs/geo.md).
int RunGeorefCommand(const std::vector<std::string>& arguments, const std::string& command_line,
                     std::ostream& out, std::ostream& err);

// `evloc-mapper info MAP` (a map directory or a .evmap file).
int RunInfoCommand(const std::vector<std::string>& arguments, const std::string& command_line,
                   std::ostream& out, std::ostream& err);

}  // namespace evloc
