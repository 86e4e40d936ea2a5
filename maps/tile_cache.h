// The server-wide cache of loaded site tiles (docs/architecture.md, "Sites and tiles"). Tiles are
// loaded by the cache's own loader threads (never by the caller of Request, so a tracking step
// never waits for a file), shared read-only between every session that uses them
// (reference-counted), and evicted least recently used first when the resident bytes exceed the
// budget, but only tiles no session holds. The loader threads also run other background work of
// the tiles' users (Post: the tiled map source composes its point arrays there).
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "core/common/thread_priority.h"
#include "maps/map.h"
#include "maps/site.h"
#include "maps/visibility.h"

namespace evloc {

// A site as its users hold it: the folder, the manifest read from it, and the key its tiles are
// cached under (folder and version, so a new version of a site never mixes with the old).
struct Site {
  // The site folder.
  std::filesystem::path directory;
  // The manifest.
  SiteManifest manifest;
  // Cache key: the folder's absolute path and the site version.
  std::string key;
};

// Reads the site in `directory` (ReadSiteManifest) into a shared Site. Throws like
// ReadSiteManifest.
std::shared_ptr<const Site> OpenSite(const std::filesystem::path& directory);

// A loaded tile: its map and a voxel visibility index built on it. Never changes once built.
struct LoadedTile {
  // Position of the tile in the site's manifest.
  size_t tile = 0;
  // The manifest's entry.
  SiteTile entry;
  // The tile map (LoadTile: checked against the manifest).
  Map map;
  // Visibility index on `map`: its keyframes' (a tile keeps every keyframe that sees one of its
  // points), or a voxel grid for tiles without keyframe visibility or with
  // TileCacheOptions::keyframe_visibility off.
  std::unique_ptr<VisibilityIndex> visibility;
  // MapMemoryBytes(map): what counts against the budget.
  uint64_t memory_bytes = 0;
};

// Options of the cache.
struct TileCacheOptions {
  // Resident bytes (MapMemoryBytes of the tiles) beyond which unused tiles are evicted, least
  // recently used first (the server's --map-memory).
  uint64_t memory_budget_bytes = uint64_t{2} << 30;
  // Background loader threads.
  int loader_threads = 1;
  // Their scheduling priority (the server's --tile-loader-priority): a tile load or composition
  // takes tens of milliseconds of CPU, which on a busy core delays the tracking steps queued
  // behind it (docs/benchmarks.md, 4.y).
  ThreadPriority loader_priority = ThreadPriority::kNormal;
  // Voxel size of the tiles' voxel visibility indexes, metres.
  double voxel_size_m = 0.25;
  // Use the tiles' keyframe visibility when they have it (else always voxels).
  bool keyframe_visibility = true;

  // Throws InvalidArgumentError unless the budget is > 0, 1 <= loader_threads <= 64 and the voxel
  // size is finite and > 0.
  void Check() const;
};

// Counters of a cache (monotonic unless said otherwise), for Prometheus.
struct TileCacheStats {
  // Find calls that found the tile resident.
  int64_t hits = 0;
  // Find calls that did not.
  int64_t misses = 0;
  // Tiles loaded (successfully).
  int64_t loads = 0;
  // Loads that failed (missing, damaged or mismatching tile files).
  int64_t load_failures = 0;
  // Total wall time of the loads, seconds, and the longest one.
  double load_seconds = 0;
  double max_load_seconds = 0;
  // Tiles evicted to meet the budget.
  int64_t evictions = 0;
  // Now: resident tiles and their bytes, of them held by some user, and loads queued or running.
  int64_t resident_tiles = 0;
  uint64_t resident_bytes = 0;
  int64_t tiles_in_use = 0;
  int64_t pending_loads = 0;
  // The budget.
  uint64_t budget_bytes = 0;
  // False when the kernel refused the loaders' priority (TileCacheOptions::loader_priority).
  bool loader_priority_applied = true;
};

// Thread-safe cache of loaded tiles, shared by every session of a server.
class TileCache {
 public:
  // Starts the loader threads. Throws InvalidArgumentError for invalid options.
  explicit TileCache(const TileCacheOptions& options = {});
  // Drops queued work and joins the loader threads (work already running finishes).
  ~TileCache();
  TileCache(const TileCache&) = delete;
  TileCache& operator=(const TileCache&) = delete;

  // The tile when it is resident (marked most recently used; counts a hit), else null (counts a
  // miss); `count` false counts neither (a user asking again for a tile it already missed).
  // Never reads a file.
  std::shared_ptr<const LoadedTile> Find(const Site& site, size_t tile, bool count = true);

  // Queues a background load of the tile unless it is resident, queued, loading, or its last load
  // failed for the same site version. Never reads a file.
  void Request(const std::shared_ptr<const Site>& site, size_t tile);

  // The tile, loaded on the calling thread when it is not resident (waiting for a load already
  // running instead of reading twice). For tools and session start-up. Throws IoError or
  // ParseError (the tile's, also a remembered failure) or InvalidArgumentError for a bad index.
  std::shared_ptr<const LoadedTile> Load(const std::shared_ptr<const Site>& site, size_t tile);

  // Runs `job` on a loader thread, after the work queued before it. `job` must not throw.
  void Post(std::function<void()> job);

  // Evicts unused tiles, least recently used first, while the resident bytes exceed the budget
  // (also done after every load; call it when users drop tiles).
  void Trim();

  // The counters.
  TileCacheStats stats() const;
  // The options.
  const TileCacheOptions& options() const { return options_; }

 private:
  struct Slot;
  using Key = std::pair<std::string, size_t>;

  // Loads into the slot of `key` (marked loading by the caller) and publishes the result.
  void LoadSlot(const std::shared_ptr<const Site>& site, size_t tile, const Key& key);
  // Evicts beyond the budget. Needs mutex_.
  void TrimLocked();
  // Body of a loader thread.
  void Run();

  TileCacheOptions options_;
  mutable std::mutex mutex_;
  std::condition_variable work_ready_;
  std::condition_variable load_done_;
  std::map<Key, Slot> slots_;
  // Resident tiles, most recently used first.
  std::list<Key> lru_;
  std::deque<std::function<void()>> queue_;
  bool stopping_ = false;
  TileCacheStats stats_;
  std::vector<std::thread> threads_;
};

}  // namespace evloc
