#include "maps/map_directory.h"

#include <unistd.h>

#include <string>
#include <system_error>
#include <vector>

#include "core/common/error.h"
#include "maps/ply.h"

namespace evloc {
namespace {

std::filesystem::path StagingName(const std::filesystem::path& directory, const char* name) {
  return directory / ("." + std::string(name) + ".staging-" + std::to_string(::getpid()));
}

}  // namespace

std::filesystem::path ResolveMapFile(const std::filesystem::path& path) {
  std::error_code error;
  if (!std::filesystem::is_directory(path, error)) return path;
  const std::filesystem::path file = path / kMapFileName;
  if (!std::filesystem::exists(file, error)) {
    throw IoError("'" + path.string() + "' is a directory without " + kMapFileName +
                  "; pass a map directory written by evloc-mapper or a .evmap file");
  }
  return file;
}

void WriteMapDirectory(const std::filesystem::path& directory, const Map& map,
                       const MapDirectoryWriteOptions& options) {
  map.Check();
  std::error_code error;
  const std::filesystem::path map_file = directory / kMapFileName;
  if (std::filesystem::exists(map_file, error) && !options.overwrite) {
    throw InvalidArgumentError("'" + directory.string() + "' already holds a map (" +
                               map_file.string() + "); choose another directory or overwrite");
  }
  if (std::filesystem::exists(directory, error) &&
      !std::filesystem::is_directory(directory, error)) {
    throw IoError("cannot write map directory '" + directory.string() +
                  "': it exists and is not a directory");
  }
  bool created_directory = false;
  if (!std::filesystem::exists(directory, error)) {
    std::filesystem::create_directories(directory, error);
    if (error) {
      throw IoError("cannot create map directory '" + directory.string() + "': " + error.message());
    }
    created_directory = true;
  }
  // (staging file, final file), renamed in this order: map.evmap last, so that a reader never
  // sees a new map.evmap next to a stale map.ply.
  std::vector<std::pair<std::filesystem::path, std::filesystem::path>> staged;
  try {
    if (options.write_ply) {
      const std::filesystem::path staging_ply = StagingName(directory, kMapPlyFileName);
      staged.emplace_back(staging_ply, directory / kMapPlyFileName);
      WritePly(staging_ply, map);
    }
    const std::filesystem::path staging_map = StagingName(directory, kMapFileName);
    staged.emplace_back(staging_map, map_file);
    SaveMap(staging_map, map);
    for (const auto& [staging, final_path] : staged) {
      std::filesystem::rename(staging, final_path, error);
      if (error) {
        throw IoError("cannot rename '" + staging.string() + "' to '" + final_path.string() +
                      "': " + error.message());
      }
    }
  } catch (...) {
    std::error_code ignored;
    for (const auto& [staging, final_path] : staged) std::filesystem::remove(staging, ignored);
    if (created_directory) std::filesystem::remove_all(directory, ignored);
    throw;
  }
}

}  // namespace evloc
