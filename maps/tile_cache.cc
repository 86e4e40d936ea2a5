#include "maps/tile_cache.h"

#include <chrono>
#include <cmath>
#include <exception>
#include <iterator>

#include "core/common/error.h"

namespace evloc {

struct TileCache::Slot {
  enum class State { kQueued, kLoading, kResident, kFailed };
  State state = State::kQueued;
  // The tile (kResident).
  std::shared_ptr<const LoadedTile> tile;
  // Where the tile is in lru_ (kResident).
  std::list<Key>::iterator lru_position;
  // The load's error (kFailed): not retried for this site version.
  std::exception_ptr error;
};

std::shared_ptr<const Site> OpenSite(const std::filesystem::path& directory) {
  auto site = std::make_shared<Site>();
  site->directory = directory;
  site->manifest = ReadSiteManifest(directory);
  std::error_code error;
  const std::filesystem::path absolute = std::filesystem::absolute(directory, error);
  site->key =
      (error ? directory : absolute).lexically_normal().string() + "@" + site->manifest.version;
  return site;
}

void TileCacheOptions::Check() const {
  if (memory_budget_bytes == 0) {
    throw InvalidArgumentError(
        "tile cache: the memory budget is 0 bytes; give at least one tile's");
  }
  if (loader_threads < 1 || loader_threads > 64) {
    throw InvalidArgumentError("tile cache: loader_threads must be in 1..64, got " +
                               std::to_string(loader_threads));
  }
  if (!std::isfinite(voxel_size_m) || voxel_size_m <= 0) {
    throw InvalidArgumentError("tile cache: the voxel size must be a positive number of metres");
  }
}

TileCache::TileCache(const TileCacheOptions& options) : options_(options) {
  options_.Check();
  stats_.budget_bytes = options_.memory_budget_bytes;
  stats_.loader_priority_applied = StartThreadsAtPriority(
      options_.loader_threads, options_.loader_priority, [this](int) { Run(); }, &threads_);
}

TileCache::~TileCache() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    queue_.clear();
  }
  work_ready_.notify_all();
  for (std::thread& thread : threads_) thread.join();
}

void TileCache::Run() {
  for (;;) {
    std::function<void()> job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      work_ready_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      job = std::move(queue_.front());
      queue_.pop_front();
    }
    job();
  }
}

void TileCache::Post(std::function<void()> job) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    queue_.push_back(std::move(job));
  }
  work_ready_.notify_one();
}

std::shared_ptr<const LoadedTile> TileCache::Find(const Site& site, size_t tile, bool count) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto found = slots_.find(Key{site.key, tile});
  if (found == slots_.end() || found->second.state != Slot::State::kResident) {
    if (count) ++stats_.misses;
    return nullptr;
  }
  if (count) ++stats_.hits;
  lru_.splice(lru_.begin(), lru_, found->second.lru_position);
  return found->second.tile;
}

void TileCache::Request(const std::shared_ptr<const Site>& site, size_t tile) {
  if (tile >= site->manifest.tiles.size()) return;
  const Key key{site->key, tile};
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (slots_.count(key) != 0) return;  // Resident, queued, loading or failed.
    slots_[key].state = Slot::State::kQueued;
    ++stats_.pending_loads;
    queue_.push_back([this, site, tile, key] { LoadSlot(site, tile, key); });
  }
  work_ready_.notify_one();
}

void TileCache::LoadSlot(const std::shared_ptr<const Site>& site, size_t tile, const Key& key) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    Slot& slot = slots_[key];
    if (slot.state != Slot::State::kQueued) return;  // Loaded meanwhile by Load.
    slot.state = Slot::State::kLoading;
  }
  const auto start = std::chrono::steady_clock::now();
  std::shared_ptr<LoadedTile> loaded;
  std::exception_ptr error;
  try {
    loaded = std::make_shared<LoadedTile>();
    loaded->tile = tile;
    loaded->entry = site->manifest.tiles[tile];
    loaded->map = LoadTile(site->directory, site->manifest, tile);
    VisibilityIndexOptions visibility;
    visibility.voxel_size_m = options_.voxel_size_m;
    visibility.use_keyframes = options_.keyframe_visibility;
    loaded->visibility = std::make_unique<VisibilityIndex>(loaded->map, visibility);
    loaded->memory_bytes = MapMemoryBytes(loaded->map);
  } catch (const Error&) {
    error = std::current_exception();
  } catch (const std::bad_alloc&) {
    error = std::make_exception_ptr(IoError("not enough memory to load tile '" +
                                            site->manifest.tiles[tile].file_name + "' of site " +
                                            site->manifest.name));
  } catch (const std::exception& unexpected) {
    error = std::make_exception_ptr(IoError(
        "cannot load tile '" + site->manifest.tiles[tile].file_name + "': " + unexpected.what()));
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    Slot& slot = slots_[key];
    --stats_.pending_loads;
    if (error) {
      slot.state = Slot::State::kFailed;
      slot.error = error;
      ++stats_.load_failures;
    } else {
      slot.state = Slot::State::kResident;
      slot.tile = std::move(loaded);
      lru_.push_front(key);
      slot.lru_position = lru_.begin();
      ++stats_.loads;
      ++stats_.resident_tiles;
      stats_.resident_bytes += slot.tile->memory_bytes;
      stats_.load_seconds += seconds;
      stats_.max_load_seconds = std::max(stats_.max_load_seconds, seconds);
      TrimLocked();
    }
  }
  load_done_.notify_all();
}

std::shared_ptr<const LoadedTile> TileCache::Load(const std::shared_ptr<const Site>& site,
                                                  size_t tile) {
  if (tile >= site->manifest.tiles.size()) {
    throw InvalidArgumentError("tile cache: tile " + std::to_string(tile) + " of a site with " +
                               std::to_string(site->manifest.tiles.size()) + " tiles");
  }
  const Key key{site->key, tile};
  bool load_here = false;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    auto found = slots_.find(key);
    if (found == slots_.end()) {
      slots_[key].state = Slot::State::kQueued;
      ++stats_.pending_loads;
      load_here = true;
    } else if (found->second.state == Slot::State::kQueued) {
      load_here = true;  // LoadSlot sees it loading (or loaded) and skips the queued job.
    }
  }
  if (load_here) LoadSlot(site, tile, key);
  std::unique_lock<std::mutex> lock(mutex_);
  load_done_.wait(lock, [&] {
    const auto found = slots_.find(key);
    return found == slots_.end() || found->second.state == Slot::State::kResident ||
           found->second.state == Slot::State::kFailed;
  });
  const auto found = slots_.find(key);
  if (found == slots_.end()) {
    lock.unlock();
    return Load(site, tile);  // Evicted before this thread woke: load it again.
  }
  Slot& slot = found->second;
  if (slot.state == Slot::State::kFailed) std::rethrow_exception(slot.error);
  lru_.splice(lru_.begin(), lru_, slot.lru_position);
  return slot.tile;
}

void TileCache::Trim() {
  std::lock_guard<std::mutex> lock(mutex_);
  TrimLocked();
}

void TileCache::TrimLocked() {
  if (stats_.resident_bytes <= options_.memory_budget_bytes) return;
  // The most recently used tile stays (it was just loaded or asked for), even when it alone
  // exceeds the budget.
  for (auto it = lru_.end(); it != lru_.begin() && std::next(lru_.begin()) != lru_.end() &&
                             stats_.resident_bytes > options_.memory_budget_bytes;) {
    --it;
    if (it == lru_.begin()) break;
    const auto found = slots_.find(*it);
    // Only the cache holds an unused tile.
    if (found->second.tile.use_count() > 1) continue;
    stats_.resident_bytes -= found->second.tile->memory_bytes;
    --stats_.resident_tiles;
    ++stats_.evictions;
    slots_.erase(found);
    it = lru_.erase(it);
  }
}

TileCacheStats TileCache::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  TileCacheStats stats = stats_;
  stats.tiles_in_use = 0;
  for (const Key& key : lru_) {
    if (slots_.at(key).tile.use_count() > 1) ++stats.tiles_in_use;
  }
  return stats;
}

}  // namespace evloc
