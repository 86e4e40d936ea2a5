#include "maps/map_directory.h"

#include <gtest/gtest.h>

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
