#include "maps/map_directory.h"

#include <signal.h>

#include <cerrno>
#include <string>
#include <system_error>
#include <vector>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "maps/ply.h"

namespace evloc {
namespace {

constexpr std::string_view kStagingTag = "staging";

// The process id in a name made by UniqueSiblingName(…, tag) (".NAME.tag-PID-…"); 0 when
// `file_name` is not such a name.
long StagingOwner(const std::string& file_name, const char* final_name) {
  const std::string prefix = "." + std::string(final_name) + "." + std::string(kStagingTag) + "-";
  if (file_name.rfind(prefix, 0) != 0) return 0;
  const size_t begin = prefix.size();
  const size_t end = file_name.find('-', begin);
  if (end == std::string::npos || end == begin) return 0;
  long pid = 0;
  for (size_t i = begin; i < end; ++i) {
    if (file_name[i] < '0' || file_name[i] > '9' || pid > 1'000'000'000) return 0;
    pid = pid * 10 + (file_name[i] - '0');
  }
  return pid;
}

// Removes the staging files (and their WriteFileAtomically temporaries) that writers killed
// before they could clean up left in `directory`: only names this module makes, and only when
// their process no longer exists. Called with the map's lock held.
void RemoveStagingFilesOfDeadWriters(const std::filesystem::path& directory) {
  std::error_code error;
  std::vector<std::filesystem::path> stale;
  for (auto it = std::filesystem::directory_iterator(directory, error);
       !error && it != std::filesystem::directory_iterator(); it.increment(error)) {
    const std::string name = it->path().filename().string();
    for (const char* final_name : {kMapFileName, kMapPlyFileName}) {
      // A temporary of a staging file is ".<staging name>.tmp-…": strip the leading dot.
      const std::string staging = name.rfind("..", 0) == 0 ? name.substr(1) : name;
      const long pid = StagingOwner(staging, final_name);
      if (pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH) {
        stale.push_back(it->path());
      }
    }
  }
  for (const auto& path : stale) std::filesystem::remove(path, error);
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

std::filesystem::path MapDirectoryLockFile(const std::filesystem::path& directory) {
  const std::filesystem::path normal = directory.lexically_normal();
  const std::filesystem::path name =
      normal.has_filename() ? normal.filename() : normal.parent_path().filename();
  const std::filesystem::path parent =
      normal.has_filename() ? normal.parent_path() : normal.parent_path().parent_path();
  return (parent.empty() ? std::filesystem::path(".") : parent) / ("." + name.string() + ".lock");
}

void WriteMapDirectory(const std::filesystem::path& directory, const Map& map,
                       const MapDirectoryWriteOptions& options) {
  map.Check();
  std::error_code error;
  if (std::filesystem::exists(directory, error) &&
      !std::filesystem::is_directory(directory, error)) {
    throw IoError("cannot write map directory '" + directory.string() +
                  "': it exists and is not a directory");
  }
  const std::filesystem::path lock_file = MapDirectoryLockFile(directory);
  std::filesystem::create_directories(lock_file.parent_path(), error);
  if (error) {
    throw IoError("cannot create '" + lock_file.parent_path().string() + "': " + error.message());
  }
  // One writer per map at a time, across processes: the check for an existing map, the staging
  // and the renames happen under the lock.
  const ScopedFileLock lock(lock_file);
  const std::filesystem::path map_file = directory / kMapFileName;
  if (std::filesystem::exists(map_file, error) && !options.overwrite) {
    throw InvalidArgumentError("'" + directory.string() + "' already holds a map (" +
                               map_file.string() + "); choose another directory or overwrite");
  }
  const bool created_directory = std::filesystem::create_directory(directory, error);
  if (error) {
    throw IoError("cannot create map directory '" + directory.string() + "': " + error.message());
  }
  if (created_directory) SyncPath(lock_file.parent_path());
  RemoveStagingFilesOfDeadWriters(directory);
  // (staging file, final file), renamed in this order: map.evmap last, so that a reader never
  // sees a new map.evmap next to a stale map.ply.
  std::vector<std::pair<std::filesystem::path, std::filesystem::path>> staged;
  size_t renamed = 0;
  try {
    if (options.write_ply) {
      const std::filesystem::path staging_ply =
          UniqueSiblingName(directory / kMapPlyFileName, kStagingTag);
      staged.emplace_back(staging_ply, directory / kMapPlyFileName);
      WritePly(staging_ply, map);
    }
    const std::filesystem::path staging_map =
        UniqueSiblingName(directory / kMapFileName, kStagingTag);
    staged.emplace_back(staging_map, map_file);
    SaveMap(staging_map, map);
    for (const auto& [staging, final_path] : staged) {
      std::filesystem::rename(staging, final_path, error);
      if (error) {
        throw IoError("cannot rename '" + staging.string() + "' to '" + final_path.string() +
                      "': " + error.message());
      }
      ++renamed;
    }
    SyncPath(directory);
  } catch (...) {
    std::error_code ignored;
    // Only what this call made: its staging files, and the directory when this call created it
    // and it is empty again (std::filesystem::remove does not remove a non-empty directory).
    for (size_t i = 0; i < staged.size(); ++i) {
      const auto& [staging, final_path] = staged[i];
      std::filesystem::remove(i < renamed && created_directory ? final_path : staging, ignored);
    }
    if (created_directory) std::filesystem::remove(directory, ignored);
    throw;
  }
}

}  // namespace evloc
