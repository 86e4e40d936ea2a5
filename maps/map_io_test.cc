#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <limits>
#include <string>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "evloc/map.pb.h"
#include "maps/crc32c.h"
#include "maps/map.h"
#include "maps/synthetic_map.h"

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
  std::filesystem::path WriteEditedPayload(Edit edit, const std::string& name) {
    SaveMap(path_, MakeMap());
    std::string bytes = ReadFileToString(path_);
    map_format::MapFile file;
    EXPECT_TRUE(file.ParseFromString(bytes.substr(kMapFileHeaderSize)));
    edit(file);
    const std::string payload = file.SerializeAsString();
    const uint32_t payload_crc = Crc32c(payload);
    const uint64_t length = payload.size();
    std::memcpy(bytes.data() + 12, &payload_crc, 4);
    std::memcpy(bytes.data() + 16, &length, 8);
    const uint32_t header_crc = Crc32c(std::string_view(bytes).substr(0, 24));
    std::memcpy(bytes.data() + 24, &header_crc, 4);
    return WriteVariant(bytes.substr(0, kMapFileHeaderSize) + payload, name);
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
  for (const uint32_t version : {0u, 2u, 77u}) {
    std::memcpy(bytes.data() + 8, &version, 4);
    const uint32_t header_crc = Crc32c(std::string_view(bytes).substr(0, 24));
    std::memcpy(bytes.data() + 24, &header_crc, 4);
    const auto path = WriteVariant(bytes, "version.evmap");
    ExpectParseError(
        [&] { LoadMap(path); },
        {"format version " + std::to_string(version) + " is not supported", "reads version(s) 1"});
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
