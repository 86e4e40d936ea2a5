#include "localizer/service/map_registry.h"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cstring>
#include <fstream>
#include <thread>

#include "core/common/file_util.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "maps/crc32c.h"
#include "maps/map_directory.h"

namespace evloc::service {
namespace {

TEST(MapRegistry, LoadsOnFirstUseAndSharesOneCopy) {
  testing::TemporaryFolder folder;
  const Map map = testing::TestMap();
  testing::WriteTestMap(folder.path(), "room", map);
  std::filesystem::create_directories(folder.path() / "empty_folder");
  MapRegistry registry(MapRegistryOptions{folder.path()});
  EXPECT_EQ(registry.ListNames(), std::vector<std::string>{"room"});
  EXPECT_EQ(registry.loads(), 0);
  const auto first = registry.Get("room");
  const auto second = registry.Get("room");
  EXPECT_EQ(first.get(), second.get());
  EXPECT_EQ(registry.loads(), 1);
  EXPECT_EQ(first->map.size(), map.size());
  EXPECT_EQ(first->version, MapVersionString(ComputeMapContentChecksum(map)));
  EXPECT_EQ(first->version.size(), 8u);
  EXPECT_EQ(registry.Get("room", first->version).get(), first.get());
}

TEST(MapRegistry, UnknownNamesAndVersionsAreNotFound) {
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), "room", testing::TestMap());
  MapRegistry registry(MapRegistryOptions{folder.path()});
  EXPECT_THROW(registry.Get("hall"), MapNotFoundError);
  EXPECT_THROW(registry.Get("../room"), MapNotFoundError);
  EXPECT_THROW(registry.Get(""), MapNotFoundError);
  EXPECT_THROW(registry.Get("room", std::string("00000000")), MapNotFoundError);
  EXPECT_THROW(MapRegistry(MapRegistryOptions{folder.path() / "missing"}), InvalidArgumentError);
}

TEST(MapRegistry, NewVersionServesNewSessionsAndKeepsTheOldOneAlive) {
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), "room", testing::TestMap());
  MapRegistry registry(MapRegistryOptions{folder.path()});
  const auto old_version = registry.Get("room");
  const size_t old_points = old_version->map.size();

  const Map coarser =
      tracking::testing::MakeRectangleMap(tracking::testing::DefaultRectangles(), 0.02);
  testing::WriteTestMap(folder.path(), "room", coarser);
  const auto new_version = registry.Get("room");
  EXPECT_NE(new_version->version, old_version->version);
  EXPECT_EQ(new_version->map.size(), coarser.size());
  EXPECT_EQ(registry.loads(), 2);
  // The running session's copy is untouched.
  EXPECT_EQ(old_version->map.size(), old_points);
  EXPECT_THROW(registry.Get("room", old_version->version), MapNotFoundError);

  // A broken file dropped in place does not stop the service: the last good version stays.
  std::filesystem::resize_file(folder.path() / "room" / "map.evmap", 100);
  EXPECT_EQ(registry.Get("room")->version, new_version->version);
}

// Rewrites the header of map `name` in `folder` to declare a payload of `payload_bytes` (with a
// valid header checksum) and extends the file sparsely to match: a crafted map whose header
// passes every check and whose load asks for that much memory.
void CraftHugePayloadMap(const std::filesystem::path& folder, const std::string& name,
                         uint64_t payload_bytes) {
  const std::filesystem::path file = folder / name / kMapFileName;
  std::string header = ReadFileToString(file).substr(0, kMapFileHeaderSize);
  std::memcpy(header.data() + 16, &payload_bytes, sizeof(payload_bytes));
  const uint32_t header_crc = Crc32c(std::string_view(header).substr(0, 24));
  std::memcpy(header.data() + 24, &header_crc, sizeof(header_crc));
  const std::filesystem::path staging = folder / name / ".crafted";
  {
    std::ofstream out(staging, std::ios::binary);
    out.write(header.data(), static_cast<std::streamsize>(header.size()));
  }
  std::filesystem::resize_file(staging, kMapFileHeaderSize + payload_bytes);
  std::filesystem::rename(staging, file);
}

// Finding 5 of issue 14: a crafted map whose load throws something other than an evloc Error
// (here std::bad_alloc: 1.5 GiB asked under a 1 GiB address-space limit) must come out of the
// registry as a typed Error, and must not stop the last good version from being served. Run in
// a child process (the limit is per process). Exit codes: 0 good, 1 an untyped exception
// escaped, 2 the last good version was not served, 3 no error.
TEST(MapRegistryDeathTest, CraftedMapThatExhaustsMemoryIsATypedErrorAndTheLastGoodVersionStays) {
  ::testing::GTEST_FLAG(death_test_style) = "threadsafe";
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), "room", testing::TestMap());
  testing::WriteTestMap(folder.path(), "hall", testing::TestMap());
  CraftHugePayloadMap(folder.path(), "hall", uint64_t{3} << 29);
  const auto run = [&] {
    MapRegistry registry(MapRegistryOptions{folder.path()});
    const auto good = registry.Get("room");
    const rlimit limit{rlim_t{1} << 30, rlim_t{1} << 30};
    if (setrlimit(RLIMIT_AS, &limit) != 0) _exit(4);
    try {
      registry.Get("hall");
      _exit(3);
    } catch (const MapLoadError&) {
    } catch (...) {
      _exit(1);
    }
    CraftHugePayloadMap(folder.path(), "room", uint64_t{3} << 29);
    try {
      if (registry.Get("room").get() != good.get()) _exit(2);
    } catch (...) {
      _exit(1);
    }
    _exit(0);
  };
  EXPECT_EXIT(run(), ::testing::ExitedWithCode(0), "");
}

// Finding 7: a file whose load failed is not read again until it changes.
TEST(MapRegistry, FailedLoadIsNotRetriedUntilTheFileChanges) {
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), "room", testing::TestMap());
  const std::filesystem::path file = folder.path() / "room" / kMapFileName;
  std::string bytes = ReadFileToString(file);
  bytes[bytes.size() / 2] ^= 0x55;  // Payload checksum mismatch.
  WriteFileAtomically(file, bytes);
  MapRegistry registry(MapRegistryOptions{folder.path()});
  for (int i = 0; i < 3; ++i) EXPECT_THROW(registry.Get("room"), ParseError);
  EXPECT_THROW(registry.Describe("room"), ParseError);
  EXPECT_EQ(registry.load_attempts(), 1);
  EXPECT_EQ(registry.loads(), 0);
  testing::WriteTestMap(folder.path(), "room", testing::TestMap());
  EXPECT_EQ(registry.Get("room")->map.size(), testing::TestMap().size());
  EXPECT_EQ(registry.load_attempts(), 2);
}

// Finding 7: concurrent requests for one map version load it once and share it.
TEST(MapRegistry, ConcurrentRequestsLoadAVersionOnce) {
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), "room", testing::TestMap());
  MapRegistry registry(MapRegistryOptions{folder.path()});
  std::vector<std::shared_ptr<const LoadedMap>> maps(8);
  std::vector<std::thread> threads;
  for (size_t i = 0; i < maps.size(); ++i) {
    threads.emplace_back([&, i] { maps[i] = registry.Get("room"); });
  }
  for (std::thread& thread : threads) thread.join();
  for (const auto& map : maps) EXPECT_EQ(map.get(), maps[0].get());
  EXPECT_EQ(registry.loads(), 1);
  EXPECT_EQ(registry.load_attempts(), 1);
}

// Finding 6: the cache keeps the maps within the budget, least recently used out first, and a
// map dropped from it stays valid for whoever holds it.
TEST(MapRegistry, CacheEvictsLeastRecentlyUsedBeyondTheBudget) {
  testing::TemporaryFolder folder;
  const Map map = testing::TestMap();
  for (const char* name : {"a", "b", "c"}) testing::WriteTestMap(folder.path(), name, map);
  MapRegistryOptions options{folder.path()};
  options.max_map_memory_bytes = 2 * MapMemoryBytes(LoadMap(folder.path() / "a" / kMapFileName));
  MapRegistry registry(options);
  const auto a = registry.Get("a");
  EXPECT_EQ(a->memory_bytes, MapMemoryBytes(a->map));
  registry.Get("b");
  EXPECT_EQ(registry.cached_maps(), 2u);
  registry.Get("a");  // a is now the most recently used: c evicts b.
  registry.Get("c");
  EXPECT_EQ(registry.cached_maps(), 2u);
  EXPECT_LE(registry.cached_bytes(), options.max_map_memory_bytes);
  EXPECT_EQ(registry.loads(), 3);
  EXPECT_EQ(registry.Get("a").get(), a.get());
  EXPECT_EQ(registry.loads(), 3);
  registry.Get("b");  // Reloaded: evicts c.
  EXPECT_EQ(registry.loads(), 4);
  registry.Get("c");  // Reloaded: evicts a, which its holder keeps.
  EXPECT_EQ(registry.loads(), 5);
  EXPECT_EQ(a->map.size(), map.size());
  EXPECT_NE(registry.Get("a").get(), a.get());
  MapRegistryOptions zero{folder.path()};
  zero.max_map_memory_bytes = 0;
  EXPECT_THROW(zero.Check(), InvalidArgumentError);
}

// Finding 5, after eviction: the last good version of a map left the cache, then its file was
// overwritten in place by one that does not load (a non-atomic copy, cut short). With a keep
// folder the registry serves the kept copy of that version; without one, the error.
TEST(MapRegistry, AKeptCopyServesTheLastGoodVersionAfterItLeftTheCacheAndTheFileBroke) {
  testing::TemporaryFolder folder;
  testing::TemporaryFolder keep;
  const Map map = testing::TestMap();
  for (const char* name : {"room", "hall"}) testing::WriteTestMap(folder.path(), name, map);
  const std::filesystem::path room_file = folder.path() / "room" / kMapFileName;
  const std::string good_bytes = ReadFileToString(room_file);
  const auto break_room = [&] {  // In place: same inode, so a hard link would break too.
    std::ofstream out(room_file, std::ios::binary | std::ios::trunc);
    out << good_bytes.substr(0, good_bytes.size() / 2);
  };
  const auto run = [&](bool with_keep) -> std::string {
    WriteFileAtomically(room_file, good_bytes);
    MapRegistryOptions options{folder.path()};
    options.max_map_memory_bytes = 1;  // Only the most recently used map stays.
    std::vector<std::string> warnings;
    if (with_keep) options.keep_dir = keep.path();
    options.warn = [&](const std::string& line) { warnings.push_back(line); };
    MapRegistry registry(options);
    const std::string good_version = registry.Get("room")->version;
    registry.Get("hall");
    EXPECT_EQ(registry.cached_maps(), 1u);
    break_room();
    const auto served = registry.Get("room");
    EXPECT_EQ(served->version, good_version);
    EXPECT_EQ(served->map.size(), map.size());
    EXPECT_EQ(registry.kept_restores(), 1);
    EXPECT_EQ(registry.Get("room").get(), served.get());  // Not read again.
    EXPECT_EQ(registry.load_attempts(), 3);
    EXPECT_EQ(registry.Describe("room").version, good_version);
    EXPECT_EQ(warnings.size(), 1u);
    if (!warnings.empty()) {
      EXPECT_NE(warnings[0].find("serving its last good version " + good_version),
                std::string::npos)
          << warnings[0];
    }
    // A good new file is served again as usual.
    const Map coarser =
        tracking::testing::MakeRectangleMap(tracking::testing::DefaultRectangles(), 0.02);
    testing::WriteTestMap(folder.path(), "room", coarser);
    EXPECT_EQ(registry.Get("room")->map.size(), coarser.size());
    return good_version;
  };
  const std::string good_version = run(true);
  EXPECT_TRUE(std::filesystem::exists(keep.path() / "room.evmap"));

  // Without a keep folder the broken file is an error once the good version left the cache.
  {
    WriteFileAtomically(room_file, good_bytes);
    MapRegistryOptions options{folder.path()};
    options.max_map_memory_bytes = 1;
    MapRegistry registry(options);
    registry.Get("room");
    registry.Get("hall");
    break_room();
    EXPECT_THROW(registry.Get("room"), ParseError);
    EXPECT_EQ(registry.kept_restores(), 0);
  }

  // A kept copy that does not load either: the file's error, tried once per file version.
  {
    WriteFileAtomically(room_file, good_bytes);
    MapRegistryOptions options{folder.path()};
    options.max_map_memory_bytes = 1;
    options.keep_dir = keep.path();
    int warnings = 0;
    options.warn = [&](const std::string&) { ++warnings; };
    MapRegistry registry(options);
    EXPECT_EQ(registry.Get("room")->version, good_version);
    registry.Get("hall");
    std::filesystem::resize_file(keep.path() / "room.evmap", 64);
    break_room();
    EXPECT_THROW(registry.Get("room"), ParseError);
    EXPECT_THROW(registry.Get("room"), ParseError);
    EXPECT_EQ(registry.kept_restores(), 0);
    EXPECT_EQ(warnings, 1);
  }

  // The keep folder is checked.
  MapRegistryOptions options{folder.path()};
  options.keep_dir = keep.path() / "missing";
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options.keep_dir = folder.path();
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

// Finding 6: ListMaps' descriptions come from the file's summary without loading the map, and
// equal the loaded map's.
TEST(MapRegistry, DescribesAMapWithoutLoadingIt) {
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path(), "room", testing::TestMap());
  MapRegistry registry(MapRegistryOptions{folder.path()});
  const MapDescriptionData described = registry.Describe("room");
  EXPECT_EQ(registry.loads(), 0);
  EXPECT_EQ(registry.load_attempts(), 0);
  const auto loaded = registry.Get("room");
  EXPECT_EQ(described.version, loaded->version);
  EXPECT_EQ(described.summary.info.content_crc32c, loaded->content_crc32c);
  EXPECT_EQ(described.summary.file_bytes, loaded->file_bytes);
  EXPECT_EQ(described.summary.info.num_points, loaded->info.num_points);
  EXPECT_EQ(described.summary.info.num_keyframes, loaded->info.num_keyframes);
  EXPECT_EQ(described.summary.info.bounding_box_min, loaded->info.bounding_box_min);
  EXPECT_EQ(described.summary.info.bounding_box_max, loaded->info.bounding_box_max);
  EXPECT_THROW(registry.Describe("hall"), MapNotFoundError);
}

}  // namespace
}  // namespace evloc::service
