#include "mapper/mapper_cli.h"

#include <filesystem>
#include <iomanip>
#include <optional>
#include <sstream>

#include "core/common/cli.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/provenance.h"
#include "mapper/build_command.h"
#include "mapper/georeference.h"
#include "mapper/relocalization_data.h"
#include "maps/map.h"
#include "maps/map_directory.h"
#include "maps/pcd_import.h"
#include "maps/site.h"

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

const char kUpgradeHelp[] =
    "usage: evloc-mapper upgrade --map MAP --images DIR [--out OUT] [--force] [--threads N]\n"
    "\n"
    "Adds the relocalization data of map format v2 (landmarks, keyframe features, vocabulary,\n"
    "global descriptors; docs/map-format.md) to a format v1 map, or to a v2 map without it: the\n"
    "keyframe images are read from DIR by the names the map records, and the data is computed\n"
    "as `evloc-mapper build` computes it. MAP is a map directory or a .evmap file.\n"
    "\n"
    "In place by default: the new map replaces MAP atomically and the old file is kept as\n"
    "MAP.v1.bak (refused when that backup exists, unless --force). With --out the map is written\n"
    "to OUT (a .evmap file, or a directory that gets map.evmap) and MAP is left alone.\n"
    "\n"
    "  --map MAP       the map to upgrade\n"
    "  --images DIR    folder of the images the map was built from\n"
    "  --out OUT       write the upgraded map here instead of in place\n"
    "  --force         replace an existing OUT or backup, or recompute relocalization data the\n"
    "                  map already has\n"
    "  --threads N     threads for feature extraction and matching (default 2; same result)\n"
    "  --help          show this help\n";

// Throws the UsageError of a subcommand's argument that none of its flags took.
[[noreturn]] void RejectArgument(const std::string& argument) {
  if (argument.rfind("-", 0) == 0) throw UsageError("unknown option '" + argument + "'");
  throw UsageError("unexpected argument '" + argument + "'");
}

// The map a command reads and rewrites (upgrade, georef): the resolved .evmap file and, when it
// is rewritten in place (no OUT), the map's writer lock (the one evloc-mapper build and import-pcd
// take) held throughout, so that a concurrent writer's map is neither lost nor mixed in.
struct MapRewrite {
  MapRewrite(const std::filesystem::path& map, const std::filesystem::path& out)
      : source(ResolveMapFile(map)) {
    if (out.empty()) {
      lock.emplace(MapDirectoryLockFile(std::filesystem::absolute(source).parent_path()));
    }
  }
  std::filesystem::path source;
  std::optional<ScopedFileLock> lock;
};

// Where a command that rewrites a map writes it: OUT (a .evmap file, or a directory that gets
// map.evmap), or the source itself when OUT is empty. Refuses an existing OUT without `force`.
std::filesystem::path RewriteTarget(const std::filesystem::path& source,
                                    const std::filesystem::path& out, bool force) {
  namespace fs = std::filesystem;
  if (out.empty()) return source;
  std::error_code error;
  const fs::path target =
      fs::is_directory(out, error) || out.extension() != ".evmap" ? out / kMapFileName : out;
  if (fs::exists(target, error) && !force) {
    throw InvalidArgumentError("'" + target.string() +
                               "' exists; choose another --out or pass "
                               "--force to replace it");
  }
  if (!target.parent_path().empty()) fs::create_directories(target.parent_path(), error);
  return target;
}

const char kTileHelp[] =
    "usage: evloc-mapper tile --map MAP --out SITE [--tile-size M] [--overlap M]\n"
    "                         [--origin X,Y] [--name NAME] [--force]\n"
    "\n"
    "Splits a built map into a site served as tiles (docs/map-format.md, \"Sites\"): SITE gets\n"
    "one self-contained .evmap per square of the grid in the x-y plane (z up) that owns points\n"
    "(the points of the square grown by the overlap; the keyframes, with their relocalization\n"
    "features, whose camera centre lies in the square), then site.manifest, written last, so a\n"
    "killed run leaves no site. `evloc-localizer serve` serves SITE under its folder name and\n"
    "`evloc-track --map SITE` tracks against it.\n"
    "\n"
    "  --map MAP        the map (directory or .evmap file)\n"
    "  --out SITE       the site folder (created if missing)\n"
    "  --tile-size M    edge of a tile's square, metres (default 50)\n"
    "  --overlap M      how far each tile reaches into its neighbours, metres, below the tile\n"
    "                   size (default 10)\n"
    "  --origin X,Y     corner of tile (0, 0), metres (default: the multiple of the tile size at\n"
    "                   or below the points' smallest x and y)\n"
    "  --name NAME      site name in the manifest (default: the folder name)\n"
    "  --force          replace a site already in SITE\n"
    "  --help           show this help\n";

int Tile(const std::vector<std::string>& arguments, const std::string& command_line,
         std::ostream& out) {
  std::filesystem::path map_path;
  std::filesystem::path site_path;
  TilingOptions options;
  options.command_line = command_line;
  for (size_t i = 0; i < arguments.size(); ++i) {
    const std::string& argument = arguments[i];
    const auto value = [&]() -> const std::string& { return TakeFlagValue(arguments, &i); };
    if (argument == "--help" || argument == "-h") {
      out << kTileHelp;
      return 0;
    } else if (argument == "--map") {
      map_path = value();
    } else if (argument == "--out") {
      site_path = value();
    } else if (argument == "--tile-size") {
      options.tile_size_m = ParseDoubleFlag(argument, value());
    } else if (argument == "--overlap") {
      options.overlap_m = ParseDoubleFlag(argument, value());
    } else if (argument == "--origin") {
      const std::string& text = value();
      const size_t comma = text.find(',');
      if (comma == std::string::npos) throw UsageError("--origin takes X,Y in metres");
      options.origin = Eigen::Vector2d(ParseDoubleFlag(argument, text.substr(0, comma)),
                                       ParseDoubleFlag(argument, text.substr(comma + 1)));
    } else if (argument == "--name") {
      options.name = value();
    } else if (argument == "--force") {
      options.overwrite = true;
    } else {
      RejectArgument(argument);
    }
  }
  if (map_path.empty()) throw UsageError("tile needs --map MAP");
  if (site_path.empty()) throw UsageError("tile needs --out SITE");
  try {
    options.Check();
  } catch (const InvalidArgumentError& error) {
    throw UsageError(error.what());
  }
  const Map map = LoadMap(ResolveMapFile(map_path));
  const SiteManifest manifest = TileMap(map, site_path, options);
  uint64_t points = 0;
  uint64_t bytes = 0;
  for (const SiteTile& tile : manifest.tiles) {
    points += tile.num_points;
    bytes += tile.file_bytes;
  }
  out << "tiled " << map.size() << " points and " << map.keyframes.size() << " keyframes into "
      << manifest.tiles.size() << " tiles of " << options.tile_size_m << " m (overlap "
      << options.overlap_m << " m): " << points << " points stored (x" << std::setprecision(3)
      << static_cast<double>(points) / static_cast<double>(map.size()) << "), " << bytes
      << " bytes\n"
      << "site " << manifest.name << " version " << manifest.version << " in " << site_path.string()
      << "\n";
  return 0;
}

// The options of `upgrade`, one field per flag.
struct UpgradeCommandOptions {
  // The map (directory or .evmap file).
  std::filesystem::path map;
  // Folder of the keyframe images.
  std::filesystem::path images;
  // Where to write; empty: in place.
  std::filesystem::path out;
  // Replace an existing output or backup; recompute existing relocalization data.
  bool force = false;
  // Threads for extraction and matching.
  int threads = 2;
  // --help was given.
  bool help = false;

  // Throws UsageError when --map or --images is missing or --threads < 1.
  void Check() const {
    if (map.empty()) throw UsageError("upgrade needs --map MAP");
    if (images.empty()) throw UsageError("upgrade needs --images DIR");
    if (threads < 1) throw UsageError("--threads must be at least 1");
  }
};

UpgradeCommandOptions ParseUpgradeOptions(const std::vector<std::string>& arguments) {
  UpgradeCommandOptions options;
  for (size_t i = 0; i < arguments.size(); ++i) {
    const std::string& argument = arguments[i];
    const auto value = [&]() -> const std::string& { return TakeFlagValue(arguments, &i); };
    if (argument == "--help" || argument == "-h") {
      options.help = true;
      return options;
    } else if (argument == "--map") {
      options.map = value();
    } else if (argument == "--images") {
      options.images = value();
    } else if (argument == "--out") {
      options.out = value();
    } else if (argument == "--force") {
      options.force = true;
    } else if (argument == "--threads") {
      options.threads = ParseIntFlag(argument, value());
    } else {
      RejectArgument(argument);
    }
  }
  options.Check();
  return options;
}

int Upgrade(const std::vector<std::string>& arguments, const std::string& command_line,
            std::ostream& out) {
  const UpgradeCommandOptions options = ParseCommandLine(ParseUpgradeOptions, arguments);
  if (options.help) {
    out << kUpgradeHelp;
    return 0;
  }
  namespace fs = std::filesystem;
  const MapRewrite rewrite(options.map, options.out);
  const fs::path& source = rewrite.source;
  const MapFileHeader header = ReadMapFileHeader(source);
  Map map = LoadMap(source);
  if (map.relocalization && !options.force) {
    throw InvalidArgumentError("'" + source.string() +
                               "' already has relocalization data (format v2); pass --force to "
                               "compute it again");
  }
  std::error_code error;
  const fs::path target = RewriteTarget(source, options.out, options.force);
  const fs::path backup = source.string() + ".v" + std::to_string(header.format_version) + ".bak";
  if (options.out.empty() && fs::exists(backup, error) && !options.force) {
    throw InvalidArgumentError("the backup '" + backup.string() +
                               "' exists; move it away or pass --force to replace it");
  }
  mapper::RelocalizationDataOptions relocalization;
  relocalization.num_threads = options.threads;
  mapper::RelocalizationDataStatistics statistics;
  map.relocalization =
      mapper::ComputeRelocalizationData(map, options.images, relocalization, &statistics);
  map.provenance.command_line += " ; " + command_line;
  map.provenance.inputs.push_back(fs::absolute(options.images).lexically_normal().string());
  if (options.out.empty()) {
    // The old file stays readable under MAP.v1.bak; the new one replaces MAP atomically.
    WriteFileAtomically(backup, ReadFileToString(source));
  }
  SaveMap(target, map);
  out << "upgraded " << source.string() << " (format " << header.format_version << ", "
      << kMapFileHeaderSize + header.payload_length << " bytes) to " << target.string()
      << " (format " << kMapFormatVersion << ", " << fs::file_size(target)
      << " bytes): " << statistics.num_landmarks << " landmarks, " << statistics.num_features_kept
      << " keyframe features of " << statistics.num_features_extracted << ", "
      << statistics.bytes_added << " bytes of relocalization data\n";
  if (options.out.empty()) out << "the previous map is kept as " << backup.string() << "\n";
  return 0;
}

const char kGeorefHelp[] =
    "usage: evloc-mapper georef --map MAP (--geo-anchor LAT,LON,ALT[,HEADING] | --geo-points FILE\n"
    "                           | --geo-exif --images DIR) [--out OUT] [--force]\n"
    "                           [--geo-inlier-threshold M]\n"
    "\n"
    "Adds a geo anchor (docs/geo.md) to a map, or replaces its anchor (with --force): where the\n"
    "map frame is on the Earth, so that poses are also reported in WGS84. MAP is a map directory\n"
    "or a .evmap file. In place by default (the map is replaced atomically; its content version,\n"
    "the content CRC32C, does not change: the anchor is not part of it); with --out the map is\n"
    "written to OUT (a .evmap file, or a directory that gets map.evmap) and MAP is left alone.\n"
    "\n"
    "  --map MAP                  the map\n"
    "  --geo-anchor LAT,LON,ALT[,HEADING]  the map frame is the ENU frame at this WGS84 point\n"
    "                             (degrees, metres above the ellipsoid), its +y axis at HEADING\n"
    "                             degrees clockwise from north (default 0)\n"
    "  --geo-points FILE          WGS84 positions of keyframe images or map points; the map is\n"
    "                             aligned to them robustly (RANSAC, then least squares)\n"
    "  --geo-exif                 the GNSS tags in the EXIF data of the keyframe images\n"
    "  --images DIR               folder of the images the map was built from (--geo-exif)\n"
    "  --geo-inlier-threshold M   a point agrees with the alignment within M metres (default 10)\n"
    "  --out OUT                  write the map here instead of in place\n"
    "  --force                    replace an existing anchor or OUT\n"
    "  --help                     show this help\n";

// The options of `georef`, one field per flag.
struct GeorefCommandOptions {
  // The map (directory or .evmap file).
  std::filesystem::path map;
  // Folder of the keyframe images (--geo-exif).
  std::filesystem::path images;
  // Where to write; empty: in place.
  std::filesystem::path out;
  // Replace an existing anchor or output.
  bool force = false;
  // The anchor's source.
  mapper::GeoReferenceOptions geo;
  // --help was given.
  bool help = false;

  // Throws UsageError unless --map and exactly one source are given (--geo-exif with --images).
  void Check() const {
    if (map.empty()) throw UsageError("georef needs --map MAP");
    if (!geo.Any()) throw UsageError("georef needs --geo-anchor, --geo-points or --geo-exif");
    if (geo.exif && images.empty()) throw UsageError("--geo-exif needs --images DIR");
    try {
      geo.Check();
    } catch (const InvalidArgumentError& error) {
      throw UsageError(error.what());
    }
  }
};

GeorefCommandOptions ParseGeorefOptions(const std::vector<std::string>& arguments) {
  GeorefCommandOptions options;
  for (size_t i = 0; i < arguments.size(); ++i) {
    const std::string& argument = arguments[i];
    const auto value = [&]() -> const std::string& { return TakeFlagValue(arguments, &i); };
    if (argument == "--help" || argument == "-h") {
      options.help = true;
      return options;
    } else if (argument == "--map") {
      options.map = value();
    } else if (argument == "--images") {
      options.images = value();
    } else if (argument == "--out") {
      options.out = value();
    } else if (argument == "--force") {
      options.force = true;
    } else if (argument == "--geo-anchor") {
      options.geo.given = mapper::ParseGeoAnchorFlag(argument, value());
    } else if (argument == "--geo-points") {
      options.geo.points_file = value();
    } else if (argument == "--geo-exif") {
      options.geo.exif = true;
    } else if (argument == "--geo-inlier-threshold") {
      options.geo.alignment.inlier_threshold_m = ParseDoubleFlag(argument, value());
    } else {
      RejectArgument(argument);
    }
  }
  options.Check();
  return options;
}

int Georef(const std::vector<std::string>& arguments, const std::string& command_line,
           std::ostream& out) {
  const GeorefCommandOptions options = ParseCommandLine(ParseGeorefOptions, arguments);
  if (options.help) {
    out << kGeorefHelp;
    return 0;
  }
  namespace fs = std::filesystem;
  const MapRewrite rewrite(options.map, options.out);
  const fs::path& source = rewrite.source;
  Map map = LoadMap(source);
  if (map.geo_anchor && !options.force) {
    throw InvalidArgumentError("'" + source.string() + "' already has a geo anchor (source " +
                               map.geo_anchor->source + "); pass --force to replace it");
  }
  const fs::path target = RewriteTarget(source, options.out, options.force);
  mapper::GeoReferenceResult result = mapper::GeoReferenceMap(map, options.images, options.geo);
  map.geo_anchor = result.anchor;
  map.provenance.command_line += " ; " + command_line;
  if (options.geo.points_file) {
    map.provenance.inputs.push_back(
        fs::absolute(*options.geo.points_file).lexically_normal().string());
  }
  SaveMap(target, map);
  out << "wrote " << target.string() << " (content CRC32C " << std::hex << std::setw(8)
      << std::setfill('0') << ComputeMapContentChecksum(map) << std::dec << std::setfill(' ')
      << ", unchanged by the anchor)\n";
  out << mapper::FormatGeoReference(result.anchor, result.alignment, result.inputs);
  return 0;
}

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

int RunUpgradeCommand(const std::vector<std::string>& arguments, const std::string& command_line,
                      std::ostream& out, std::ostream& err) {
  return RunGuarded("evloc-mapper upgrade", err,
                    [&] { return Upgrade(arguments, command_line, out); });
}

int RunGeorefCommand(const std::vector<std::string>& arguments, const std::string& command_line,
                     std::ostream& out, std::ostream& err) {
  return RunGuarded("evloc-mapper georef", err,
                    [&] { return Georef(arguments, command_line, out); });
}

int RunTileCommand(const std::vector<std::string>& arguments, const std::string& command_line,
                   std::ostream& out, std::ostream& err) {
  return RunGuarded("evloc-mapper tile", err, [&] { return Tile(arguments, command_line, out); });
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
      {"georef", "add or replace the geo anchor of a map (WGS84; docs/geo.md)", RunGeorefCommand},
      {"import-pcd", "import a Canny-EVT PCD map into a map directory", RunImportPcdCommand},
      {"info", "verify and summarise a map", RunInfoCommand},
      {"upgrade", "add relocalization data (format v2) to a v1 map from its images",
       RunUpgradeCommand},
      {"tile", "split a map into a site of tiles for serving", RunTileCommand},
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
