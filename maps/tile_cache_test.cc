#include "maps/tile_cache.h"

#include <gtest/gtest.h>

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <future>
#include <thread>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "maps/synthetic_map.h"

namespace evloc {
namespace {

class TileCacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = testing::MakeTempDir("tile_cache_test");
    CorridorMapOptions corridor;
    corridor.num_points = 6000;
    TilingOptions tiling;
    tiling.tile_size_m = 4;
    tiling.overlap_m = 0.5;
    TileMap(MakeCorridorMap(corridor), root_ / "site", tiling);
    site_ = OpenSite(root_ / "site");
    ASSERT_GE(site_->manifest.tiles.size(), 6u);
  }
  void TearDown() override { std::filesystem::remove_all(root_); }

  // The resident size of tile `t` (loaded in a cache of its own).
  uint64_t TileBytes(size_t t) {
    TileCache cache;
    return cache.Load(site_, t)->memory_bytes;
  }

  std::filesystem::path root_;
  std::shared_ptr<const Site> site_;
};

TEST_F(TileCacheTest, LoadedTilesAreSharedAndCounted) {
  TileCache cache;
  EXPECT_EQ(cache.Find(*site_, 0), nullptr);
  const auto first = cache.Load(site_, 0);
  const auto second = cache.Load(site_, 0);
  EXPECT_EQ(first.get(), second.get());
  EXPECT_EQ(cache.Find(*site_, 0).get(), first.get());
  const TileCacheStats stats = cache.stats();
  EXPECT_EQ(stats.loads, 1);
  EXPECT_EQ(stats.hits, 1);
  EXPECT_EQ(stats.misses, 1);
  EXPECT_EQ(stats.resident_tiles, 1);
  EXPECT_EQ(stats.resident_bytes, first->memory_bytes);
  EXPECT_EQ(stats.tiles_in_use, 1);
  EXPECT_TRUE(first->visibility->uses_keyframes());  // The corridor has keyframes.
  EXPECT_EQ(first->map.size(), site_->manifest.tiles[0].num_points);
}

TEST_F(TileCacheTest, RequestLoadsInTheBackground) {
  TileCache cache;
  cache.Request(site_, 2);
  cache.Request(site_, 2);  // Queued once.
  std::shared_ptr<const LoadedTile> tile;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (!(tile = cache.Find(*site_, 2, false)) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_NE(tile, nullptr);
  EXPECT_EQ(tile->tile, 2u);
  EXPECT_EQ(cache.stats().loads, 1);
  EXPECT_EQ(cache.stats().pending_loads, 0);
  EXPECT_GT(cache.stats().load_seconds, 0.0);
}

// The loader threads run at the priority asked for, and so does the work posted to them
// (compositions): SCHED_IDLE, or nice 19 where the kernel refuses the policy.
TEST_F(TileCacheTest, LoadersRunAtTheirPriority) {
  TileCacheOptions options;
  options.loader_priority = ThreadPriority::kIdle;
  TileCache cache(options);
  std::promise<std::pair<int, int>> seen;
  cache.Post([&seen] {
    int policy = 0;
    sched_param param{};
    pthread_getschedparam(pthread_self(), &policy, &param);
    seen.set_value({policy, getpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)))});
  });
  const std::pair<int, int> loader = seen.get_future().get();
  if (cache.stats().loader_priority_applied) {
    EXPECT_EQ(loader.first, SCHED_IDLE);
  } else {
    EXPECT_EQ(loader.second, 19);
  }
  int policy = 0;
  sched_param param{};
  pthread_getschedparam(pthread_self(), &policy, &param);
  EXPECT_NE(policy, SCHED_IDLE);  // The caller's own priority is untouched.
}

TEST_F(TileCacheTest, EvictsLeastRecentlyUsedUnusedTilesBeyondTheBudget) {
  TileCacheOptions options;
  // Room for about two tiles.
  options.memory_budget_bytes = TileBytes(0) + TileBytes(1) + TileBytes(2) / 2;
  TileCache cache(options);
  cache.Load(site_, 0);
  cache.Load(site_, 1);
  EXPECT_EQ(cache.stats().evictions, 0);
  cache.Load(site_, 2);  // Tile 0, the least recently used, goes.
  EXPECT_EQ(cache.stats().evictions, 1);
  EXPECT_EQ(cache.Find(*site_, 0), nullptr);
  EXPECT_NE(cache.Find(*site_, 1), nullptr);
  EXPECT_LE(cache.stats().resident_bytes, options.memory_budget_bytes);
}

TEST_F(TileCacheTest, TilesInUseAreNeverEvicted) {
  TileCacheOptions options;
  options.memory_budget_bytes = 1;  // Everything is over budget.
  TileCache cache(options);
  const auto held = cache.Load(site_, 0);
  cache.Load(site_, 1);
  cache.Load(site_, 2);
  EXPECT_NE(cache.Find(*site_, 0), nullptr);   // Held by this test.
  EXPECT_EQ(cache.Find(*site_, 1), nullptr);   // Dropped.
  EXPECT_EQ(cache.stats().resident_tiles, 2);  // The held one and the most recent.
  const LoadedTile* address = held.get();
  EXPECT_EQ(cache.Load(site_, 0).get(), address);
}

TEST_F(TileCacheTest, AFailedLoadIsRememberedAndReported) {
  const std::filesystem::path file = root_ / "site" / site_->manifest.tiles[3].file_name;
  {
    std::fstream stream(file, std::ios::in | std::ios::out | std::ios::binary);
    stream.seekp(100);
    stream.put('\x7f');
  }
  TileCache cache;
  EXPECT_THROW(cache.Load(site_, 3), ParseError);
  EXPECT_THROW(cache.Load(site_, 3), ParseError);  // Remembered, not read again.
  cache.Request(site_, 3);
  EXPECT_EQ(cache.stats().load_failures, 1);
  EXPECT_EQ(cache.stats().pending_loads, 0);
  EXPECT_THROW(cache.Load(site_, 99), InvalidArgumentError);
}

TEST_F(TileCacheTest, ConcurrentUsersLoadEachTileOnce) {
  TileCache cache;
  std::vector<std::thread> threads;
  for (int i = 0; i < 4; ++i) {
    threads.emplace_back([&] {
      for (size_t t = 0; t < site_->manifest.tiles.size(); ++t) {
        cache.Request(site_, t);
        cache.Load(site_, t);
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(cache.stats().loads, static_cast<int64_t>(site_->manifest.tiles.size()));
}

}  // namespace
}  // namespace evloc
