#include "localizer/tracking/tiled_map_source.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <tuple>
#include <utility>

#include "core/common/error.h"
#include "localizer/tracking/tracker.h"

namespace evloc::tracking {

struct TiledMapSource::Pending {
  std::mutex mutex;
  // The tiles being composed (manifest positions, ascending).
  std::vector<size_t> tile_ids;
  // Set by the loader thread when done.
  std::shared_ptr<const Composition> result;
};

namespace {

std::vector<size_t> IdsOf(const std::vector<std::shared_ptr<const LoadedTile>>& tiles) {
  std::vector<size_t> ids;
  ids.reserve(tiles.size());
  for (const auto& tile : tiles) ids.push_back(tile->tile);
  std::sort(ids.begin(), ids.end());
  return ids;
}

}  // namespace

void TileSelectionOptions::Check() const {
  for (const double value : {radius_m, lookahead_s, view_distance_m, release_margin_m}) {
    if (!std::isfinite(value) || value < 0) {
      throw InvalidArgumentError(
          "tile selection: radius_m, lookahead_s, view_distance_m and release_margin_m must be "
          "finite and >= 0");
    }
  }
}

TiledMapSource::TiledMapSource(std::shared_ptr<const Site> site, std::shared_ptr<TileCache> cache,
                               const TileSelectionOptions& options)
    : site_(std::move(site)), cache_(std::move(cache)), options_(options) {
  options_.Check();
  if (!site_ || !cache_) throw InvalidArgumentError("TiledMapSource: no site or no tile cache");
  current_ = Compose(*site_, {});
}

TiledMapSource::~TiledMapSource() {
  current_.reset();
  pending_.reset();
  cache_->Trim();
}

std::vector<size_t> TiledMapSource::NeededTiles(const Rigid3d& world_from_cam,
                                                const Eigen::Vector3d& velocity_world,
                                                double extra_m) const {
  const TileGrid& grid = site_->manifest.grid;
  const double radius = (options_.radius_m > 0 ? options_.radius_m : grid.tile_size_m) + extra_m;
  std::vector<Eigen::Vector2d> centres;
  const Eigen::Vector3d position = world_from_cam.translation;
  centres.emplace_back(position.head<2>());
  if (options_.lookahead_s > 0 && velocity_world.allFinite()) {
    centres.emplace_back((position + options_.lookahead_s * velocity_world).head<2>());
  }
  if (options_.view_distance_m > 0) {
    const Eigen::Vector3d axis = world_from_cam.rotation * Eigen::Vector3d::UnitZ();
    centres.emplace_back((position + options_.view_distance_m * axis).head<2>());
  }
  std::vector<size_t> needed;
  for (const Eigen::Vector2d& centre : centres) {
    if (!centre.allFinite()) continue;
    const TileIndex low = grid.IndexOf(centre.x() - radius, centre.y() - radius);
    const TileIndex high = grid.IndexOf(centre.x() + radius, centre.y() + radius);
    for (int64_t iy = low.iy; iy <= high.iy; ++iy) {
      for (int64_t ix = low.ix; ix <= high.ix; ++ix) {
        const TileIndex index{static_cast<int32_t>(ix), static_cast<int32_t>(iy)};
        const std::optional<size_t> found = site_->manifest.Find(index);
        if (!found) continue;
        if (grid.Core(index).DistanceTo(centre.x(), centre.y()) <= radius) {
          needed.push_back(*found);
        }
      }
    }
  }
  std::sort(needed.begin(), needed.end());
  needed.erase(std::unique(needed.begin(), needed.end()), needed.end());
  return needed;
}

std::vector<size_t> TiledMapSource::Wanted(const Rigid3d& world_from_cam,
                                           const Eigen::Vector3d& velocity_world,
                                           double extra_m) const {
  std::vector<size_t> wanted = NeededTiles(world_from_cam, velocity_world, extra_m);
  const double margin = options_.release_margin_m > 0 ? options_.release_margin_m
                                                      : 0.5 * site_->manifest.grid.tile_size_m;
  for (const size_t id : NeededTiles(world_from_cam, velocity_world, extra_m + margin)) {
    if (std::binary_search(current_->tile_ids.begin(), current_->tile_ids.end(), id)) {
      wanted.push_back(id);
    }
  }
  std::sort(wanted.begin(), wanted.end());
  wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
  return wanted;
}

std::vector<std::shared_ptr<const LoadedTile>> TiledMapSource::Gather(
    const std::vector<size_t>& needed, bool load_here) {
  std::vector<std::shared_ptr<const LoadedTile>> tiles;
  for (const size_t id : needed) {
    const auto composed = std::find(current_->tile_ids.begin(), current_->tile_ids.end(), id);
    if (composed != current_->tile_ids.end()) {
      tiles.push_back(current_->tiles[static_cast<size_t>(composed - current_->tile_ids.begin())]);
      continue;
    }
    if (load_here) {
      if (auto tile = cache_->Find(*site_, id)) {
        tiles.push_back(std::move(tile));
      } else {
        tiles.push_back(cache_->Load(site_, id));
      }
      continue;
    }
    // A tile this source is waiting for was counted as a miss when first asked.
    const bool waiting = pending_ && std::find(pending_->tile_ids.begin(), pending_->tile_ids.end(),
                                               id) != pending_->tile_ids.end();
    if (auto tile = cache_->Find(*site_, id, !waiting)) {
      tiles.push_back(std::move(tile));
    } else {
      cache_->Request(site_, id);
    }
  }
  return tiles;
}

void TiledMapSource::Install(std::shared_ptr<const Composition> composition) {
  current_ = std::move(composition);
  ++generation_;
  cache_->Trim();  // Tiles this source dropped may now be evictable.
}

bool TiledMapSource::Update(const Rigid3d& world_from_cam, const Eigen::Vector3d& velocity_world) {
  return UpdateWithin(world_from_cam, velocity_world, 0);
}

bool TiledMapSource::UpdateWithin(const Rigid3d& world_from_cam,
                                  const Eigen::Vector3d& velocity_world, double extra_m) {
  const std::vector<size_t> needed = Wanted(world_from_cam, velocity_world, extra_m);
  if (options_.synchronous) {
    std::vector<std::shared_ptr<const LoadedTile>> tiles = Gather(needed, true);
    if (IdsOf(tiles) == current_->tile_ids) return false;
    Install(Compose(*site_, std::move(tiles)));
    return true;
  }
  bool changed = false;
  if (pending_) {
    std::shared_ptr<const Composition> result;
    {
      std::lock_guard<std::mutex> lock(pending_->mutex);
      result = pending_->result;
    }
    if (result) {
      if (result->tile_ids != current_->tile_ids) {
        Install(std::move(result));
        changed = true;
      }
      pending_.reset();
    }
  }
  std::vector<std::shared_ptr<const LoadedTile>> tiles = Gather(needed, false);
  if (tiles.size() < needed.size()) {
    // Some needed tiles are still loading: keep what is composed meanwhile (tracking goes on with
    // it); the tiles no longer needed are dropped once every needed one is in.
    for (const auto& tile : current_->tiles) {
      if (!std::binary_search(needed.begin(), needed.end(), tile->tile)) tiles.push_back(tile);
    }
  }
  std::vector<size_t> ids = IdsOf(tiles);
  if (ids != current_->tile_ids && !pending_) {
    auto pending = std::make_shared<Pending>();
    pending->tile_ids = ids;
    // Remember which tiles were asked for (and missed) so they are not counted again.
    for (const size_t id : needed) {
      if (std::find(ids.begin(), ids.end(), id) == ids.end()) pending->tile_ids.push_back(id);
    }
    pending_ = pending;
    std::shared_ptr<const Site> site = site_;
    cache_->Post([pending, site, tiles = std::move(tiles)]() mutable {
      std::shared_ptr<const Composition> result = Compose(*site, std::move(tiles));
      std::lock_guard<std::mutex> lock(pending->mutex);
      pending->result = std::move(result);
    });
  }
  return changed;
}

void TiledMapSource::SetSearchRegion(const Eigen::Vector3d& center, double radius_m) {
  CheckSearchRegion(center, radius_m, "TiledMapSource::SetSearchRegion");
  search_center_ = center;
  search_radius_m_ = radius_m;
}

void TiledMapSource::ClearSearchRegion() {
  search_center_.reset();
  search_radius_m_ = 0;
}

bool TiledMapSource::Follow(const Tracker& tracker) {
  if (search_center_ && IsSearching(tracker.status())) {
    // The centre as a camera looking straight down (z up): the point ahead on its axis, if any,
    // stays over the centre.
    const Rigid3d over_center(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX())),
                              *search_center_);
    return UpdateWithin(over_center, Eigen::Vector3d::Zero(), search_radius_m_);
  }
  // A tracker that never had a pose has nothing to follow: no tile until a search region.
  if (!tracker.has_pose()) return false;
  const Rigid3d& world_from_cam = tracker.last_good_world_from_cam();
  const Eigen::Vector3d velocity_world = world_from_cam.rotation * tracker.velocity().head<3>();
  return Update(world_from_cam, velocity_world);
}

void TiledMapSource::LoadNow(const Rigid3d& world_from_cam) {
  const std::vector<size_t> needed = NeededTiles(world_from_cam, Eigen::Vector3d::Zero());
  std::vector<std::shared_ptr<const LoadedTile>> tiles = Gather(needed, true);
  pending_.reset();
  if (IdsOf(tiles) != current_->tile_ids) Install(Compose(*site_, std::move(tiles)));
}

std::vector<size_t> TiledMapSource::composed_tiles() const { return current_->tile_ids; }

MapPoints TiledMapSource::points() const { return {current_->positions, current_->gradients}; }

void TiledMapSource::VisibleCandidates(const Camera& camera, const Rigid3d& world_from_cam,
                                       const VisibilityQueryOptions& options,
                                       std::vector<uint32_t>* candidates) const {
  candidates->clear();
  const Eigen::Vector3d position = world_from_cam.translation;
  for (size_t t = 0; t < current_->tiles.size(); ++t) {
    const LoadedTile& tile = *current_->tiles[t];
    // A tile entirely beyond the depth range contributes nothing.
    if (tile.entry.padded.DistanceTo(position.x(), position.y()) > options.max_depth_m) continue;
    const std::vector<uint32_t>& composed = current_->composed_index[t];
    for (const uint32_t local : tile.visibility->Query(camera, world_from_cam, options)) {
      if (composed[local] != kNoKeyframe) candidates->push_back(composed[local]);
    }
  }
  // Tiles are composed in order and each one's points in order: already ascending.
}

void TiledMapSource::CandidateViewpoints(const ViewpointQuery& query,
                                         std::vector<Rigid3d>* world_from_cams) const {
  // Tiles share the keyframes that see several of them: each keyframe once.
  std::vector<std::pair<int64_t, Rigid3d>> keyframes;
  std::set<std::tuple<int64_t, double, double, double>> seen;
  for (const auto& tile : current_->tiles) {
    for (const Keyframe& keyframe : tile->map.keyframes) {
      const Rigid3d world_from_cam = keyframe.cam_from_world.Inverse();
      const Eigen::Vector3d& c = world_from_cam.translation;
      if (!seen.insert({keyframe.t_ns, c.x(), c.y(), c.z()}).second) continue;
      keyframes.emplace_back(keyframe.t_ns, world_from_cam);
    }
  }
  ViewpointsAlongKeyframes(std::move(keyframes), query, world_from_cams);
}

std::shared_ptr<const TiledMapSource::Composition> TiledMapSource::Compose(
    const Site& site, std::vector<std::shared_ptr<const LoadedTile>> tiles) {
  auto composition = std::make_shared<Composition>();
  std::sort(tiles.begin(), tiles.end(),
            [](const auto& a, const auto& b) { return a->tile < b->tile; });
  tiles.erase(std::unique(tiles.begin(), tiles.end(),
                          [](const auto& a, const auto& b) { return a->tile == b->tile; }),
              tiles.end());
  composition->tile_ids = IdsOf(tiles);
  const std::vector<size_t>& ids = composition->tile_ids;
  const SiteManifest& manifest = site.manifest;
  const TileGrid& grid = manifest.grid;
  const auto loaded = [&](TileIndex index) -> std::optional<size_t> {
    const std::optional<size_t> id = manifest.Find(index);
    if (!id || !std::binary_search(ids.begin(), ids.end(), *id)) return std::nullopt;
    return id;
  };
  size_t total = 0;
  for (const auto& tile : tiles) total += tile->map.size();
  composition->positions.reserve(total);
  composition->gradients.reserve(total);
  composition->composed_index.resize(tiles.size());
  for (size_t t = 0; t < tiles.size(); ++t) {
    const Map& map = tiles[t]->map;
    const TileIndex self = tiles[t]->entry.index;
    std::vector<uint32_t>& composed = composition->composed_index[t];
    composed.assign(map.size(), kNoKeyframe);
    for (size_t i = 0; i < map.size(); ++i) {
      const Eigen::Vector3f& p = map.positions[i];
      const TileIndex owner = grid.IndexOf(p.x(), p.y());
      bool take = owner == self;
      if (!take && !loaded(owner)) {
        // In the padding, owner not loaded: the first loaded tile holding it takes it. Tiles
        // holding it lie next to its owner (the overlap is below a tile).
        take = true;
        for (int dy = -1; dy <= 1 && take; ++dy) {
          for (int dx = -1; dx <= 1 && take; ++dx) {
            const TileIndex other{owner.ix + dx, owner.iy + dy};
            if (other == owner || other == self || !(other < self)) continue;
            if (loaded(other) && grid.Holds(other, p.x(), p.y())) take = false;
          }
        }
      }
      if (!take) continue;
      composed[i] = static_cast<uint32_t>(composition->positions.size());
      composition->positions.push_back(p);
      composition->gradients.push_back(map.gradients[i]);
    }
  }
  composition->tiles = std::move(tiles);
  return composition;
}

}  // namespace evloc::tracking
