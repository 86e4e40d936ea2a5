#include "maps/site.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <set>
#include <tuple>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "evloc/map.pb.h"
#include "maps/map_directory.h"
#include "maps/synthetic_map.h"

namespace evloc {
namespace {

using Position = std::tuple<float, float, float>;

Position Key(const Eigen::Vector3f& p) { return {p.x(), p.y(), p.z()}; }

// A corridor 20 m long down x, 2 m wide in y, z up, with relocalization data: every 50th point is
// a landmark, each keyframe sees the landmarks it lists.
Map MakeSiteTestMap() {
  CorridorMapOptions options;
  options.num_points = 4000;
  options.num_keyframes = 8;
  Map map = MakeCorridorMap(options);
  RelocalizationData data;
  data.vocabulary.assign(2 * kRelocalizationDescriptorBytes, 0.5f);
  std::map<uint32_t, uint32_t> landmark_of_point;
  for (uint32_t i = 0; i < map.size(); i += 50) {
    landmark_of_point[i] = static_cast<uint32_t>(data.landmarks.size());
    data.landmarks.push_back(map.positions[i]);
  }
  for (const Keyframe& keyframe : map.keyframes) {
    KeyframeFeatures features;
    for (const uint32_t point : keyframe.visible_points) {
      const auto found = landmark_of_point.find(point);
      if (found == landmark_of_point.end()) continue;
      features.keypoints.emplace_back(static_cast<float>(point % 640), 10.0f);
      features.landmarks.push_back(found->second);
      for (size_t b = 0; b < kRelocalizationDescriptorBytes; ++b) {
        features.descriptors.push_back(static_cast<uint8_t>((point + b) & 0xff));
      }
    }
    features.global_descriptor.assign(data.vocabulary.size(), 0.0f);
    data.keyframes.push_back(std::move(features));
  }
  map.relocalization = std::move(data);
  map.Check();
  return map;
}

class SiteTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = testing::MakeTempDir("site_test");
    map_ = MakeSiteTestMap();
    options_.tile_size_m = 5;
    options_.overlap_m = 1;
    manifest_ = TileMap(map_, root_ / "site", options_);
  }
  void TearDown() override { std::filesystem::remove_all(root_); }

  std::filesystem::path root_;
  Map map_;
  TilingOptions options_;
  SiteManifest manifest_;
};

TEST_F(SiteTest, EveryPointLandsInTheTileThatOwnsIt) {
  // x in [0, 20], y in [-1, 1]: origin (0, -5), tiles ix 0..4 (x = 20 is owned by ix 4), iy 0..1.
  EXPECT_EQ(manifest_.grid.origin_x, 0.0);
  EXPECT_EQ(manifest_.grid.origin_y, -5.0);
  ASSERT_GE(manifest_.tiles.size(), 8u);
  uint64_t core_points = 0;
  std::vector<std::set<Position>> tile_points;
  for (size_t t = 0; t < manifest_.tiles.size(); ++t) {
    const Map tile = LoadTile(root_ / "site", manifest_, t);
    std::set<Position> points;
    for (const Eigen::Vector3f& p : tile.positions) points.insert(Key(p));
    tile_points.push_back(std::move(points));
    core_points += manifest_.tiles[t].num_core_points;
  }
  EXPECT_EQ(core_points, map_.size());
  for (const Eigen::Vector3f& p : map_.positions) {
    const TileIndex owner = manifest_.grid.IndexOf(p.x(), p.y());
    const std::optional<size_t> tile = manifest_.Find(owner);
    ASSERT_TRUE(tile.has_value()) << "no tile for the owner of a point";
    EXPECT_EQ(tile_points[*tile].count(Key(p)), 1u);
    const TileRectangle core = manifest_.tiles[*tile].core;
    EXPECT_TRUE(p.x() >= core.min_x && p.x() < core.max_x && p.y() >= core.min_y &&
                p.y() < core.max_y);
  }
}

TEST_F(SiteTest, OverlapsHoldTheNeighboursBorderPoints) {
  bool some_border_point = false;
  for (size_t t = 0; t < manifest_.tiles.size(); ++t) {
    const SiteTile& entry = manifest_.tiles[t];
    const Map tile = LoadTile(root_ / "site", manifest_, t);
    std::set<Position> held;
    for (const Eigen::Vector3f& p : tile.positions) held.insert(Key(p));
    size_t expected = 0;
    for (const Eigen::Vector3f& p : map_.positions) {
      const bool in_padding = p.x() >= entry.padded.min_x && p.x() < entry.padded.max_x &&
                              p.y() >= entry.padded.min_y && p.y() < entry.padded.max_y;
      const bool owned = manifest_.grid.IndexOf(p.x(), p.y()) == entry.index;
      if (!in_padding && !owned) continue;
      ++expected;
      EXPECT_EQ(held.count(Key(p)), 1u);
      if (!owned) some_border_point = true;
    }
    EXPECT_EQ(tile.size(), expected);
    EXPECT_EQ(entry.num_points, expected);
  }
  EXPECT_TRUE(some_border_point);
}

TEST_F(SiteTest, ManifestCountsAndChecksumsAgreeWithTheTiles) {
  const SiteManifest read = ReadSiteManifest(root_ / "site");
  EXPECT_EQ(read.version, SiteVersionOf(read.tiles));
  EXPECT_EQ(read.name, "site");
  EXPECT_EQ(read.source_content_crc32c, ComputeMapContentChecksum(map_));
  ASSERT_EQ(read.tiles.size(), manifest_.tiles.size());
  uint64_t keyframes = 0;
  for (size_t t = 0; t < read.tiles.size(); ++t) {
    const SiteTile& entry = read.tiles[t];
    const std::filesystem::path file = root_ / "site" / entry.file_name;
    EXPECT_EQ(std::filesystem::file_size(file), entry.file_bytes);
    const Map tile = LoadMap(file);
    EXPECT_EQ(ComputeMapContentChecksum(tile), entry.content_crc32c);
    EXPECT_EQ(tile.size(), entry.num_points);
    EXPECT_EQ(tile.keyframes.size(), entry.num_keyframes);
    keyframes += entry.num_core_keyframes;
    EXPECT_GE(entry.num_keyframes, entry.num_core_keyframes);
  }
  EXPECT_EQ(keyframes, map_.keyframes.size());
}

TEST_F(SiteTest, TilesKeepTheirKeyframesFeaturesAndLandmarks) {
  size_t features_kept = 0;
  for (size_t t = 0; t < manifest_.tiles.size(); ++t) {
    const Map tile = LoadTile(root_ / "site", manifest_, t);
    ASSERT_TRUE(tile.relocalization.has_value());
    ASSERT_EQ(tile.relocalization->keyframes.size(), tile.keyframes.size());
    EXPECT_EQ(tile.relocalization->vocabulary, map_.relocalization->vocabulary);
    for (size_t k = 0; k < tile.keyframes.size(); ++k) {
      const Keyframe& keyframe = tile.keyframes[k];
      const Eigen::Vector3d centre = keyframe.cam_from_world.Inverse().translation;
      // Its camera is in the tile, or it sees one of the tile's points.
      EXPECT_TRUE(manifest_.grid.IndexOf(centre.x(), centre.y()) == manifest_.tiles[t].index ||
                  !keyframe.visible_points.empty());
      // Every visible point is a tile point the original keyframe listed.
      for (const uint32_t point : keyframe.visible_points) ASSERT_LT(point, tile.size());
      const KeyframeFeatures& features = tile.relocalization->keyframes[k];
      for (const uint32_t landmark : features.landmarks) {
        const Eigen::Vector3f& p = tile.relocalization->landmarks[landmark];
        EXPECT_TRUE(manifest_.grid.Holds(manifest_.tiles[t].index, p.x(), p.y()));
      }
      features_kept += features.landmarks.size();
    }
    for (size_t i = 0; i < tile.size(); ++i) {
      if (tile.source_keyframe[i] != kNoKeyframe) {
        ASSERT_LT(tile.source_keyframe[i], tile.keyframes.size());
      }
    }
  }
  EXPECT_GT(features_kept, 0u);
}

// A geo-referenced map gives a geo-referenced site: the manifest carries the map's anchor, and
// every tile (a self-contained map) carries it too.
TEST_F(SiteTest, TheMapsGeoAnchorGoesIntoTheManifestAndEveryTile) {
  EXPECT_TRUE(manifest_.geo_anchor.empty());
  Map anchored = map_;
  GeoAnchor anchor;
  anchor.origin.latitude_deg = 46.5191;
  anchor.origin.longitude_deg = 6.5668;
  anchor.origin.altitude_m = 372.5;
  anchor.horizontal_sigma_m = 0.02;
  anchored.geo_anchor = anchor;
  const SiteManifest manifest = TileMap(anchored, root_ / "anchored", options_);
  map_format::GeoAnchor carried;
  ASSERT_TRUE(carried.ParseFromString(ReadSiteManifest(root_ / "anchored").geo_anchor));
  EXPECT_EQ(carried.latitude_deg(), 46.5191);
  EXPECT_EQ(carried.longitude_deg(), 6.5668);
  EXPECT_EQ(carried.altitude_m(), 372.5);
  EXPECT_EQ(carried.horizontal_sigma_m(), 0.02);
  ASSERT_FALSE(manifest.tiles.empty());
  for (size_t t = 0; t < manifest.tiles.size(); ++t) {
    const Map tile = LoadTile(root_ / "anchored", manifest, t);
    ASSERT_TRUE(tile.geo_anchor.has_value()) << "tile " << t;
    EXPECT_EQ(tile.geo_anchor->origin.altitude_m, 372.5);
  }
  // SiteGeoAnchor decodes it for the site's users (the service, evloc-track --geo).
  const std::optional<GeoAnchor> decoded = SiteGeoAnchor(ReadSiteManifest(root_ / "anchored"));
  ASSERT_TRUE(decoded.has_value());
  EXPECT_EQ(decoded->origin.latitude_deg, 46.5191);
  EXPECT_EQ(decoded->origin.longitude_deg, 6.5668);
  EXPECT_EQ(decoded->horizontal_sigma_m, 0.02);
  EXPECT_FALSE(SiteGeoAnchor(manifest_).has_value());
}

// A stored anchor that does not decode, or decodes outside GeoAnchor's domain, is a named error.
TEST_F(SiteTest, SiteGeoAnchorRefusesAnInvalidStoredAnchor) {
  SiteManifest manifest = manifest_;
  manifest.geo_anchor = "\xff\xff not a message";
  try {
    SiteGeoAnchor(manifest);
    ADD_FAILURE() << "an undecodable anchor was accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("the manifest's geo anchor"), std::string::npos)
        << error.what();
  }
  map_format::GeoAnchor out_of_range;
  out_of_range.set_latitude_deg(123.0);
  manifest.geo_anchor = out_of_range.SerializeAsString();
  EXPECT_THROW(SiteGeoAnchor(manifest), InvalidArgumentError);
  // The manifest's own check refuses it, so a manifest file holding it does not decode.
  EXPECT_THROW(manifest.Check(), InvalidArgumentError);
  EXPECT_THROW(EncodeSiteManifest(manifest), InvalidArgumentError);
}

TEST_F(SiteTest, DamagedManifestsAreRefusedWithTheirPosition) {
  const std::filesystem::path path = root_ / "site" / kSiteManifestFileName;
  const std::string good = ReadFileToString(path);
  const auto refused = [&](std::string bytes, const std::string& words) {
    try {
      DecodeSiteManifest(bytes, "m");
      ADD_FAILURE() << "accepted: " << words;
    } catch (const ParseError& error) {
      EXPECT_NE(std::string(error.what()).find(words), std::string::npos) << error.what();
    }
  };
  refused("", "not an evloc site manifest");
  refused("EVLOCMAP" + good.substr(8), "not an evloc site manifest");
  refused(good.substr(0, 20), "truncated");
  refused(good.substr(0, good.size() - 1), "byte 16");
  refused(good + "x", "byte 16");
  std::string flipped = good;
  flipped[good.size() / 2] ^= 0x40;
  refused(flipped, "checksum");
  std::string version = good;
  version[8] = 9;
  refused(version, "version 9");
  EXPECT_NO_THROW(DecodeSiteManifest(good, "m"));
}

TEST_F(SiteTest, InconsistentManifestsAreRefused) {
  const auto refused = [&](const SiteManifest& manifest, const std::string& words) {
    try {
      manifest.Check();
      ADD_FAILURE() << "accepted: " << words;
    } catch (const InvalidArgumentError& error) {
      EXPECT_NE(std::string(error.what()).find(words), std::string::npos) << error.what();
    }
  };
  SiteManifest bad = manifest_;
  bad.tiles[0].file_name = "../escape.evmap";
  refused(bad, "file name");
  bad = manifest_;
  std::swap(bad.tiles[0], bad.tiles[1]);
  refused(bad, "out of order");
  bad = manifest_;
  bad.tiles[1].core.max_x += 1;
  refused(bad, "bounds");
  bad = manifest_;
  bad.tiles[0].content_crc32c ^= 1;
  refused(bad, "version");
  bad = manifest_;
  bad.grid.overlap_m = bad.grid.tile_size_m;
  refused(bad, "overlap");
}

TEST_F(SiteTest, ATileThatDisagreesWithTheManifestIsRefused) {
  // Replace tile 0 by another valid map: its size and checksum differ from the manifest's.
  const std::filesystem::path file = root_ / "site" / manifest_.tiles[0].file_name;
  SaveMap(file, LoadTile(root_ / "site", manifest_, 1));
  EXPECT_THROW(LoadTile(root_ / "site", manifest_, 0), ParseError);
  std::filesystem::remove(file);
  EXPECT_THROW(LoadTile(root_ / "site", manifest_, 0), IoError);
}

TEST_F(SiteTest, AnExistingSiteIsReplacedOnlyWithOverwriteAndAFailedRunLeavesNoSite) {
  EXPECT_THROW(TileMap(map_, root_ / "site", options_), InvalidArgumentError);
  // A run that fails half way (a tile's name is taken by a folder) leaves no manifest.
  TilingOptions bigger = options_;
  bigger.tile_size_m = 10;
  bigger.overlap_m = 2;
  bigger.overwrite = true;
  std::filesystem::remove(root_ / "site" / "tile_+1_+0.evmap");
  std::filesystem::create_directories(root_ / "site" / "tile_+1_+0.evmap" / "blocker");
  EXPECT_THROW(TileMap(map_, root_ / "site", bigger), Error);
  EXPECT_FALSE(IsSiteDirectory(root_ / "site"));
  std::filesystem::remove_all(root_ / "site" / "tile_+1_+0.evmap");
  const SiteManifest replaced = TileMap(map_, root_ / "site", bigger);
  EXPECT_TRUE(IsSiteDirectory(root_ / "site"));
  EXPECT_EQ(ReadSiteManifest(root_ / "site").version, replaced.version);
  // Files of the old site the new one does not list are gone.
  size_t evmaps = 0;
  for (const auto& entry : std::filesystem::directory_iterator(root_ / "site")) {
    if (entry.path().extension() == ".evmap") ++evmaps;
  }
  EXPECT_EQ(evmaps, replaced.tiles.size());
}

TEST_F(SiteTest, EqualMapsGiveEqualSiteVersions) {
  const SiteManifest again = TileMap(map_, root_ / "again", options_);
  EXPECT_EQ(again.version, manifest_.version);
  TilingOptions shifted = options_;
  shifted.origin = Eigen::Vector2d(0.5, -5);
  EXPECT_NE(TileMap(map_, root_ / "shifted", shifted).version, manifest_.version);
}

// A site written by `evloc-mapper tile` and checked in (maps/testdata/site_small: the
// v1_small.evmap corridor in 1 m tiles with 0.25 m overlap): today's reader loads it and every
// tile agrees with the manifest.
TEST(SiteReferenceFile, CheckedInSiteLoads) {
  const std::filesystem::path site = testing::SourceDir() / "maps" / "testdata" / "site_small";
  const SiteManifest manifest = ReadSiteManifest(site);
  EXPECT_EQ(manifest.grid.tile_size_m, 1.0);
  EXPECT_EQ(manifest.grid.overlap_m, 0.25);
  const Map source = LoadMap(testing::SourceDir() / "maps" / "testdata" / "v1_small.evmap");
  EXPECT_EQ(manifest.source_content_crc32c, ComputeMapContentChecksum(source));
  uint64_t core_points = 0;
  for (size_t t = 0; t < manifest.tiles.size(); ++t) {
    EXPECT_NO_THROW(LoadTile(site, manifest, t));
    core_points += manifest.tiles[t].num_core_points;
  }
  EXPECT_EQ(core_points, source.size());
}

}  // namespace
}  // namespace evloc
