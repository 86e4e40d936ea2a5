// The maps a localizer serves: one per subdirectory of a map folder (`DIR/NAME/map.evmap`, the
// name being the directory name). Maps are loaded on first use and shared read-only with every
// session; a new file dropped into the folder (atomically, as WriteMapDirectory does) is picked
// up by the next session while running sessions keep the version they started with.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "maps/map.h"
#include "maps/visibility.h"

namespace evloc::service {

// A requested map (or map version) does not exist.
class MapNotFoundError : public Error {
 public:
  using Error::Error;
};

// A map as loaded by the registry: the map, its visibility index and what describes it. Never
// changes once built; shared by every session that tracks against it.
struct LoadedMap {
  // Map name (its directory name).
  std::string name;
  // Version: the content checksum as 8 lowercase hex digits.
  std::string version;
  // Content checksum (CRC32C, docs/map-format.md).
  uint32_t content_crc32c = 0;
  // Size of map.evmap, bytes.
  uint64_t file_bytes = 0;
  // Modification time of map.evmap when it was loaded.
  std::filesystem::file_time_type file_time;
  // The map.
  Map map;
  // Summary (counts, bounding box).
  MapInfo info;
  // Visibility index built on `map`.
  std::unique_ptr<VisibilityIndex> visibility;
};

// Options of the registry.
struct MapRegistryOptions {
  // Folder holding one subdirectory per map.
  std::filesystem::path maps_dir;

  // Throws InvalidArgumentError when maps_dir is empty or not a directory.
  void Check() const;
};

// Thread-safe registry of the maps in a folder.
class MapRegistry {
 public:
  // Throws InvalidArgumentError when the options are invalid. Loads nothing yet.
  explicit MapRegistry(MapRegistryOptions options);

  // Names of the maps in the folder (subdirectories holding map.evmap), sorted.
  std::vector<std::string> ListNames() const;

  // The current version of map `name`: loaded on first use, and reloaded when map.evmap changed
  // (size or modification time) since it was loaded. When a reload fails (e.g. a file copied in
  // place non-atomically) the previous version keeps being served. `version`, when given, must
  // equal the current version. Throws MapNotFoundError when there is no such map or version,
  // IoError / ParseError when a map that was never loaded cannot be loaded.
  std::shared_ptr<const LoadedMap> Get(const std::string& name,
                                       const std::optional<std::string>& version = std::nullopt);

  // Number of map versions loaded since construction (reloads included).
  int64_t loads() const;

 private:
  MapRegistryOptions options_;
  mutable std::mutex mutex_;
  std::map<std::string, std::shared_ptr<const LoadedMap>> current_;
  int64_t loads_ = 0;
};

// Formats a content checksum as a version string (8 lowercase hex digits).
std::string MapVersionString(uint32_t content_crc32c);

}  // namespace evloc::service
