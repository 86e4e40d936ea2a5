#include "maps/map_directory.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <mutex>
#include <thread>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "maps/synthetic_map.h"

namespace evloc {
namespace {

class MapDirectoryTest : public ::testing::Test {
 protected:
  void SetUp() override { root_ = testing::MakeTempDir("map_directory_test"); }
  void TearDown() override { std::filesystem::remove_all(root_); }
  std::filesystem::path root_;
};

Map SmallMap(uint32_t seed) {
  CorridorMapOptions options;
  options.num_points = 500;
  options.num_keyframes = 3;
  options.seed = seed;
  return MakeCorridorMap(options);
}

TEST_F(MapDirectoryTest, WritesMapAndPlyIntoANewDirectory) {
  const std::filesystem::path directory = root_ / "nested" / "map";
  const Map map = SmallMap(1);
  WriteMapDirectory(directory, map);
  EXPECT_TRUE(std::filesystem::exists(directory / "map.ply"));
  EXPECT_EQ(ResolveMapFile(directory), directory / "map.evmap");
  EXPECT_EQ(ResolveMapFile(directory / "map.evmap"), directory / "map.evmap");
  EXPECT_EQ(LoadMap(ResolveMapFile(directory)).size(), 500u);
  // Only the two files: no staging leftovers.
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(directory),
                          std::filesystem::directory_iterator()),
            2);
}

TEST_F(MapDirectoryTest, RefusesToReplaceAMapUnlessAsked) {
  const std::filesystem::path directory = root_ / "map";
  WriteMapDirectory(directory, SmallMap(1));
  const std::string before = ReadFileToString(directory / "map.evmap");
  try {
    WriteMapDirectory(directory, SmallMap(2));
    ADD_FAILURE() << "replaced an existing map";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("already holds a map"), std::string::npos);
  }
  EXPECT_EQ(ReadFileToString(directory / "map.evmap"), before);
  MapDirectoryWriteOptions options;
  options.overwrite = true;
  WriteMapDirectory(directory, SmallMap(2), options);
  EXPECT_NE(ReadFileToString(directory / "map.evmap"), before);
  EXPECT_EQ(ComputeMapContentChecksum(LoadMap(directory / "map.evmap")),
            ComputeMapContentChecksum(SmallMap(2)));
}

TEST_F(MapDirectoryTest, InvalidMapLeavesNothingBehind) {
  const std::filesystem::path directory = root_ / "map";
  Map map = SmallMap(1);
  map.source_keyframe[0] = 99;
  EXPECT_THROW(WriteMapDirectory(directory, map), InvalidArgumentError);
  EXPECT_FALSE(std::filesystem::exists(directory));
}

// Finding 10 of issue 14: two writers of one map (same process, so the same PID) used the same
// staging name and broke each other's write; with unique staging names and the map's lock every
// write succeeds and the result is one of the written maps, with no staging file left.
TEST_F(MapDirectoryTest, ConcurrentWritersOfOneMapBothSucceed) {
  const std::filesystem::path directory = root_ / "map";
  const Map maps[2] = {SmallMap(1), SmallMap(2)};
  MapDirectoryWriteOptions options;
  options.overwrite = true;
  int failures = 0;
  std::mutex mutex;
  std::vector<std::thread> writers;
  for (int w = 0; w < 2; ++w) {
    writers.emplace_back([&, w] {
      for (int i = 0; i < 10; ++i) {
        try {
          WriteMapDirectory(directory, maps[w], options);
        } catch (const Error& error) {
          std::lock_guard<std::mutex> lock(mutex);
          ++failures;
          ADD_FAILURE() << error.what();
        }
      }
    });
  }
  for (std::thread& writer : writers) writer.join();
  EXPECT_EQ(failures, 0);
  const uint32_t crc = ComputeMapContentChecksum(LoadMap(directory / kMapFileName));
  EXPECT_TRUE(crc == ComputeMapContentChecksum(maps[0]) ||
              crc == ComputeMapContentChecksum(maps[1]));
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(directory),
                          std::filesystem::directory_iterator()),
            2);
  EXPECT_TRUE(std::filesystem::exists(MapDirectoryLockFile(directory)));
  EXPECT_EQ(MapDirectoryLockFile(root_ / "map/"), root_ / ".map.lock");
}

// A write removes the staging files of writers that were killed (their process is gone), and
// only those: a live process's staging file stays.
TEST_F(MapDirectoryTest, StagingFilesOfKilledWritersAreRemovedByTheNextWrite) {
  const std::filesystem::path directory = root_ / "map";
  WriteMapDirectory(directory, SmallMap(1));
  const pid_t child = fork();
  if (child == 0) _exit(0);
  ASSERT_GT(child, 0);
  waitpid(child, nullptr, 0);
  const std::string dead = std::to_string(child);
  const std::string live = std::to_string(getpid());
  const std::vector<std::string> stale = {".map.evmap.staging-" + dead + "-0-ab",
                                          "..map.evmap.staging-" + dead + "-1-cd.tmp-" + dead,
                                          ".map.ply.staging-" + dead + "-2-ef"};
  const std::vector<std::string> kept = {".map.evmap.staging-" + live + "-0-ab", "notes.txt"};
  for (const auto& name : stale) WriteFileAtomically(directory / name, "x");
  for (const auto& name : kept) WriteFileAtomically(directory / name, "x");
  MapDirectoryWriteOptions options;
  options.overwrite = true;
  WriteMapDirectory(directory, SmallMap(2), options);
  for (const auto& name : stale) EXPECT_FALSE(std::filesystem::exists(directory / name)) << name;
  for (const auto& name : kept) EXPECT_TRUE(std::filesystem::exists(directory / name)) << name;
}

TEST_F(MapDirectoryTest, DirectoryWithoutAMapIsAClearError) {
  try {
    ResolveMapFile(root_);
    ADD_FAILURE() << "resolved a directory without a map";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("without map.evmap"), std::string::npos);
  }
}

}  // namespace
}  // namespace evloc
