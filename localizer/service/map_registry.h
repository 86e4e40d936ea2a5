// The maps a localizer serves: one per subdirectory of a map folder (`DIR/NAME/map.evmap`, the
// name being the directory name), and the sites served as tiles (`DIR/NAME/site.manifest`,
// maps/site.h): a site is "loaded" as its manifest, and its tiles come from the registry's
// server-wide TileCache as sessions need them. Maps are loaded on first use and shared read-only
// with every session; a new file dropped into the folder (atomically, as WriteMapDirectory does) is
// picked up by the next session while running sessions keep the version they started with.
//
// Bounded: the loaded maps are an LRU cache with a byte budget (max_map_memory_bytes); a map
// dropped from the cache stays alive as long as a session holds it (shared_ptr). Concurrent: the
// registry's lock only guards its tables, never file I/O; each (map, file version) is loaded
// once, by the first request, while the others wait for that load only. A load that fails is
// remembered for that file version (size and modification time): the file is not read again
// until it changes.
//
// Durable last good versions: with a keep folder (MapRegistryOptions::keep_dir), the registry
// writes the bytes of every map version it loaded there (`KEEP/NAME.evmap`, the bytes it
// verified). When a map's file then stops loading (copied in place non-atomically, truncated,
// crafted) and its last good version is no longer in the cache, the kept copy is loaded and served
// instead, so a map never goes from "served" to "error" because of a bad file.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "maps/map.h"
#include "maps/tile_cache.h"
#include "maps/visibility.h"

namespace evloc::service {

// A requested map (or map version) does not exist.
class MapNotFoundError : public Error {
 public:
  using Error::Error;
};

// A map file exists but cannot be loaded for a reason that is not one of the typed errors of its
// reader (out of memory, an unexpected exception); the message names the map.
class MapLoadError : public Error {
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
  // Visibility index built on `map` (null for a site).
  std::unique_ptr<VisibilityIndex> visibility;
  // For a site: the site (its manifest) and the tile cache its sessions take tiles from; `map`
  // is then empty but for the site's geo anchor and `file_bytes`, `file_time` are the manifest's.
  std::shared_ptr<const Site> site;
  std::shared_ptr<TileCache> tiles;
  // Estimated memory of the map and its index, bytes (what counts against the cache budget).
  uint64_t memory_bytes = 0;
};

// What ListMaps says about a map, read from the loaded map or from the file's header and
// summary fields (ReadMapFileSummary) without loading it.
struct MapDescriptionData {
  // Map name (its directory name).
  std::string name;
  // Version: the content checksum as 8 lowercase hex digits.
  std::string version;
  // Counts, bounding box, content checksum and file size (header: unset when from a loaded map).
  MapFileSummary summary;
};

// The description of a loaded map (its MapInfo and file size).
MapDescriptionData DescribeLoadedMap(const LoadedMap& map);

// Options of the registry.
struct MapRegistryOptions {
  // Folder holding one subdirectory per map.
  std::filesystem::path maps_dir;
  // Budget of the loaded-map cache, bytes (MapMemoryBytes of each map): beyond it the least
  // recently used maps are dropped from the cache (sessions keep theirs). The most recently
  // used map always stays, even when it alone is larger.
  uint64_t max_map_memory_bytes = uint64_t{1} << 30;
  // The budget of the sites' tile cache, bytes (its own LRU of unused tiles).
  uint64_t max_tile_memory_bytes = uint64_t{1} << 30;
  // Background threads of the tile cache (loads and compositions of the sites' tiles).
  int tile_loader_threads = 1;
  // Their scheduling priority (TileCacheOptions::loader_priority).
  ThreadPriority tile_loader_priority = TileCacheOptions{}.loader_priority;
  // Folder (existing, writable) where each map version loaded is kept, to serve again when its
  // file stops loading after the version left the cache; empty: nothing is kept. Takes disk
  // space of one file per map name. Sites are not kept (evloc-mapper tile writes their manifests
  // last and atomically).
  std::filesystem::path keep_dir{};
  // Called (from the request's thread, without the registry's lock) with a line for the operator
  // when a version cannot be kept and when a kept version is served instead of a file that does
  // not load. Optional.
  std::function<void(const std::string& line)> warn{};

  // Throws InvalidArgumentError when maps_dir is empty or not a directory, a budget is 0, the
  // loader threads are not in 1..64, or keep_dir is given and is not a directory or is maps_dir.
  void Check() const;
};

// Thread-safe registry of the maps in a folder.
class MapRegistry {
 public:
  // Throws InvalidArgumentError when the options are invalid. Loads nothing yet.
  explicit MapRegistry(MapRegistryOptions options);

  // Names of the maps and sites in the folder (subdirectories holding map.evmap or
  // site.manifest), sorted.
  std::vector<std::string> ListNames() const;

  // The current version of map `name`: loaded on first use, and reloaded when map.evmap changed
  // (size or modification time) since it was loaded. When a reload fails (e.g. a file copied in
  // place non-atomically, or a crafted one) the previous version keeps being served while it is
  // in the cache or kept (keep_dir). `version`, when given, must equal the current version.
  // Throws MapNotFoundError when there is no such map or version; IoError, ParseError or
  // MapLoadError (never anything else) when the map cannot be loaded and no earlier version is in
  // the cache or kept.
  std::shared_ptr<const LoadedMap> Get(const std::string& name,
                                       const std::optional<std::string>& version = std::nullopt);

  // What describes the version Get(name) would serve, without loading the map: from the cache
  // when it holds it, else from the file's summary fields (ReadMapFileSummary, constant memory).
  // A file version whose load failed is not described (the last good version is, when cached).
  // Throws like Get.
  MapDescriptionData Describe(const std::string& name);

  // Number of map versions loaded since construction (reloads included).
  int64_t loads() const;
  // Number of times a map file was read by a load (successful or not) since construction.
  int64_t load_attempts() const;
  // Bytes of the maps in the cache (MapMemoryBytes).
  uint64_t cached_bytes() const;
  // Number of maps in the cache.
  size_t cached_maps() const;
  // Number of times a kept copy was loaded because the map's file did not load.
  int64_t kept_restores() const;
  // The sites' tile cache (its counters for the metrics).
  const TileCache& tile_cache() const { return *tiles_; }

 private:
  // Size and modification time of a map file: a file version.
  struct FileStamp {
    uint64_t bytes = 0;
    std::filesystem::file_time_type time;
    // The file is a site manifest (else a map.evmap).
    bool site = false;
    bool operator==(const FileStamp& other) const {
      return bytes == other.bytes && time == other.time && site == other.site;
    }
  };
  // One load of one file version; the first requester loads, the others wait on `done`.
  struct Load;
  // Everything the registry knows about one map name.
  struct Entry {
    // The newest version loaded successfully, while it is in the cache.
    std::shared_ptr<const LoadedMap> current;
    // Where `current` is in lru_ (valid when current is set).
    std::list<std::string>::iterator lru_position;
    // The load in progress or the last one (its result is the negative cache when it failed).
    std::shared_ptr<Load> load;
    // Description of the file version `described`, read without loading.
    std::optional<MapDescriptionData> description;
    // File version of `description`.
    FileStamp described;
    // Version of the copy in keep_dir written by this registry (empty: none yet).
    std::string kept_version;
    // The file version after whose failure the kept copy did not load either (not tried again
    // until the file changes).
    std::optional<FileStamp> kept_failed_for;
  };

  // The file version of `name`'s site.manifest or else map.evmap; nullopt when neither exists.
  std::optional<FileStamp> Stamp(const std::string& name) const;
  // Loads `name` at `stamp`, converting every exception to an evloc Error.
  std::shared_ptr<const LoadedMap> LoadVersion(const std::string& name, const FileStamp& stamp);
  // Makes `map` the current version of `entry` and evicts beyond the budget. Needs mutex_.
  void InsertLocked(Entry& entry, std::shared_ptr<const LoadedMap> map);
  // Writes `bytes` (those `map` was loaded from) to keep_dir unless that version is kept already.
  void Keep(const LoadedMap& map, const std::string& bytes);
  // After `name`'s file (version `failed`) did not load, with `error`: the current version when
  // one is in the cache, else the kept copy loaded and made the current version; null when there
  // is neither (a kept copy that does not load is not tried again for the same file version).
  std::shared_ptr<const LoadedMap> RestoreKept(const std::string& name, const FileStamp& failed,
                                               const std::string& error);
  void Warn(const std::string& line) const;
  // Where the kept copy of map `name` is (in keep_dir).
  std::filesystem::path KeptFile(const std::string& name) const;

  MapRegistryOptions options_;
  std::shared_ptr<TileCache> tiles_;
  mutable std::mutex mutex_;
  // Serialises the loads of kept copies (rare: only after a failure, for a map not in the cache).
  std::mutex restore_mutex_;
  std::map<std::string, Entry> entries_;
  // Names of the cached maps, most recently used first.
  std::list<std::string> lru_;
  uint64_t cached_bytes_ = 0;
  size_t cached_maps_ = 0;
  int64_t loads_ = 0;
  int64_t load_attempts_ = 0;
  int64_t kept_restores_ = 0;
};

// Formats a content checksum as a version string (8 lowercase hex digits).
std::string MapVersionString(uint32_t content_crc32c);

}  // namespace evloc::service
