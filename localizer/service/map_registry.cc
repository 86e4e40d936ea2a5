#include "localizer/service/map_registry.h"

#include <cstdio>
#include <system_error>

#include "maps/map_directory.h"

namespace evloc::service {
namespace {

// A map name is one path component: no separators, not "." or "..", not hidden.
bool IsValidMapName(const std::string& name) {
  if (name.empty() || name.front() == '.') return false;
  return name.find('/') == std::string::npos && name.find('\\') == std::string::npos;
}

}  // namespace

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
}

MapRegistry::MapRegistry(MapRegistryOptions options) : options_(std::move(options)) {
  options_.Check();
}

std::vector<std::string> MapRegistry::ListNames() const {
  std::vector<std::string> names;
  std::error_code error;
  for (const auto& entry : std::filesystem::directory_iterator(options_.maps_dir, error)) {
    const std::string name = entry.path().filename().string();
    if (!IsValidMapName(name)) continue;
    std::error_code file_error;
    if (std::filesystem::is_regular_file(entry.path() / kMapFileName, file_error)) {
      names.push_back(name);
    }
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::shared_ptr<const LoadedMap> MapRegistry::Get(const std::string& name,
                                                  const std::optional<std::string>& version) {
  if (!IsValidMapName(name)) {
    throw MapNotFoundError("no map named '" + name + "' (see ListMaps)");
  }
  const std::filesystem::path file = options_.maps_dir / name / kMapFileName;
  std::error_code error;
  const uint64_t file_bytes = std::filesystem::file_size(file, error);
  const bool exists = !error;
  const auto file_time =
      exists ? std::filesystem::last_write_time(file, error) : std::filesystem::file_time_type();

  std::lock_guard<std::mutex> lock(mutex_);
  auto found = current_.find(name);
  if (!exists && found == current_.end()) {
    throw MapNotFoundError("no map named '" + name + "' in " + options_.maps_dir.string() +
                           " (see ListMaps)");
  }
  const bool changed =
      found == current_.end() || (exists && (found->second->file_bytes != file_bytes ||
                                             found->second->file_time != file_time));
  if (changed && exists) {
    try {
      auto loaded = std::make_shared<LoadedMap>();
      loaded->name = name;
      loaded->map = LoadMap(file);
      loaded->info = SummarizeMap(loaded->map);
      loaded->content_crc32c = loaded->info.content_crc32c;
      loaded->version = MapVersionString(loaded->content_crc32c);
      loaded->file_bytes = file_bytes;
      loaded->file_time = file_time;
      loaded->visibility = std::make_unique<VisibilityIndex>(loaded->map);
      ++loads_;
      found = current_.insert_or_assign(name, std::move(loaded)).first;
    } catch (const Error&) {
      if (found == current_.end()) throw;
      // Keep serving the version already loaded.
    }
  }
  if (version && !version->empty() && *version != found->second->version) {
    throw MapNotFoundError("map '" + name + "' has no version '" + *version +
                           "' (current version " + found->second->version + ")");
  }
  return found->second;
}

int64_t MapRegistry::loads() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return loads_;
}

}  // namespace evloc::service
