#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <string>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "evloc/map.pb.h"
#include "maps/crc32c.h"
#include "maps/map.h"
#include "maps/synthetic_map.h"
#include "maps/testing/map_file_editing.h"

namespace evloc {
namespace {

Map MakeMap() {
  CorridorMapOptions options;
  options.num_points = 2000;
  options.num_keyframes = 6;
  options.camera.model = CameraModel::kRadialTangential;
  options.camera.distortion = {-0.1, 0.01, 0.001, -0.002, 0.0};
  Map map = MakeCorridorMap(options);
  map.inverse_depth_sigma[5] = 0.0f;
  map.positions[7].x() = -0.0f;
  map.provenance = {"evloc-test", "0.1.0", "2024-05-01T12:00:00Z", "evloc-test --flag", {"a.pcd"}};
  return map;
}

// MakeMap() with relocalization data: landmarks, per-keyframe features (keyframe 2 has none) and a
// two-word vocabulary, from a fixed seed.
Map MakeRelocalizationMap() {
  Map map = MakeMap();
  RelocalizationData& data = map.relocalization.emplace();
  uint32_t state = 12345;
  const auto next = [&state] {
    state = state * 1664525u + 1013904223u;
    return static_cast<float>(state >> 8) / static_cast<float>(1 << 24);
  };
  for (int i = 0; i < 40; ++i) data.landmarks.emplace_back(next() * 10, next() - 0.5f, next());
  for (size_t i = 0; i < 2 * kRelocalizationDescriptorBytes; ++i) data.vocabulary.push_back(next());
  data.keyframes.resize(map.keyframes.size());
  for (size_t k = 0; k < map.keyframes.size(); ++k) {
    KeyframeFeatures& features = data.keyframes[k];
    const int count = k == 2 ? 0 : 10 + static_cast<int>(k);
    for (int i = 0; i < count; ++i) {
      features.keypoints.emplace_back(next() * 640, next() * 480);
      features.landmarks.push_back(static_cast<uint32_t>((i * 7 + k) % data.landmarks.size()));
      for (size_t b = 0; b < kRelocalizationDescriptorBytes; ++b) {
        features.descriptors.push_back(static_cast<uint8_t>(next() * 255));
      }
    }
    features.global_descriptor.assign(data.vocabulary.size(), 0.0f);
    if (count > 0) {
      features.global_descriptor[k] = 0.6f;
      features.global_descriptor[k + 1] = -0.8f;
    }
  }
  return map;
}

// Expects `function` to throw ParseError whose message contains every fragment.
template <typename Function>
void ExpectParseError(Function function, std::initializer_list<std::string> fragments) {
  try {
    function();
    ADD_FAILURE() << "no ParseError";
  } catch (const ParseError& error) {
    for (const std::string& fragment : fragments) {
      EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos)
          << "message: " << error.what() << "\nexpected to contain: " << fragment;
    }
  }
}

template <typename T>
bool SameBytes(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

class MapIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    directory_ = testing::MakeTempDir("map_io_test");
    path_ = directory_ / "map.evmap";
  }
  void TearDown() override { std::filesystem::remove_all(directory_); }

  // Writes `bytes` to a sibling file and returns its path.
  std::filesystem::path WriteVariant(const std::string& bytes, const std::string& name) {
    const std::filesystem::path path = directory_ / name;
    WriteFileAtomically(path, bytes);
    return path;
  }

  // Saves MakeMap(), lets `edit` change its payload, and writes the result with valid header and
  // payload checksums (the content checksum left as saved) to a sibling file.
  template <typename Edit>
  std::filesystem::path WriteEditedPayload(Edit edit, const std::string& name,
                                           const Map& map = MakeMap()) {
    SaveMap(path_, map);
    return WriteVariant(testing::EditMapPayload(ReadFileToString(path_), edit), name);
  }

  std::filesystem::path directory_;
  std::filesystem::path path_;
};

TEST_F(MapIoTest, RoundTripIsBitExact) {
  const Map map = MakeMap();
  SaveMap(path_, map);
  const Map loaded = LoadMap(path_);
  EXPECT_TRUE(SameBytes(loaded.positions, map.positions));
  EXPECT_TRUE(SameBytes(loaded.gradients, map.gradients));
  EXPECT_TRUE(SameBytes(loaded.inverse_depth_sigma, map.inverse_depth_sigma));
  EXPECT_TRUE(SameBytes(loaded.gradient_magnitude, map.gradient_magnitude));
  EXPECT_TRUE(SameBytes(loaded.source_keyframe, map.source_keyframe));
  EXPECT_TRUE(std::signbit(loaded.positions[7].x()));
  ASSERT_EQ(loaded.keyframes.size(), map.keyframes.size());
  for (size_t k = 0; k < map.keyframes.size(); ++k) {
    const Keyframe& a = loaded.keyframes[k];
    const Keyframe& b = map.keyframes[k];
    EXPECT_EQ(a.cam_from_world.rotation.coeffs(), b.cam_from_world.rotation.coeffs());
    EXPECT_EQ(a.cam_from_world.translation, b.cam_from_world.translation);
    EXPECT_EQ(a.camera_index, b.camera_index);
    EXPECT_EQ(a.t_ns, b.t_ns);
    EXPECT_EQ(a.image_name, b.image_name);
    EXPECT_EQ(a.visible_points, b.visible_points);
  }
  ASSERT_EQ(loaded.cameras.size(), 1u);
  EXPECT_TRUE(loaded.cameras[0] == map.cameras[0]);
  EXPECT_EQ(loaded.provenance.tool, map.provenance.tool);
  EXPECT_EQ(loaded.provenance.tool_version, map.provenance.tool_version);
  EXPECT_EQ(loaded.provenance.created_utc, map.provenance.created_utc);
  EXPECT_EQ(loaded.provenance.command_line, map.provenance.command_line);
  EXPECT_EQ(loaded.provenance.inputs, map.provenance.inputs);
  EXPECT_EQ(ComputeMapContentChecksum(loaded), ComputeMapContentChecksum(map));
  // Saving the loaded map gives the same file.
  const std::filesystem::path again = directory_ / "again.evmap";
  SaveMap(again, loaded);
  EXPECT_EQ(ReadFileToString(again), ReadFileToString(path_));
}

TEST_F(MapIoTest, RelocalizationDataRoundTripsBitExactly) {
  const Map map = MakeRelocalizationMap();
  SaveMap(path_, map);
  EXPECT_EQ(ReadMapFileHeader(path_).format_version, 2u);
  const Map loaded = LoadMap(path_);
  ASSERT_TRUE(loaded.relocalization.has_value());
  EXPECT_TRUE(HasRelocalizationData(loaded));
  const RelocalizationData& a = *loaded.relocalization;
  const RelocalizationData& b = *map.relocalization;
  EXPECT_TRUE(SameBytes(a.landmarks, b.landmarks));
  EXPECT_TRUE(SameBytes(a.vocabulary, b.vocabulary));
  ASSERT_EQ(a.keyframes.size(), b.keyframes.size());
  for (size_t k = 0; k < a.keyframes.size(); ++k) {
    EXPECT_TRUE(SameBytes(a.keyframes[k].keypoints, b.keyframes[k].keypoints));
    EXPECT_EQ(a.keyframes[k].descriptors, b.keyframes[k].descriptors);
    EXPECT_EQ(a.keyframes[k].landmarks, b.keyframes[k].landmarks);
    EXPECT_TRUE(SameBytes(a.keyframes[k].global_descriptor, b.keyframes[k].global_descriptor));
  }
  EXPECT_TRUE(a.keyframes[2].keypoints.empty());
  EXPECT_EQ(ComputeMapContentChecksum(loaded), ComputeMapContentChecksum(map));
  // The content checksum covers the relocalization data, and a map without it keeps its value.
  Map without = map;
  without.relocalization.reset();
  EXPECT_NE(ComputeMapContentChecksum(without), ComputeMapContentChecksum(map));
  EXPECT_EQ(ComputeMapContentChecksum(without), ComputeMapContentChecksum(MakeMap()));
  Map changed = map;
  changed.relocalization->keyframes[1].descriptors[5] ^= 1;
  EXPECT_NE(ComputeMapContentChecksum(changed), ComputeMapContentChecksum(map));
  const std::filesystem::path again = directory_ / "again.evmap";
  SaveMap(again, loaded);
  EXPECT_EQ(ReadFileToString(again), ReadFileToString(path_));
  // What the data adds to the file: the difference in file size.
  SaveMap(again, without);
  EXPECT_EQ(std::filesystem::file_size(path_) - std::filesystem::file_size(again),
            EncodedRelocalizationBytes(b));
  // The same map, read from memory.
  const std::string bytes = ReadFileToString(path_);
  EXPECT_EQ(ComputeMapContentChecksum(LoadMapFromBytes(bytes, "memory")),
            ComputeMapContentChecksum(map));
  EXPECT_EQ(ComputeMapContentChecksum(DecodeMapPayloadUnchecked(
                std::string_view(bytes).substr(kMapFileHeaderSize), "payload")),
            ComputeMapContentChecksum(map));
  ExpectParseError([&] { LoadMapFromBytes(bytes.substr(0, 100), "memory"); },
                   {"memory", "truncated evloc map"});
}

// maps/testdata/v1_small.evmap was written by the format-1 writer (before relocalization data): a
// 300-point corridor with 3 keyframes and a radial-tangential camera.
TEST_F(MapIoTest, FormatVersion1FileStillLoads) {
  const std::filesystem::path v1 = testing::SourceDir() / "maps/testdata/v1_small.evmap";
  EXPECT_EQ(ReadMapFileHeader(v1).format_version, 1u);
  const Map map = LoadMap(v1);
  EXPECT_EQ(map.size(), 300u);
  EXPECT_EQ(map.keyframes.size(), 3u);
  EXPECT_EQ(map.keyframes[1].image_name, "frame_1.png");
  EXPECT_FALSE(map.relocalization.has_value());
  EXPECT_FALSE(HasRelocalizationData(map));
  EXPECT_EQ(ComputeMapContentChecksum(map), 0x7a0bb2aeu);  // The value the v1 writer stored.
  try {
    RequireRelocalizationData(map, v1.string());
    ADD_FAILURE() << "no error for a v1 map";
  } catch (const InvalidArgumentError& error) {
    EXPECT_EQ(std::string(error.what()), MissingRelocalizationDataMessage(v1.string()));
    EXPECT_NE(std::string(error.what())
                  .find("run `evloc-mapper upgrade --map " + v1.string() +
                        " --images DIR` or rebuild it with evloc-mapper build"),
              std::string::npos);
  }
  // Saved again it is a version 2 file with the same content.
  SaveMap(path_, map);
  EXPECT_EQ(ReadMapFileHeader(path_).format_version, 2u);
  EXPECT_EQ(ComputeMapContentChecksum(LoadMap(path_)), 0x7a0bb2aeu);
}

// maps/testdata/anchored_small.evmap: v1_small.evmap given an anchor by `evloc-mapper georef
// --map maps/testdata/v1_small.evmap --geo-anchor 46.5191,6.5668,372.5,30 --out ...` (the
// writer of the first anchored maps, kept as a file future readers must read).
TEST_F(MapIoTest, AFileWrittenWithAnAnchorLoadsAndLists) {
  const std::filesystem::path path = testing::SourceDir() / "maps/testdata/anchored_small.evmap";
  const Map map = LoadMap(path);
  EXPECT_EQ(map.size(), 300u);
  ASSERT_TRUE(map.geo_anchor.has_value());
  EXPECT_EQ(map.geo_anchor->origin.latitude_deg, 46.5191);
  EXPECT_EQ(map.geo_anchor->origin.longitude_deg, 6.5668);
  EXPECT_EQ(map.geo_anchor->origin.altitude_m, 372.5);
  EXPECT_EQ(map.geo_anchor->source, "given");
  // Heading 30: the map's +y axis points 30 degrees east of north.
  const Eigen::Vector3d y_axis = map.geo_anchor->enu_from_map * Eigen::Vector3d::UnitY();
  EXPECT_NEAR(y_axis.x(), 0.5, 1e-12);
  EXPECT_NEAR(y_axis.y(), std::sqrt(3.0) / 2, 1e-12);
  EXPECT_EQ(ComputeMapContentChecksum(map), 0x7a0bb2aeu);  // v1_small's: the anchor is not content
  const MapFileSummary summary = ReadMapFileSummary(path);
  ASSERT_TRUE(summary.info.geo_anchor.has_value());
  EXPECT_EQ(summary.info.geo_anchor->origin.altitude_m, 372.5);
}

TEST_F(MapIoTest, CorruptedRelocalizationFieldsAreRefused) {
  // Edits the relocalization data of the saved map both in the payload and in a copy of the
  // map, whose content checksum the payload then carries (so that the content checks are reached).
  const auto edit = [&](const std::string& name, const std::function<void(Map&)>& change_map,
                        const std::function<void(map_format::MapFile&)>& change_file) {
    Map map = MakeRelocalizationMap();
    change_map(map);
    const uint32_t content_crc = ComputeMapContentChecksum(map);
    return WriteEditedPayload(
        [&](map_format::MapFile& file) {
          change_file(file);
          file.set_content_crc32c(content_crc);
        },
        name, MakeRelocalizationMap());
  };
  const auto no_change = [](Map&) {};
  auto path = edit("descriptors.evmap", no_change, [](map_format::MapFile& file) {
    file.mutable_relocalization()->mutable_keyframes(1)->mutable_descriptors()->pop_back();
  });
  ExpectParseError([&] { LoadMap(path); },
                   {path.string(), "relocalization.keyframes[1].descriptors has 1407 bytes",
                    "expected 128 x 11 keypoints"});
  path = edit("landmark_count.evmap", no_change, [](map_format::MapFile& file) {
    file.mutable_relocalization()->set_landmark_count(0xffffffffffffffffull);
  });
  ExpectParseError([&] { LoadMap(path); }, {path.string(), "relocalization.landmarks has 120"});
  path = edit("odd_keypoints.evmap", no_change, [](map_format::MapFile& file) {
    file.mutable_relocalization()->mutable_keyframes(0)->add_keypoints(1.0f);
  });
  ExpectParseError([&] { LoadMap(path); }, {"relocalization.keyframes[0].keypoints has 21"});
  path = edit("landmark_indices.evmap", no_change, [](map_format::MapFile& file) {
    file.mutable_relocalization()->mutable_keyframes(3)->mutable_landmarks()->RemoveLast();
  });
  ExpectParseError([&] { LoadMap(path); }, {"relocalization.keyframes[3].landmarks has 12"});
  path = edit(
      "landmark_index.evmap", [](Map& map) { map.relocalization->keyframes[1].landmarks[4] = 40; },
      [](map_format::MapFile& file) {
        file.mutable_relocalization()->mutable_keyframes(1)->set_landmarks(4, 40);
      });
  ExpectParseError([&] { LoadMap(path); },
                   {path.string(), "invalid evloc map content",
                    "keyframe 1 keypoint 4 sees landmark 40 but there are 40 landmarks"});
  path = edit(
      "nan_landmark.evmap", [](Map& map) { map.relocalization->landmarks[3].y() = std::nanf(""); },
      [](map_format::MapFile& file) {
        file.mutable_relocalization()->set_landmarks(10, std::nanf(""));
      });
  ExpectParseError([&] { LoadMap(path); }, {"landmark 3 has a non-finite position"});
  path = edit(
      "global.evmap",
      [](Map& map) { map.relocalization->keyframes[0].global_descriptor.pop_back(); },
      [](map_format::MapFile& file) {
        file.mutable_relocalization()
            ->mutable_keyframes(0)
            ->mutable_global_descriptor()
            ->RemoveLast();
      });
  ExpectParseError([&] { LoadMap(path); },
                   {"keyframe 0 has a global descriptor of 255 values; expected the vocabulary "
                    "size 256"});
  path = edit(
      "keyframes.evmap", [](Map& map) { map.relocalization->keyframes.pop_back(); },
      [](map_format::MapFile& file) {
        file.mutable_relocalization()->mutable_keyframes()->RemoveLast();
      });
  ExpectParseError([&] { LoadMap(path); }, {"has feature sets for 5 keyframes but the map has 6"});
  path = edit(
      "vocabulary.evmap", [](Map& map) { map.relocalization->vocabulary.resize(100); },
      [](map_format::MapFile& file) {
        file.mutable_relocalization()->mutable_vocabulary()->Truncate(100);
      });
  ExpectParseError([&] { LoadMap(path); }, {"the vocabulary has 100 values"});
  // A version 1 header with the version 2 field.
  SaveMap(path_, MakeRelocalizationMap());
  path = WriteVariant(testing::EditMapPayload(
                          ReadFileToString(path_),
                          [](map_format::MapFile& file) { file.set_format_version(1); }, 1),
                      "v1_with_field.evmap");
  ExpectParseError([&] { LoadMap(path); }, {"a format version 1 map carries the version 2"});
  // SaveMap refuses what LoadMap would refuse.
  Map bad = MakeRelocalizationMap();
  bad.relocalization->keyframes[0].global_descriptor[0] = 3.0f;
  EXPECT_THROW(SaveMap(directory_ / "bad.evmap", bad), InvalidArgumentError);
  EXPECT_FALSE(std::filesystem::exists(directory_ / "bad.evmap"));
}

// Finding 5 of issue 14: counts whose product with the values per element wraps around 64 bits
// (0x5555555555555556 x 3 = 2) are refused as ParseErrors naming the field.
TEST_F(MapIoTest, ForgedCountsWhoseSizeWrapsAreParseErrors) {
  constexpr uint64_t kWrapsToTwo = 0x5555555555555556ull;
  auto path = WriteEditedPayload(
      [](map_format::MapFile& file) {
        file.clear_summary();  // So that ReadMapFileSummary reads the points.
        file.mutable_points()->set_count(kWrapsToTwo);
        file.mutable_points()->mutable_positions()->Resize(2, 0.0f);
      },
      "points.evmap");
  ExpectParseError([&] { LoadMap(path); }, {"points.evmap", "positions has 2 values"});
  ExpectParseError([&] { ReadMapFileSummary(path); }, {"points.evmap", "positions has 2 values"});
  path = WriteEditedPayload(
      [](map_format::MapFile& file) {
        file.mutable_relocalization()->set_landmark_count(kWrapsToTwo);
        file.mutable_relocalization()->mutable_landmarks()->Resize(2, 0.0f);
      },
      "landmarks.evmap", MakeRelocalizationMap());
  ExpectParseError([&] { LoadMap(path); }, {"landmarks.evmap", "relocalization.landmarks"});
}

// ReadMapFileSummary gives what SummarizeMap gives of the loaded map, for v1 and v2 files, with
// the summary field SaveMap writes and without it (v2 files of earlier writers).
TEST_F(MapIoTest, SummaryWithoutLoadingMatchesTheLoadedMap) {
  for (const Map& map : {MakeMap(), MakeRelocalizationMap(), Map()}) {
    for (const bool with_summary_field : {true, false}) {
      SaveMap(path_, map);
      if (!with_summary_field) {
        const std::string old_writer = testing::EditMapPayload(
            ReadFileToString(path_), [](map_format::MapFile& file) { file.clear_summary(); });
        ASSERT_FALSE(old_writer.empty());
        WriteFileAtomically(path_, old_writer);
      }
      const MapFileSummary summary = ReadMapFileSummary(path_);
      const MapInfo info = SummarizeMap(LoadMap(path_));
      EXPECT_EQ(summary.info.num_points, info.num_points);
      EXPECT_EQ(summary.info.num_keyframes, info.num_keyframes);
      EXPECT_EQ(summary.info.bounding_box_min, info.bounding_box_min);
      EXPECT_EQ(summary.info.bounding_box_max, info.bounding_box_max);
      EXPECT_EQ(summary.info.content_crc32c, info.content_crc32c);
      EXPECT_EQ(summary.info.has_relocalization, info.has_relocalization);
      EXPECT_EQ(summary.info.format_version, info.format_version);
      EXPECT_EQ(summary.file_bytes, std::filesystem::file_size(path_));
    }
  }
  // Found by evloc_map_loader_crc_fuzzer: field 8 (relocalization) with the fixed64 wire type is
  // an unknown field to protobuf, so the map has no relocalization data.
  SaveMap(path_, MakeMap());
  std::string bytes = ReadFileToString(path_);
  const std::string wrong_wire_type = testing::EditMapPayload(bytes, [](map_format::MapFile& file) {
    file.GetReflection()->MutableUnknownFields(&file)->AddFixed64(8, 0x0909098634a61aull);
  });
  const std::filesystem::path unknown = WriteVariant(wrong_wire_type, "unknown8.evmap");
  EXPECT_FALSE(SummarizeMap(LoadMap(unknown)).has_relocalization);
  EXPECT_FALSE(ReadMapFileSummary(unknown).info.has_relocalization);
  const std::filesystem::path v1 = testing::SourceDir() / "maps/testdata/v1_small.evmap";
  EXPECT_EQ(ReadMapFileSummary(v1).info.content_crc32c, SummarizeMap(LoadMap(v1)).content_crc32c);
  std::string truncated = testing::EditMapPayload(
      ReadFileToString(path_), [](map_format::MapFile& file) { file.clear_summary(); });
  truncated.resize(truncated.size() - 1);
  ExpectParseError([&] { ReadMapFileSummary(WriteVariant(truncated, "short.evmap")); },
                   {"short.evmap", "truncated"});
}

// Attack 6 of issue 14: listing maps must not read them. A file SaveMap wrote starts with its
// summary field; ReadMapFileSummary stops there: with every byte after the field overwritten it
// still gives the summary (LoadMap refuses the file).
TEST_F(MapIoTest, SummaryReadsOnlyTheSummaryField) {
  const Map map = MakeRelocalizationMap();
  SaveMap(path_, map);
  const MapInfo info = SummarizeMap(LoadMap(path_));
  std::string bytes = ReadFileToString(path_);
  map_format::MapFile payload;
  ASSERT_TRUE(payload.ParseFromString(bytes.substr(kMapFileHeaderSize)));
  ASSERT_TRUE(payload.has_summary());
  map_format::MapFile summary_only;
  *summary_only.mutable_summary() = payload.summary();
  const size_t summary_end = kMapFileHeaderSize + summary_only.ByteSizeLong();
  ASSERT_LT(summary_end, bytes.size() / 2);
  std::fill(bytes.begin() + static_cast<std::ptrdiff_t>(summary_end), bytes.end(), '\xff');
  const std::filesystem::path damaged = WriteVariant(bytes, "damaged.evmap");
  const MapFileSummary summary = ReadMapFileSummary(damaged);
  EXPECT_EQ(summary.info.num_points, info.num_points);
  EXPECT_EQ(summary.info.num_keyframes, info.num_keyframes);
  EXPECT_EQ(summary.info.bounding_box_min, info.bounding_box_min);
  EXPECT_EQ(summary.info.bounding_box_max, info.bounding_box_max);
  EXPECT_EQ(summary.info.content_crc32c, info.content_crc32c);
  EXPECT_TRUE(summary.info.has_relocalization);
  ExpectParseError([&] { LoadMap(damaged); }, {"damaged.evmap", "checksum"});
}

// A summary field that contradicts the content is refused by LoadMap; one that is malformed is
// refused by ReadMapFileSummary, naming the problem.
TEST_F(MapIoTest, SummaryFieldIsCheckedAgainstTheContent) {
  const auto edited = [&](const std::function<void(map_format::Summary&)>& edit,
                          const std::string& name) {
    return WriteEditedPayload([&](map_format::MapFile& file) { edit(*file.mutable_summary()); },
                              name);
  };
  ExpectParseError(
      [&] { LoadMap(edited([](map_format::Summary& s) { s.set_num_points(7); }, "count.evmap")); },
      {"count.evmap", "summary field disagrees"});
  const std::filesystem::path box =
      edited([](map_format::Summary& s) { s.set_bounding_box(4, 100.0f); }, "box.evmap");
  ExpectParseError([&] { LoadMap(box); }, {"box.evmap", "summary field disagrees"});
  EXPECT_EQ(ReadMapFileSummary(box).info.bounding_box_max.y(), 100.0f);  // Not checked: documented.
  ExpectParseError(
      [&] {
        ReadMapFileSummary(edited(
            [](map_format::Summary& s) { s.mutable_bounding_box()->RemoveLast(); }, "five.evmap"));
      },
      {"five.evmap", "summary field", "5 values"});
  ExpectParseError(
      [&] {
        ReadMapFileSummary(edited(
            [](map_format::Summary& s) {
              s.set_bounding_box(0, std::numeric_limits<float>::quiet_NaN());
            },
            "nan.evmap"));
      },
      {"nan.evmap", "summary field", "not finite"});
  ExpectParseError(
      [&] {
        ReadMapFileSummary(
            edited([](map_format::Summary& s) { s.set_num_points(0); }, "zero.evmap"));
      },
      {"zero.evmap", "a bounding box for 0 points"});
  // Field 9 twice: protobuf merges the occurrences (a later scalar wins) while ReadMapFileSummary
  // reads the first alone; the merged summary is right here, the first one is not: refused.
  SaveMap(path_, MakeMap());
  const std::string bytes = ReadFileToString(path_);
  map_format::MapFile payload;
  ASSERT_TRUE(payload.ParseFromString(bytes.substr(kMapFileHeaderSize)));
  ASSERT_GT(payload.summary().num_keyframes(), 0u);
  map_format::MapFile first;
  *first.mutable_summary() = payload.summary();
  first.mutable_summary()->set_num_keyframes(payload.summary().num_keyframes() + 5);
  map_format::MapFile second;
  second.mutable_summary()->set_num_keyframes(payload.summary().num_keyframes());
  payload.clear_summary();
  const std::filesystem::path twice = WriteVariant(
      testing::WithPayload(
          bytes,
          first.SerializeAsString() + payload.SerializeAsString() + second.SerializeAsString(), 0),
      "twice.evmap");
  EXPECT_EQ(ReadMapFileSummary(twice).info.num_keyframes,
            payload.keyframes_size() + 5);  // What a listing shows until a load.
  ExpectParseError([&] { LoadMap(twice); }, {"twice.evmap", "summary field disagrees"});
}

TEST_F(MapIoTest, EmptyMapRoundTrips) {
  SaveMap(path_, Map());
  const Map loaded = LoadMap(path_);
  EXPECT_EQ(loaded.size(), 0u);
  EXPECT_TRUE(loaded.keyframes.empty());
}

TEST_F(MapIoTest, HeaderLayoutIsAsDocumented) {
  SaveMap(path_, MakeMap());
  const std::string bytes = ReadFileToString(path_);
  ASSERT_GT(bytes.size(), kMapFileHeaderSize);
  EXPECT_EQ(bytes.substr(0, 8), "EVLOCMAP");
  uint32_t version, payload_crc, header_crc, reserved;
  uint64_t payload_length;
  std::memcpy(&version, bytes.data() + 8, 4);
  std::memcpy(&payload_crc, bytes.data() + 12, 4);
  std::memcpy(&payload_length, bytes.data() + 16, 8);
  std::memcpy(&header_crc, bytes.data() + 24, 4);
  std::memcpy(&reserved, bytes.data() + 28, 4);
  EXPECT_EQ(version, kMapFormatVersion);
  EXPECT_EQ(payload_length, bytes.size() - kMapFileHeaderSize);
  EXPECT_EQ(payload_crc, Crc32c(std::string_view(bytes).substr(kMapFileHeaderSize)));
  EXPECT_EQ(header_crc, Crc32c(std::string_view(bytes).substr(0, 24)));
  EXPECT_EQ(reserved, 0u);
  const MapFileHeader header = ReadMapFileHeader(path_);
  EXPECT_EQ(header.format_version, version);
  EXPECT_EQ(header.payload_length, payload_length);
  EXPECT_EQ(header.payload_crc32c, payload_crc);
}

TEST_F(MapIoTest, TruncatedFilesAreReportedWithExpectedAndActualSizes) {
  SaveMap(path_, MakeMap());
  const std::string bytes = ReadFileToString(path_);
  const std::string expected = std::to_string(bytes.size());
  for (const size_t length :
       {kMapFileHeaderSize, kMapFileHeaderSize + 1, bytes.size() / 2, bytes.size() - 1}) {
    const auto truncated = WriteVariant(bytes.substr(0, length), "truncated.evmap");
    ExpectParseError([&] { LoadMap(truncated); },
                     {"truncated evloc map", "expected " + expected + " bytes",
                      "file has " + std::to_string(length)});
  }
  for (const size_t length : {size_t{3}, size_t{8}, size_t{20}}) {
    const auto truncated = WriteVariant(bytes.substr(0, length), "short.evmap");
    ExpectParseError([&] { LoadMap(truncated); }, {"truncated evloc map", "header needs 32 bytes",
                                                   "file has " + std::to_string(length)});
  }
}

TEST_F(MapIoTest, FlippedPayloadByteFailsTheChecksum) {
  SaveMap(path_, MakeMap());
  std::string bytes = ReadFileToString(path_);
  for (const size_t offset : {kMapFileHeaderSize, bytes.size() / 2, bytes.size() - 1}) {
    std::string damaged = bytes;
    damaged[offset] = static_cast<char>(damaged[offset] ^ 0x10);
    const auto path = WriteVariant(damaged, "damaged.evmap");
    ExpectParseError([&] { LoadMap(path); }, {"payload checksum mismatch", "byte 32"});
  }
}

TEST_F(MapIoTest, FlippedHeaderByteFailsTheHeaderChecksum) {
  SaveMap(path_, MakeMap());
  std::string bytes = ReadFileToString(path_);
  bytes[17] = static_cast<char>(bytes[17] ^ 0x01);  // payload length
  const auto path = WriteVariant(bytes, "damaged.evmap");
  ExpectParseError([&] { LoadMap(path); }, {"corrupted evloc map header"});
}

TEST_F(MapIoTest, TrailingBytesAreRejected) {
  SaveMap(path_, MakeMap());
  const auto path = WriteVariant(ReadFileToString(path_) + "extra", "long.evmap");
  ExpectParseError([&] { LoadMap(path); }, {"5 unexpected bytes after the payload"});
}

TEST_F(MapIoTest, ForeignFilesAreNotEvlocMaps) {
  for (const std::string& content :
       {std::string("\x89PNG\r\n\x1a\n0000000000000000000000000000000000", 42),
        std::string("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"),
        std::string("ply\nformat ascii 1.0\n"), std::string()}) {
    const auto path = WriteVariant(content, "foreign.bin");
    ExpectParseError([&] { LoadMap(path); }, {"not an evloc map", "byte 0"});
  }
}

TEST_F(MapIoTest, UnsupportedVersionNamesTheSupportedOnes) {
  SaveMap(path_, MakeMap());
  std::string bytes = ReadFileToString(path_);
  for (const uint32_t version : {0u, 3u, 77u}) {
    std::memcpy(bytes.data() + 8, &version, 4);
    const uint32_t header_crc = Crc32c(std::string_view(bytes).substr(0, 24));
    std::memcpy(bytes.data() + 24, &header_crc, 4);
    const auto path = WriteVariant(bytes, "version.evmap");
    ExpectParseError([&] { LoadMap(path); },
                     {"format version " + std::to_string(version) + " is not supported",
                      "reads version(s) 1, 2"});
  }
}

TEST_F(MapIoTest, GarbagePayloadWithAValidChecksumIsRejected) {
  const std::string payload(64, '\xff');
  std::string bytes(kMapFileHeaderSize, '\0');
  std::memcpy(bytes.data(), "EVLOCMAP", 8);
  const uint32_t version = 1;
  const uint32_t payload_crc = Crc32c(payload);
  const uint64_t length = payload.size();
  std::memcpy(bytes.data() + 8, &version, 4);
  std::memcpy(bytes.data() + 12, &payload_crc, 4);
  std::memcpy(bytes.data() + 16, &length, 8);
  const uint32_t header_crc = Crc32c(std::string_view(bytes).substr(0, 24));
  std::memcpy(bytes.data() + 24, &header_crc, 4);
  const auto path = WriteVariant(bytes + payload, "garbage.evmap");
  ExpectParseError([&] { LoadMap(path); }, {"not a valid MapFile protobuf"});
}

// The map reader checks cameras as the service checks a session's camera (proto/convert).
TEST_F(MapIoTest, InvalidCameraNamesTheFileAndTheCamera) {
  const auto path = WriteEditedPayload(
      [](map_format::MapFile& file) { file.mutable_cameras(0)->set_fx(-1.0); }, "bad_fx.evmap");
  ExpectParseError([&] { LoadMap(path); },
                   {path.string(), "invalid evloc map payload: camera 0: ", "focal lengths"});
  const auto unset = WriteEditedPayload(
      [](map_format::MapFile& file) {
        file.mutable_cameras(0)->set_model(map_format::CAMERA_MODEL_UNSPECIFIED);
      },
      "unset_model.evmap");
  ExpectParseError([&] { LoadMap(unset); }, {unset.string(), "camera 0.model is not set"});
  const auto wide = WriteEditedPayload(
      [](map_format::MapFile& file) { file.mutable_cameras(0)->set_width(70'000); }, "wide.evmap");
  ExpectParseError([&] { LoadMap(wide); }, {wide.string(), "camera 0: width and height"});
}

TEST_F(MapIoTest, InvalidKeyframePoseNamesTheFileAndTheKeyframe) {
  const auto path = WriteEditedPayload(
      [](map_format::MapFile& file) {
        file.mutable_keyframes(2)->mutable_cam_from_world()->mutable_translation()->set_x(
            std::numeric_limits<double>::quiet_NaN());
      },
      "nan_pose.evmap");
  ExpectParseError([&] { LoadMap(path); },
                   {path.string(), "keyframe 2 cam_from_world: the pose has a non-finite value"});
}

// A radial-tangential camera stored with 4 coefficients gets k3 = 0, as in a SessionStart.
TEST_F(MapIoTest, FourCoefficientRadialTangentialCameraGetsZeroK3) {
  const auto path = WriteEditedPayload(
      [](map_format::MapFile& file) {
        ASSERT_EQ(file.cameras(0).distortion_size(), 5);
        ASSERT_EQ(file.cameras(0).distortion(4), 0.0);
        file.mutable_cameras(0)->mutable_distortion()->RemoveLast();
      },
      "four_coefficients.evmap");
  const Map loaded = LoadMap(path);
  EXPECT_EQ(loaded.cameras[0].distortion, MakeMap().cameras[0].distortion);
}

TEST_F(MapIoTest, MissingFileAndDirectoryAreIoErrors) {
  EXPECT_THROW(LoadMap(directory_ / "missing.evmap"), IoError);
  EXPECT_THROW(LoadMap(directory_), IoError);
}

TEST_F(MapIoTest, InvalidMapIsNotWritten) {
  Map map = MakeMap();
  map.gradients[3] = Eigen::Vector3f::Zero();
  EXPECT_THROW(SaveMap(path_, map), InvalidArgumentError);
  EXPECT_FALSE(std::filesystem::exists(path_));
  EXPECT_TRUE(std::filesystem::is_empty(directory_));
}

}  // namespace
}  // namespace evloc

namespace evloc {
namespace {

GeoAnchor MakeAnchor() {
  GeoAnchor anchor;
  anchor.origin = {47.376887, 8.541694, 408.25};
  anchor.enu_from_map = Rigid3d(Eigen::Quaterniond(0.9, 0.1, -0.05, 0.4), {12.5, -3.0, 0.75});
  anchor.source = kGeoAnchorSourceSurvey;
  anchor.horizontal_sigma_m = 0.02;
  anchor.vertical_sigma_m = 0.05;
  return anchor;
}

// A map with a geo anchor: saved, loaded bit for bit, listed (the summary reader reads the
// anchor written right after the summary field), shown by FormatMapInfo; its content checksum is
// that of the same map without the anchor (readers older than the anchor verify it without).
TEST_F(MapIoTest, GeoAnchorRoundTripsAndIsListedWithoutChangingTheContentChecksum) {
  Map map = MakeRelocalizationMap();
  const uint32_t crc_without = ComputeMapContentChecksum(map);
  map.geo_anchor = MakeAnchor();
  EXPECT_EQ(ComputeMapContentChecksum(map), crc_without);
  SaveMap(path_, map);
  const Map loaded = LoadMap(path_);
  ASSERT_TRUE(loaded.geo_anchor.has_value());
  const GeoAnchor& anchor = *loaded.geo_anchor;
  EXPECT_EQ(anchor.origin.latitude_deg, map.geo_anchor->origin.latitude_deg);
  EXPECT_EQ(anchor.origin.longitude_deg, map.geo_anchor->origin.longitude_deg);
  EXPECT_EQ(anchor.origin.altitude_m, map.geo_anchor->origin.altitude_m);
  EXPECT_EQ(anchor.enu_from_map.rotation.coeffs(), map.geo_anchor->enu_from_map.rotation.coeffs());
  EXPECT_EQ(anchor.enu_from_map.translation, map.geo_anchor->enu_from_map.translation);
  EXPECT_EQ(anchor.source, "survey");
  EXPECT_EQ(anchor.horizontal_sigma_m, 0.02);
  EXPECT_EQ(anchor.vertical_sigma_m, 0.05);

  // The summary reader stops after the summary and the anchor: damage everything after them.
  std::string bytes = ReadFileToString(path_);
  map_format::MapFile prefix;
  ASSERT_TRUE(prefix.ParseFromString(bytes.substr(kMapFileHeaderSize)));
  map_format::MapFile summary_and_anchor;
  *summary_and_anchor.mutable_summary() = prefix.summary();
  *summary_and_anchor.mutable_geo_anchor() = prefix.geo_anchor();
  const size_t prefix_end = kMapFileHeaderSize + summary_and_anchor.ByteSizeLong();
  EXPECT_EQ(bytes.substr(kMapFileHeaderSize, summary_and_anchor.ByteSizeLong()),
            summary_and_anchor.SerializeAsString());
  std::fill(bytes.begin() + static_cast<std::ptrdiff_t>(prefix_end), bytes.end(), '\xff');
  const MapFileSummary summary = ReadMapFileSummary(WriteVariant(bytes, "damaged.evmap"));
  ASSERT_TRUE(summary.info.geo_anchor.has_value());
  EXPECT_EQ(summary.info.geo_anchor->origin.latitude_deg, 47.376887);
  EXPECT_EQ(summary.info.content_crc32c, crc_without);

  const std::string text = FormatMapInfo(SummarizeMap(loaded));
  EXPECT_NE(
      text.find("geo anchor:       47.37688700, 8.54169400, 408.250 m (WGS84), source survey"),
      std::string::npos)
      << text;

  // What a reader that does not know field 10 sees: the same map, checksums and summary valid.
  const auto stripped = WriteEditedPayload(
      [](map_format::MapFile& file) { file.clear_geo_anchor(); }, "stripped.evmap", map);
  const Map without = LoadMap(stripped);
  EXPECT_FALSE(without.geo_anchor.has_value());
  EXPECT_EQ(ComputeMapContentChecksum(without), crc_without);
  EXPECT_NE(FormatMapInfo(SummarizeMap(without)).find("geo anchor:       none"), std::string::npos);
}

TEST_F(MapIoTest, InvalidGeoAnchorsAreRefusedNamingTheField) {
  Map map = MakeMap();
  map.geo_anchor = MakeAnchor();
  const auto edited = [&](const std::string& name,
                          const std::function<void(map_format::GeoAnchor&)>& change) {
    return WriteEditedPayload(
        [&](map_format::MapFile& file) { change(*file.mutable_geo_anchor()); }, name, map);
  };
  auto path = edited("latitude.evmap", [](auto& anchor) { anchor.set_latitude_deg(91.0); });
  ExpectParseError([&] { LoadMap(path); }, {path.string(), "geo_anchor", "latitude 91"});
  ExpectParseError([&] { ReadMapFileSummary(path); }, {"geo_anchor", "latitude 91"});
  path = edited("source.evmap", [](auto& anchor) { anchor.set_source("guess"); });
  ExpectParseError([&] { LoadMap(path); }, {"geo_anchor", "source 'guess'"});
  path = edited("sigma.evmap", [](auto& anchor) { anchor.set_vertical_sigma_m(-1.0); });
  ExpectParseError([&] { LoadMap(path); }, {"geo_anchor", "vertical_sigma_m"});
  path = edited("rotation.evmap",
                [](auto& anchor) { anchor.mutable_enu_from_map()->mutable_rotation()->set_w(7); });
  ExpectParseError([&] { LoadMap(path); }, {"geo_anchor.enu_from_map", "unit quaternion"});
  // SaveMap refuses an invalid anchor before writing anything.
  map.geo_anchor->origin.longitude_deg = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(SaveMap(directory_ / "never.evmap", map), InvalidArgumentError);
  EXPECT_FALSE(std::filesystem::exists(directory_ / "never.evmap"));
}

}  // namespace
}  // namespace evloc
