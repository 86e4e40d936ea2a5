#include "mapper/mapper_cli.h"

#include <filesystem>
#include <iomanip>
#include <optional>
#include <sstream>

#include "core/common/cli.h"
#include "core/common/error.h"
#include "core/common/provenance.h"
#include "mapper/build_command.h"
#include "maps/map.h"
#include "maps/map_directory.h"
#include "maps/pcd_import.h"

namespace evloc {
namespace {

const char kImportPcdHelp[] =
    "usage: evloc-mapper import-pcd FILE.pcd --out MAPDIR [--force] [--min-gradient-offset M]\n"
    "\n"
    "Imports a Canny-EVT semi-dense map (PCD, FIELDS x y z normal_x normal_y normal_z, where\n"
    "normal_* is the end point of the 3D gradient, 2-3 cm from the point, in world coordinates)\n"
    "and writes MAPDIR/map.evmap and MAPDIR/map.ply. The map has no keyframes: the localizer\n"
    "builds a voxel visibility index for it.\n"
    "\n"
    "  --out MAPDIR               output map directory (created if missing)\n"
    "  --force                    replace a map already in MAPDIR\n"
    "  --min-gradient-offset M    drop points whose gradient end point is closer than M metres\n"
    "                             (default 1e-6)\n"
    "  --help                     show this help\n";

const char kInfoHelp[] =
    "usage: evloc-mapper info MAP\n"
    "\n"
    "Verifies and summarises a map: MAP is a map directory (holding map.evmap) or a .evmap file.\n"
    "Prints the format version, checksums, point/keyframe/camera counts, bounding box and\n"
    "provenance. Exits with 1 and a message when the map is missing, truncated or corrupted.\n"
    "\n"
    "  --help   show this help\n";

// The options of `import-pcd`, one field per flag.
struct ImportPcdCommandOptions {
  // Input PCD file.
  std::filesystem::path pcd_path;
  // Output map directory.
  std::filesystem::path output_directory;
  // Replace a map already in the output directory.
  bool force = false;
  // Import options (--min-gradient-offset).
  PcdImportOptions import;

  // Throws UsageError when the input or output is missing or a value is out of its domain.
  void Check() const {
    if (pcd_path.empty()) throw UsageError("import-pcd needs an input FILE.pcd");
    if (output_directory.empty()) throw UsageError("import-pcd needs --out MAPDIR");
    try {
      import.Check();
    } catch (const InvalidArgumentError& error) {
      throw UsageError(error.what());
    }
  }
};

int ImportPcd(const std::vector<std::string>& arguments, const std::string& command_line,
              std::ostream& out) {
  ImportPcdCommandOptions options;
  for (size_t i = 0; i < arguments.size(); ++i) {
    const std::string& argument = arguments[i];
    const auto value = [&]() -> const std::string& { return TakeFlagValue(arguments, &i); };
    if (argument == "--help" || argument == "-h") {
      out << kImportPcdHelp;
      return 0;
    } else if (argument == "--out") {
      options.output_directory = value();
    } else if (argument == "--force") {
      options.force = true;
    } else if (argument == "--min-gradient-offset") {
      options.import.min_gradient_offset_m = ParseDoubleFlag(argument, value());
    } else if (argument.rfind("-", 0) == 0) {
      throw UsageError("unknown option '" + argument + "'");
    } else if (options.pcd_path.empty()) {
      options.pcd_path = argument;
    } else {
      throw UsageError("unexpected argument '" + argument + "' (one input file only)");
    }
  }
  options.Check();
  std::error_code error;
  if (!std::filesystem::is_regular_file(options.pcd_path, error)) {
    throw IoError("input '" + options.pcd_path.string() +
                  "' does not exist or is not a file; pass a Canny-EVT .pcd map");
  }
  if (std::filesystem::exists(options.output_directory / kMapFileName, error) && !options.force) {
    throw InvalidArgumentError("'" + options.output_directory.string() +
                               "' already holds a map; choose another --out or pass --force");
  }
  PcdImport imported = ImportCannyEvtPcd(options.pcd_path, options.import);
  if (imported.map.size() == 0) {
    throw InvalidArgumentError("'" + options.pcd_path.string() +
                               "' has no usable points (all dropped); nothing written");
  }
  MapProvenance& provenance = imported.map.provenance;
  provenance.tool = "evloc-mapper import-pcd";
  provenance.tool_version = ToolVersion();
  provenance.created_utc = UtcNowIso8601();
  provenance.command_line = command_line;
  provenance.inputs = {std::filesystem::absolute(options.pcd_path).lexically_normal().string()};
  MapDirectoryWriteOptions write_options;
  write_options.overwrite = options.force;
  WriteMapDirectory(options.output_directory, imported.map, write_options);

  const PcdImportReport& report = imported.report;
  out << "imported " << report.num_imported << " of " << report.num_points_in_file
      << " points from " << options.pcd_path.string() << "\n";
  if (report.num_dropped_zero_gradient + report.num_dropped_non_finite > 0) {
    out << "dropped " << report.num_dropped_zero_gradient << " with a zero-length gradient and "
        << report.num_dropped_non_finite << " with non-finite values (first, 0-based:";
    for (const size_t index : report.first_dropped_points) out << " " << index;
    out << ")\n";
  }
  out << "median gradient end-point offset: " << std::fixed << std::setprecision(4)
      << report.median_gradient_offset_m << " m\n";
  out << "wrote " << (options.output_directory / kMapFileName).string() << " and "
      << (options.output_directory / kMapPlyFileName).string() << "\n";
  return 0;
}

int Info(const std::vector<std::string>& arguments, std::ostream& out) {
  std::optional<std::filesystem::path> map_path;
  for (const std::string& argument : arguments) {
    if (argument == "--help" || argument == "-h") {
      out << kInfoHelp;
      return 0;
    } else if (argument.rfind("-", 0) == 0) {
      throw UsageError("unknown option '" + argument + "'");
    } else if (map_path) {
      throw UsageError("unexpected argument '" + argument + "' (one map only)");
    }
    map_path = argument;
  }
  if (!map_path) throw UsageError("info needs a MAP (map directory or .evmap file)");
  const std::filesystem::path file = ResolveMapFile(*map_path);
  const MapFileHeader header = ReadMapFileHeader(file);
  const Map map = LoadMap(file);
  MapInfo info = SummarizeMap(map);
  info.format_version = header.format_version;
  out << "map:              " << file.string() << "\n";
  out << "file size:        " << header.payload_length + kMapFileHeaderSize << " bytes (payload "
      << header.payload_length << ", CRC32C " << std::hex << std::setw(8) << std::setfill('0')
      << header.payload_crc32c << std::dec << std::setfill(' ') << ", verified)\n";
  out << FormatMapInfo(info);
  return 0;
}

std::string TopLevelHelp() {
  std::ostringstream text;
  text << "usage: evloc-mapper SUBCOMMAND [ARGS...]\n\n"
          "Builds, imports and inspects evloc maps (docs/map-format.md).\n\nsubcommands:\n";
  for (const MapperSubcommand& subcommand : MapperSubcommands()) {
    text << "  " << std::left << std::setw(12) << subcommand.name << subcommand.summary << "\n";
  }
  text << "\nRun `evloc-mapper SUBCOMMAND --help` for its options.\n";
  return text.str();
}

}  // namespace

int RunImportPcdCommand(const std::vector<std::string>& arguments, const std::string& command_line,
                        std::ostream& out, std::ostream& err) {
  return RunGuarded("evloc-mapper import-pcd", err,
                    [&] { return ImportPcd(arguments, command_line, out); });
}

int RunInfoCommand(const std::vector<std::string>& arguments, const std::string& /*command_line*/,
                   std::ostream& out, std::ostream& err) {
  return RunGuarded("evloc-mapper info", err, [&] { return Info(arguments, out); });
}

// `build` keeps its own argv-style entry point (mapper/build_command.h), which prints to the
// process's streams.
int RunBuildSubcommand(const std::vector<std::string>& arguments,
                       const std::string& /*command_line*/, std::ostream& /*out*/,
                       std::ostream& /*err*/) {
  std::vector<std::string> storage = {"build"};
  storage.insert(storage.end(), arguments.begin(), arguments.end());
  std::vector<char*> argv;
  for (std::string& argument : storage) argv.push_back(argument.data());
  return mapper::RunBuildCommand(static_cast<int>(argv.size()), argv.data());
}

const std::vector<MapperSubcommand>& MapperSubcommands() {
  static const std::vector<MapperSubcommand> subcommands = {
      {"build", "build a map from images (COLMAP or known poses, semi-dense edges)",
       RunBuildSubcommand},
      {"import-pcd", "import a Canny-EVT PCD map into a map directory", RunImportPcdCommand},
      {"info", "verify and summarise a map", RunInfoCommand},
  };
  return subcommands;
}

int RunMapperCli(int argc, const char* const* argv, std::ostream& out, std::ostream& err) {
  std::string command_line;
  for (int i = 0; i < argc; ++i) command_line += (i ? " " : "") + std::string(argv[i]);
  if (argc < 2) {
    err << TopLevelHelp();
    return kExitUsage;
  }
  const std::string name = argv[1];
  if (name == "--help" || name == "-h" || name == "help") {
    out << TopLevelHelp();
    return 0;
  }
  const std::vector<std::string> arguments(argv + 2, argv + argc);
  for (const MapperSubcommand& subcommand : MapperSubcommands()) {
    if (subcommand.name == name) return subcommand.run(arguments, command_line, out, err);
  }
  return RunGuarded("evloc-mapper", err,
                    [&]() -> int { throw UsageError("unknown subcommand '" + name + "'"); });
}

}  // namespace evloc
