#include "localizer/service/map_registry.h"

#include <gtest/gtest.h>

#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"

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

}  // namespace
}  // namespace evloc::service
