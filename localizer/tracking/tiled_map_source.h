// A site of tiles as the tracker's MapSource (docs/tracking.md, "Tiled map source"): the union
// of the loaded tiles near the camera and ahead of it along its velocity. Between two calls into
// the tracker, Update chooses the tiles the pose needs, asks the server-wide TileCache for them
// (loads run on the cache's loader threads) and, when the set of loaded tiles changed, composes
// the new union on a loader thread too; the next Update after the composition is ready swaps it
// in and changes the generation. So a tracking step never waits for a file or a copy, and a
// session whose tiles are not loaded yet keeps tracking on what is loaded: while a needed tile is
// missing, the composed tiles stay and the loaded needed ones join them; once every needed tile
// is in, the composition is exactly the needed tiles. Points in overlaps are
// not doubled: a tile contributes the points it owns (its core square) and, of its padding, only
// those whose owner tile is not loaded (the first loaded tile holding such a point takes it).
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include "localizer/tracking/map_source.h"
#include "maps/tile_cache.h"

namespace evloc::tracking {

class Tracker;

// Which tiles a pose needs.
struct TileSelectionOptions {
  // Tiles whose core square is within this distance of the camera centre, metres; 0: one tile
  // size (the tile under the camera and its neighbours as the camera nears them).
  double radius_m = 0;
  // Also the tiles within radius_m of where the camera will be this far ahead at its current
  // velocity, seconds.
  double lookahead_s = 2.0;
  // Also the tiles within radius_m of the point this far ahead along the optical axis, metres
  // (0: none); what a camera looking far sees.
  double view_distance_m = 0;
  // A composed tile stays while it is within radius_m + this of a centre, metres; 0: half a tile
  // size. The hysteresis keeps a tile at the edge of the radius from coming and going with
  // every small motion.
  double release_margin_m = 0;
  // Load and compose on the calling thread (evloc-track, tests): every Update ends with every
  // needed tile loaded and composed, so the poses do not depend on timing.
  bool synchronous = false;

  // Throws InvalidArgumentError unless the distances, the margin and the lookahead are finite
  // and >= 0.
  void Check() const;
};

// The union of a site's loaded tiles. Not thread-safe (like the tracker it feeds); its background
// work holds only what it needs, so the source may be destroyed while a composition runs.
class TiledMapSource final : public MapSource {
 public:
  // Over `site`, with tiles from `cache` (both shared, kept alive). Throws InvalidArgumentError
  // for invalid options. Holds no tile until the first Update.
  TiledMapSource(std::shared_ptr<const Site> site, std::shared_ptr<TileCache> cache,
                 const TileSelectionOptions& options = {});
  ~TiledMapSource() override;

  // Chooses the tiles for a camera at `world_from_cam` moving at `velocity_world` (m/s, world
  // frame), requests the missing ones and swaps in a finished composition. Call it between calls
  // into the tracker only. Returns true when the generation changed. Synchronous sources throw
  // the tile's IoError or ParseError when a needed tile cannot be loaded; asynchronous ones keep
  // serving what is loaded (the cache remembers the failure and counts it).
  bool Update(const Rigid3d& world_from_cam, const Eigen::Vector3d& velocity_world);

  // Update from the tracker's last good pose and its velocity (rotated into the world frame);
  // while the tracker searches and a search region is set, from the region instead; nothing for
  // a tracker that never had a pose and no region.
  bool Follow(const Tracker& tracker);
  // Where a tracker without a pose searches (a GNSS fix and its radius, world frame): while it
  // searches, Follow composes the tiles within radius_m (plus the selection radius) of `center`
  // in the x-y plane, so that a session that starts without a pose on a site has the tiles near
  // its fix to search. Throws InvalidArgumentError for a non-finite centre or a radius that is
  // not positive.
  void SetSearchRegion(const Eigen::Vector3d& center, double radius_m);
  // Removes the search region: a searching tracker's tiles follow its last good pose again.
  void ClearSearchRegion();

  // Waits until the composition of every tile needed at `world_from_cam` is in place (loading
  // them on the calling thread), for session start-up. Throws like a synchronous Update.
  void LoadNow(const Rigid3d& world_from_cam);

  // The tiles (positions in the manifest, ascending) needed at this pose and velocity: within
  // radius_m (plus `extra_m`) of the camera centre, of where it will be, and of the point ahead
  // on its optical axis.
  std::vector<size_t> NeededTiles(const Rigid3d& world_from_cam,
                                  const Eigen::Vector3d& velocity_world, double extra_m = 0) const;
  // The tiles (positions in the manifest, ascending) of the current composition.
  std::vector<size_t> composed_tiles() const;
  // The site.
  const Site& site() const { return *site_; }

  uint64_t generation() const override { return generation_; }
  MapPoints points() const override;
  // Each composed tile's visibility query, restricted to the points it contributes, in the
  // composed indices (ascending).
  void VisibleCandidates(const Camera& camera, const Rigid3d& world_from_cam,
                         const VisibilityQueryOptions& options,
                         std::vector<uint32_t>* candidates) const override;
  // The keyframes of the composed tiles (each once), with poses interpolated between consecutive
  // ones.
  void CandidateViewpoints(const ViewpointQuery& query,
                           std::vector<Rigid3d>* world_from_cams) const override;

  // The union of `tiles` (resident tiles of `site`, any order): exposed for tests.
  struct Composition;
  static std::shared_ptr<const Composition> Compose(
      const Site& site, std::vector<std::shared_ptr<const LoadedTile>> tiles);

 private:
  // Composition work handed to a loader thread and its result.
  struct Pending;

  // The needed tiles (NeededTiles with `extra_m`), and the composed ones within the release
  // margin.
  std::vector<size_t> Wanted(const Rigid3d& world_from_cam, const Eigen::Vector3d& velocity_world,
                             double extra_m) const;
  // Update with the needed tiles reaching `extra_m` further.
  bool UpdateWithin(const Rigid3d& world_from_cam, const Eigen::Vector3d& velocity_world,
                    double extra_m);
  // Requests/loads the needed tiles; returns the resident ones.
  std::vector<std::shared_ptr<const LoadedTile>> Gather(const std::vector<size_t>& needed,
                                                        bool load_here);
  // Swaps in `composition` (a new generation).
  void Install(std::shared_ptr<const Composition> composition);

  std::shared_ptr<const Site> site_;
  std::shared_ptr<TileCache> cache_;
  TileSelectionOptions options_;
  std::shared_ptr<const Composition> current_;
  std::shared_ptr<Pending> pending_;
  uint64_t generation_ = 0;
  // The search region (SetSearchRegion), if any.
  std::optional<Eigen::Vector3d> search_center_;
  double search_radius_m_ = 0;
};

// The composed arrays of a TiledMapSource generation.
struct TiledMapSource::Composition {
  // The tiles composed, by manifest position (ascending).
  std::vector<std::shared_ptr<const LoadedTile>> tiles;
  // Per composed tile, per tile point: its composed index, or kNoKeyframe when another tile
  // contributes it.
  std::vector<std::vector<uint32_t>> composed_index;
  // The composed points.
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Vector3f> gradients;
  // Their tile positions (manifest) as a set, for comparisons.
  std::vector<size_t> tile_ids;
};

}  // namespace evloc::tracking
