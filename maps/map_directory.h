// A map directory (MAPDIR): the layout evloc tools write and read, `MAPDIR/map.evmap` (the map)
// and `MAPDIR/map.ply` (the points for viewers). See docs/map-format.md.
#pragma once

#include <filesystem>

#include "maps/map.h"

namespace evloc {

// File name of the map inside a map directory.
inline constexpr const char* kMapFileName = "map.evmap";
// File name of the PLY export inside a map directory.
inline constexpr const char* kMapPlyFileName = "map.ply";

// The .evmap file for a path given by a user: `path/map.evmap` when `path` is a directory,
// `path` itself otherwise. Throws IoError when a directory holds no map.evmap.
std::filesystem::path ResolveMapFile(const std::filesystem::path& path);

// How WriteMapDirectory treats an existing map.
struct MapDirectoryWriteOptions {
  // Replace the map files of a directory that already holds a map; otherwise refuse.
  bool overwrite = false;
  // Also write map.ply.
  bool write_ply = true;
};

// The lock file that serialises the writers of map directory `directory`: ".NAME.lock" next to
// it in its parent (hidden, so map folders ignore it).
std::filesystem::path MapDirectoryLockFile(const std::filesystem::path& directory);

// Writes `map` into `directory` (created when missing, with its parents) as map.evmap and
// map.ply, holding an exclusive flock on MapDirectoryLockFile(directory) so that concurrent
// writers (threads or processes) of one map run one after the other. Every file is first written
// in full and fsync'ed under a staging name unique to the call, then renamed in place, map.evmap
// last, and the directory is fsync'ed: a crash or an error leaves either the old or the new map,
// never a partial one. On error the call removes only what it made (its staging files; the
// directory and its files only when this call created the directory). Staging files of writers
// that were killed (their process is gone) are removed by the next write. Throws
// InvalidArgumentError when the map is invalid or the directory already holds a map and
// `overwrite` is false, IoError when writing fails.
void WriteMapDirectory(const std::filesystem::path& directory, const Map& map,
                       const MapDirectoryWriteOptions& options = {});

}  // namespace evloc
