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

// Writes `map` into `directory` (created when missing, with its parents) as map.evmap and
// map.ply. Every file is first written in full under a temporary name and only then renamed in
// place, map.evmap last, so an error leaves no half-written or partial map: a directory the call
// created is removed again. Throws InvalidArgumentError when the map is invalid or the directory
// already holds a map and `overwrite` is false, IoError when writing fails.
void WriteMapDirectory(const std::filesystem::path& directory, const Map& map,
                       const MapDirectoryWriteOptions& options = {});

}  // namespace evloc
