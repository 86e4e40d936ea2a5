#include "localizer/service/map_registry.h"

#include <algorithm>
#include <cstdio>
#include <future>
#include <new>
#include <system_error>

#include "core/common/file_util.h"
#include "maps/map_directory.h"
#include "maps/site.h"

namespace evloc::service {

struct MapRegistry::Load {
  // The file version being (or that was) loaded.
  FileStamp stamp;
  // The loaded map, or the load's evloc Error (the negative cache when kept in the entry).
  std::shared_future<std::shared_ptr<const LoadedMap>> result;
};

namespace {

// A map name is one path component: no separators, not "." or "..", not hidden.
bool IsValidMapName(const std::string& name) {
  if (name.empty() || name.front() == '.') return false;
  return name.find('/') == std::string::npos && name.find('\\') == std::string::npos;
}

// Runs `read` (which reads map `name`), letting evloc Errors through and turning anything else
// (std::bad_alloc from a forged size, an unexpected exception) into a MapLoadError.
template <typename Read>
auto WithTypedErrors(const std::string& name, const Read& read) -> decltype(read()) {
  try {
    return read();
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    throw MapLoadError("not enough memory to load map '" + name +
                       "'; check the file (it may be corrupt) or give the server more memory");
  } catch (const std::exception& error) {
    throw MapLoadError("cannot load map '" + name + "': " + error.what());
  } catch (...) {
    throw MapLoadError("cannot load map '" + name + "': unknown error");
  }
}

// A loaded map of `name` from `map`, with what describes it and its visibility index;
// `file_bytes` and `file_time` are the file version it stands for.
std::shared_ptr<const LoadedMap> MakeLoadedMap(const std::string& name, uint64_t file_bytes,
                                               std::filesystem::file_time_type file_time, Map map) {
  auto loaded = std::make_shared<LoadedMap>();
  loaded->name = name;
  loaded->file_bytes = file_bytes;
  loaded->file_time = file_time;
  loaded->map = std::move(map);
  loaded->info = SummarizeMap(loaded->map);
  loaded->content_crc32c = loaded->info.content_crc32c;
  loaded->version = MapVersionString(loaded->content_crc32c);
  loaded->visibility = std::make_unique<VisibilityIndex>(loaded->map);
  loaded->memory_bytes = MapMemoryBytes(loaded->map);
  return loaded;
}

// True when `load` finished with an error (the negative cache).
bool Failed(const std::shared_future<std::shared_ptr<const LoadedMap>>& result) {
  if (result.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return false;
  try {
    result.get();
    return false;
  } catch (...) {
    return true;
  }
}

}  // namespace

MapDescriptionData DescribeLoadedMap(const LoadedMap& map) {
  MapDescriptionData description;
  description.name = map.name;
  description.version = map.version;
  description.summary.file_bytes = map.file_bytes;
  description.summary.info = map.info;
  return description;
}

std::string MapVersionString(uint32_t content_crc32c) {
  char text[16];
  std::snprintf(text, sizeof(text), "%08x", content_crc32c);
  return text;
}

void MapRegistryOptions::Check() const {
  if (maps_dir.empty()) throw InvalidArgumentError("map registry: the map folder is not set");
  std::error_code error;
  if (!std::filesystem::is_directory(maps_dir, error)) {
    throw InvalidArgumentError("map registry: '" + maps_dir.string() +
                               "' is not a directory (give a folder with one subdirectory per "
                               "map, each holding map.evmap)");
  }
  if (max_map_memory_bytes == 0 || max_tile_memory_bytes == 0) {
    throw InvalidArgumentError(
        "map registry: the map memory budget is 0 bytes; give at least the size of one map");
  }
  if (tile_loader_threads < 1 || tile_loader_threads > 64) {
    throw InvalidArgumentError("map registry: the tile loader threads must be in 1..64");
  }
  if (!keep_dir.empty()) {
    if (!std::filesystem::is_directory(keep_dir, error)) {
      throw InvalidArgumentError("map registry: the folder for kept map versions '" +
                                 keep_dir.string() + "' is not a directory (create it first)");
    }
    if (std::filesystem::equivalent(keep_dir, maps_dir, error)) {
      throw InvalidArgumentError(
          "map registry: the folder for kept map versions must not be the map folder itself");
    }
  }
}

namespace {

TileCacheOptions TileCacheOptionsOf(const MapRegistryOptions& options) {
  options.Check();
  TileCacheOptions tiles;
  tiles.memory_budget_bytes = options.max_tile_memory_bytes;
  tiles.loader_threads = options.tile_loader_threads;
  tiles.loader_priority = options.tile_loader_priority;
  return tiles;
}

}  // namespace

MapRegistry::MapRegistry(MapRegistryOptions options)
    : options_(std::move(options)),
      tiles_(std::make_shared<TileCache>(TileCacheOptionsOf(options_))) {}

std::vector<std::string> MapRegistry::ListNames() const {
  std::vector<std::string> names;
  std::error_code error;
  for (auto it = std::filesystem::directory_iterator(options_.maps_dir, error);
       !error && it != std::filesystem::directory_iterator(); it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (!IsValidMapName(name)) continue;
    std::error_code file_error;
    if (std::filesystem::is_regular_file(it->path() / kMapFileName, file_error) ||
        IsSiteDirectory(it->path())) {
      names.push_back(name);
    }
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::optional<MapRegistry::FileStamp> MapRegistry::Stamp(const std::string& name) const {
  FileStamp stamp;
  stamp.site = IsSiteDirectory(options_.maps_dir / name);
  const std::filesystem::path file =
      options_.maps_dir / name / (stamp.site ? kSiteManifestFileName : kMapFileName);
  std::error_code error;
  stamp.bytes = std::filesystem::file_size(file, error);
  if (error) return std::nullopt;
  stamp.time = std::filesystem::last_write_time(file, error);
  if (error) return std::nullopt;
  return stamp;
}

std::shared_ptr<const LoadedMap> MapRegistry::LoadVersion(const std::string& name,
                                                          const FileStamp& stamp) {
  return WithTypedErrors(name, [&]() -> std::shared_ptr<const LoadedMap> {
    if (stamp.site) {
      auto loaded = std::make_shared<LoadedMap>();
      loaded->name = name;
      loaded->file_bytes = stamp.bytes;
      loaded->file_time = stamp.time;
      loaded->site = OpenSite(options_.maps_dir / name);
      loaded->tiles = tiles_;
      loaded->info = SummarizeSite(loaded->site->manifest);
      // Its sessions report geodetic poses and take GNSS fixes through the site's anchor.
      loaded->map.geo_anchor = loaded->info.geo_anchor;
      loaded->content_crc32c = loaded->info.content_crc32c;
      loaded->version = loaded->site->manifest.version;
      // The manifest; the tiles count against the tile cache's budget.
      loaded->memory_bytes = sizeof(Site) + loaded->site->manifest.tiles.size() * sizeof(SiteTile);
      return std::shared_ptr<const LoadedMap>(std::move(loaded));
    }
    const std::filesystem::path file = options_.maps_dir / name / kMapFileName;
    // The header first (a file that is not a map is refused before it is read whole), then the
    // bytes, parsed from memory so that the copy kept is exactly what was verified.
    ReadMapFileHeader(file);
    const std::string bytes = ReadFileToString(file);
    std::shared_ptr<const LoadedMap> map =
        MakeLoadedMap(name, stamp.bytes, stamp.time, LoadMapFromBytes(bytes, file.string()));
    Keep(*map, bytes);
    return map;
  });
}

std::filesystem::path MapRegistry::KeptFile(const std::string& name) const {
  return options_.keep_dir / (name + ".evmap");
}

void MapRegistry::Warn(const std::string& line) const {
  if (options_.warn) options_.warn(line);
}

void MapRegistry::Keep(const LoadedMap& map, const std::string& bytes) {
  if (options_.keep_dir.empty()) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (entries_[map.name].kept_version == map.version) return;
  }
  try {
    WriteFileAtomically(KeptFile(map.name), bytes);
  } catch (const Error& error) {
    // Serving goes on; only the fallback for a later bad file is missing.
    Warn("map '" + map.name + "' version " + map.version +
         ": cannot keep a copy to serve if its file stops loading: " + error.what());
    return;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  entries_[map.name].kept_version = map.version;
}

std::shared_ptr<const LoadedMap> MapRegistry::RestoreKept(const std::string& name,
                                                          const FileStamp& failed,
                                                          const std::string& error) {
  const auto current = [&]() -> std::shared_ptr<const LoadedMap> {
    Entry& entry = entries_[name];
    if (!entry.current) return nullptr;
    lru_.splice(lru_.begin(), lru_, entry.lru_position);
    return entry.current;
  };
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (auto map = current()) return map;
    if (options_.keep_dir.empty() || failed.site) return nullptr;
  }
  std::lock_guard<std::mutex> restore_lock(restore_mutex_);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (auto map = current()) return map;  // Restored by another request meanwhile.
    if (entries_[name].kept_failed_for == failed) return nullptr;
  }
  const std::filesystem::path kept = KeptFile(name);
  std::error_code exists_error;
  if (!std::filesystem::exists(kept, exists_error)) return nullptr;
  std::shared_ptr<const LoadedMap> map;
  try {
    // The failed file's version: the kept copy is what is served while that file stays.
    map = WithTypedErrors(
        name, [&] { return MakeLoadedMap(name, failed.bytes, failed.time, LoadMap(kept)); });
  } catch (const Error& kept_error) {
    Warn("map '" + name + "': its file does not load (" + error +
         ") and neither does its kept copy: " + kept_error.what());
    std::lock_guard<std::mutex> lock(mutex_);
    entries_[name].kept_failed_for = failed;
    return nullptr;
  }
  Warn("map '" + name + "': its file does not load (" + error +
       "); serving its last good version " + map->version + " from the kept copy");
  std::lock_guard<std::mutex> lock(mutex_);
  ++loads_;
  ++kept_restores_;
  Entry& entry = entries_[name];
  entry.kept_version = map->version;
  InsertLocked(entry, map);
  return map;
}

void MapRegistry::InsertLocked(Entry& entry, std::shared_ptr<const LoadedMap> map) {
  if (entry.current) {
    cached_bytes_ -= entry.current->memory_bytes;
    --cached_maps_;
    lru_.erase(entry.lru_position);
  }
  cached_bytes_ += map->memory_bytes;
  ++cached_maps_;
  lru_.push_front(map->name);
  entry.lru_position = lru_.begin();
  entry.current = std::move(map);
  while (cached_bytes_ > options_.max_map_memory_bytes && lru_.size() > 1) {
    Entry& oldest = entries_[lru_.back()];
    cached_bytes_ -= oldest.current->memory_bytes;
    --cached_maps_;
    oldest.current.reset();  // Sessions holding it keep it alive.
    lru_.pop_back();
  }
}

std::shared_ptr<const LoadedMap> MapRegistry::Get(const std::string& name,
                                                  const std::optional<std::string>& version) {
  if (!IsValidMapName(name)) {
    throw MapNotFoundError("no map named '" + name + "' (see ListMaps)");
  }
  const std::optional<FileStamp> stamp = Stamp(name);
  const auto check_version = [&](std::shared_ptr<const LoadedMap> map) {
    if (version && !version->empty() && *version != map->version) {
      throw MapNotFoundError("map '" + name + "' has no version '" + *version +
                             "' (current version " + map->version + ")");
    }
    return map;
  };
  std::shared_ptr<Load> load;
  std::promise<std::shared_ptr<const LoadedMap>> promise;
  bool loader = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto found = entries_.find(name);
    Entry* entry = found == entries_.end() ? nullptr : &found->second;
    if (!stamp) {
      if (entry == nullptr || !entry->current) {
        throw MapNotFoundError("no map named '" + name + "' in " + options_.maps_dir.string() +
                               " (see ListMaps)");
      }
      lru_.splice(lru_.begin(), lru_, entry->lru_position);
      return check_version(entry->current);
    }
    if (entry == nullptr) entry = &entries_[name];
    if (entry->current && entry->current->file_bytes == stamp->bytes &&
        entry->current->file_time == stamp->time) {
      lru_.splice(lru_.begin(), lru_, entry->lru_position);
      return check_version(entry->current);
    }
    if (entry->load && entry->load->stamp == *stamp) {
      load = entry->load;  // Being loaded by another request, or failed (negative cache).
    } else {
      load = std::make_shared<Load>();
      load->stamp = *stamp;
      load->result = promise.get_future().share();
      entry->load = load;
      loader = true;
      ++load_attempts_;
    }
  }
  if (loader) {
    // File I/O and parsing without the registry's lock.
    try {
      std::shared_ptr<const LoadedMap> map = LoadVersion(name, load->stamp);
      {
        std::lock_guard<std::mutex> lock(mutex_);
        ++loads_;
        Entry& entry = entries_[name];
        InsertLocked(entry, map);
        if (entry.load == load) entry.load.reset();  // Only failures stay as a negative cache.
      }
      promise.set_value(std::move(map));
    } catch (...) {
      promise.set_exception(std::current_exception());
    }
  }
  try {
    return check_version(load->result.get());
  } catch (const MapNotFoundError&) {
    throw;
  } catch (const Error& error) {
    // Keep serving the version already loaded, or the kept copy of the last good one.
    if (auto map = RestoreKept(name, load->stamp, error.what())) return check_version(map);
    throw;
  }
}

MapDescriptionData MapRegistry::Describe(const std::string& name) {
  if (!IsValidMapName(name)) {
    throw MapNotFoundError("no map named '" + name + "' (see ListMaps)");
  }
  const std::optional<FileStamp> stamp = Stamp(name);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto found = entries_.find(name);
    const Entry* entry = found == entries_.end() ? nullptr : &found->second;
    if (entry != nullptr && entry->current &&
        (!stamp || (entry->current->file_bytes == stamp->bytes &&
                    entry->current->file_time == stamp->time))) {
      return DescribeLoadedMap(*entry->current);
    }
    if (!stamp) {
      throw MapNotFoundError("no map named '" + name + "' in " + options_.maps_dir.string() +
                             " (see ListMaps)");
    }
    if (entry != nullptr && entry->load && entry->load->stamp == *stamp &&
        Failed(entry->load->result)) {
      if (entry->current) return DescribeLoadedMap(*entry->current);
      entry->load->result.get();  // Throws the load's error.
    }
    if (entry != nullptr && entry->description && entry->described == *stamp) {
      return *entry->description;
    }
  }
  MapDescriptionData description;
  description.name = name;
  if (stamp->site) {
    const SiteManifest manifest =
        WithTypedErrors(name, [&] { return ReadSiteManifest(options_.maps_dir / name); });
    description.summary.info = SummarizeSite(manifest);
    description.summary.file_bytes = stamp->bytes;
    description.version = manifest.version;
  } else {
    description.summary = WithTypedErrors(
        name, [&] { return ReadMapFileSummary(options_.maps_dir / name / kMapFileName); });
    description.version = MapVersionString(description.summary.info.content_crc32c);
  }
  std::lock_guard<std::mutex> lock(mutex_);
  Entry& entry = entries_[name];
  entry.description = description;
  entry.described = *stamp;
  return description;
}

int64_t MapRegistry::loads() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return loads_;
}

int64_t MapRegistry::load_attempts() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return load_attempts_;
}

uint64_t MapRegistry::cached_bytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return cached_bytes_;
}

size_t MapRegistry::cached_maps() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return cached_maps_;
}

int64_t MapRegistry::kept_restores() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return kept_restores_;
}

}  // namespace evloc::service
