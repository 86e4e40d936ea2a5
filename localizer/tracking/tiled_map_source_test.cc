#include "localizer/tracking/tiled_map_source.h"

#include <gtest/gtest.h>

#include <chrono>
#include <map>
#include <set>
#include <thread>
#include <tuple>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "maps/synthetic_map.h"

namespace evloc::tracking {
namespace {

using Position = std::tuple<float, float, float>;

std::multiset<Position> PositionsOf(const MapPoints& points) {
  std::multiset<Position> positions;
  for (const Eigen::Vector3f& p : points.positions) positions.insert({p.x(), p.y(), p.z()});
  return positions;
}

class TiledMapSourceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = evloc::testing::MakeTempDir("tiled_map_source_test");
    CorridorMapOptions corridor;
    corridor.num_points = 8000;
    corridor.length_m = 20;
    map_ = MakeCorridorMap(corridor);
    TilingOptions tiling;
    tiling.tile_size_m = 2;
    tiling.overlap_m = 0.5;
    TileMap(map_, root_ / "site", tiling);
    site_ = OpenSite(root_ / "site");
    cache_ = std::make_shared<TileCache>();
  }
  void TearDown() override { std::filesystem::remove_all(root_); }

  std::vector<std::shared_ptr<const LoadedTile>> Load(const std::vector<size_t>& tiles) {
    std::vector<std::shared_ptr<const LoadedTile>> loaded;
    for (const size_t t : tiles) loaded.push_back(cache_->Load(site_, t));
    return loaded;
  }

  std::filesystem::path root_;
  Map map_;
  std::shared_ptr<const Site> site_;
  std::shared_ptr<TileCache> cache_;
};

TEST_F(TiledMapSourceTest, AllTilesComposeToTheWholeMapWithNoPointTwice) {
  std::vector<size_t> all(site_->manifest.tiles.size());
  for (size_t t = 0; t < all.size(); ++t) all[t] = t;
  const auto composition = TiledMapSource::Compose(*site_, Load(all));
  MapPoints points{composition->positions, composition->gradients};
  EXPECT_EQ(points.size(), map_.size());
  EXPECT_EQ(PositionsOf(points), PositionsOf(MapPoints{map_.positions, map_.gradients}));
}

TEST_F(TiledMapSourceTest, PaddingFillsInForMissingNeighboursOnlyOnce) {
  // Every other tile along the corridor: each takes its core and the borders of its missing
  // neighbours, a border point held by two loaded tiles' paddings is taken once.
  std::vector<size_t> some;
  for (size_t t = 0; t < site_->manifest.tiles.size(); t += 2) some.push_back(t);
  const auto composition = TiledMapSource::Compose(*site_, Load(some));
  std::set<Position> expected;
  for (const size_t t : some) {
    const Map tile = LoadTile(site_->directory, site_->manifest, t);
    for (const Eigen::Vector3f& p : tile.positions) expected.insert({p.x(), p.y(), p.z()});
  }
  const std::multiset<Position> composed =
      PositionsOf(MapPoints{composition->positions, composition->gradients});
  EXPECT_EQ(composed.size(), expected.size());                                // No point twice...
  EXPECT_EQ(std::set<Position>(composed.begin(), composed.end()), expected);  // ...none missing.
  EXPECT_LT(composed.size(), map_.size());
}

TEST_F(TiledMapSourceTest, VisibleCandidatesAreTheVisiblePointsOfTheComposition) {
  TileSelectionOptions options;
  options.synchronous = true;
  options.radius_m = 30;  // Every tile.
  TileCacheOptions voxels;
  voxels.keyframe_visibility = false;
  TiledMapSource source(site_, std::make_shared<TileCache>(voxels), options);
  const Rigid3d pose = CorridorCameraPose(3.0);
  EXPECT_TRUE(source.Update(pose, Eigen::Vector3d::Zero()));
  ASSERT_EQ(source.composed_tiles().size(), site_->manifest.tiles.size());
  const Camera camera = CorridorMapOptions{}.camera;
  VisibilityQueryOptions query;
  query.max_depth_m = 6;
  std::vector<uint32_t> candidates;
  source.VisibleCandidates(camera, pose, query, &candidates);
  EXPECT_TRUE(std::is_sorted(candidates.begin(), candidates.end()));
  // The same as the voxel index (exact: it equals a brute-force test) of the composed points.
  const MapPoints points = source.points();
  Map composed;
  for (size_t i = 0; i < points.size(); ++i) {
    composed.AddPoint(points.positions[i], points.gradients[i]);
  }
  const VisibilityIndex whole(composed);
  EXPECT_EQ(candidates, whole.Query(camera, pose, query));
  EXPECT_GT(candidates.size(), 100u);
  // Keyframes of every tile are viewpoints.
  std::vector<Rigid3d> viewpoints;
  ViewpointQuery viewpoint_query;
  viewpoint_query.samples_between_keyframes = 0;
  source.CandidateViewpoints(viewpoint_query, &viewpoints);
  EXPECT_EQ(viewpoints.size(), map_.keyframes.size());
}

TEST_F(TiledMapSourceTest, SelectsTheTilesNearTheCameraAndAheadOfIt) {
  TileSelectionOptions options;
  options.radius_m = 1;
  options.lookahead_s = 2;
  TiledMapSource source(site_, cache_, options);
  const auto index_of = [&](size_t t) { return site_->manifest.tiles[t].index; };
  std::set<int> columns;
  for (const size_t t : source.NeededTiles(CorridorCameraPose(5.0), Eigen::Vector3d::Zero())) {
    columns.insert(index_of(t).ix);
  }
  // x in [4, 6]: the core squares [4, 6) and [6, 8) (at distance 0 and 1 m).
  EXPECT_EQ(columns, (std::set<int>{2, 3}));
  columns.clear();
  for (const size_t t :
       source.NeededTiles(CorridorCameraPose(5.0), Eigen::Vector3d(3, 0, 0))) {  // 6 m ahead.
    columns.insert(index_of(t).ix);
  }
  EXPECT_EQ(columns, (std::set<int>{2, 3, 5, 6}));  // And [10, 12), [12, 14) around x = 11.
}

TEST_F(TiledMapSourceTest, AsynchronousUpdatesKeepServingWhatIsLoadedUntilTheNewTilesAreIn) {
  TileSelectionOptions options;
  options.radius_m = 1;
  options.lookahead_s = 0;
  TiledMapSource source(site_, cache_, options);
  source.LoadNow(CorridorCameraPose(3.0));
  const uint64_t first = source.generation();
  const std::vector<size_t> at_three = source.composed_tiles();
  ASSERT_FALSE(at_three.empty());
  const size_t points_at_three = source.points().size();
  // The camera jumps to x = 15: nothing there is loaded. The first update only asks for it.
  const Rigid3d far = CorridorCameraPose(15.0);
  EXPECT_FALSE(source.Update(far, Eigen::Vector3d::Zero()));
  EXPECT_EQ(source.generation(), first);
  EXPECT_EQ(source.points().size(), points_at_three);
  // Later updates swap in the loaded tiles (a new generation) without waiting in Update.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  const std::vector<size_t> needed = source.NeededTiles(far, Eigen::Vector3d::Zero());
  while (source.composed_tiles() != needed && std::chrono::steady_clock::now() < deadline) {
    // Meanwhile the tiles at x = 3 stay, joined by those at x = 15 as they come in.
    const std::vector<size_t> composed = source.composed_tiles();
    for (const size_t t : at_three) {
      EXPECT_TRUE(std::binary_search(composed.begin(), composed.end(), t));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    const auto start = std::chrono::steady_clock::now();
    source.Update(far, Eigen::Vector3d::Zero());
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(50));
  }
  EXPECT_GT(source.generation(), first);
  EXPECT_EQ(source.composed_tiles(), source.NeededTiles(far, Eigen::Vector3d::Zero()));
  for (const Eigen::Vector3f& p : source.points().positions) EXPECT_GT(p.x(), 12.0f);
  const TileCacheStats stats = cache_->stats();
  EXPECT_EQ(stats.load_failures, 0);
  EXPECT_GE(stats.misses, static_cast<int64_t>(source.composed_tiles().size()));
}

TEST_F(TiledMapSourceTest, InvalidOptionsAreRefused) {
  TileSelectionOptions options;
  options.radius_m = -1;
  EXPECT_THROW(TiledMapSource(site_, cache_, options), InvalidArgumentError);
  options = {};
  options.lookahead_s = std::nan("");
  EXPECT_THROW(TiledMapSource(site_, cache_, options), InvalidArgumentError);
  EXPECT_THROW(TiledMapSource(site_, nullptr), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::tracking
