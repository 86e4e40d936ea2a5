// SaveMap / LoadMap: the .evmap container (docs/map-format.md).
#include <array>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <string_view>

#include <fcntl.h>
#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl.h>
#include <google/protobuf/wire_format_lite.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "evloc/map.pb.h"
#include "maps/crc32c.h"
#include "maps/map.h"
#include "proto/convert/proto_convert.h"

namespace evloc {
namespace {

namespace pb = ::evloc::map_format;
using WireFormatLite = ::google::protobuf::internal::WireFormatLite;

constexpr std::string_view kMagic = "EVLOCMAP";
constexpr uint32_t kSupportedVersions[] = {1, 2};
constexpr const char* kLengthUnit = "m";
constexpr const char* kTimeUnit = "ns";

// Header layout (little-endian): magic[8] version u32 | payload_crc32c u32 | payload_length u64 |
// header_crc32c u32 (over bytes 0..23) | reserved u32 (0).
constexpr size_t kVersionOffset = 8;
constexpr size_t kPayloadCrcOffset = 12;
constexpr size_t kPayloadLengthOffset = 16;
constexpr size_t kHeaderCrcOffset = 24;
constexpr size_t kReservedOffset = 28;
static_assert(kReservedOffset + 4 == kMapFileHeaderSize);

using HeaderBytes = std::array<unsigned char, kMapFileHeaderSize>;

template <typename T>
void PutLittleEndian(HeaderBytes& bytes, size_t offset, T value) {
  for (size_t i = 0; i < sizeof(T); ++i) {
    bytes[offset + i] = static_cast<unsigned char>(static_cast<uint64_t>(value) >> (8 * i));
  }
}

template <typename T>
T GetLittleEndian(const HeaderBytes& bytes, size_t offset) {
  uint64_t value = 0;
  for (size_t i = 0; i < sizeof(T); ++i)
    value |= static_cast<uint64_t>(bytes[offset + i]) << (8 * i);
  return static_cast<T>(value);
}

HeaderBytes EncodeHeader(const MapFileHeader& header) {
  HeaderBytes bytes{};
  std::memcpy(bytes.data(), kMagic.data(), kMagic.size());
  PutLittleEndian<uint32_t>(bytes, kVersionOffset, header.format_version);
  PutLittleEndian<uint32_t>(bytes, kPayloadCrcOffset, header.payload_crc32c);
  PutLittleEndian<uint64_t>(bytes, kPayloadLengthOffset, header.payload_length);
  PutLittleEndian<uint32_t>(bytes, kHeaderCrcOffset,
                            ExtendCrc32c(0, bytes.data(), kHeaderCrcOffset));
  PutLittleEndian<uint32_t>(bytes, kReservedOffset, 0);
  return bytes;
}

std::string SupportedVersionsText() {
  std::string text;
  for (const uint32_t version : kSupportedVersions) {
    text += (text.empty() ? "" : ", ") + std::to_string(version);
  }
  return text;
}

// Validates the first `header_bytes_read` bytes of a map of `file_size` bytes (the header, or
// all of a shorter file) against the file size.
MapFileHeader CheckHeader(const HeaderBytes& bytes, size_t header_bytes_read, uint64_t file_size,
                          const std::string& source) {
  const size_t magic_bytes = std::min(header_bytes_read, kMagic.size());
  if (file_size == 0 || std::memcmp(bytes.data(), kMagic.data(), magic_bytes) != 0) {
    throw ParseError::AtByte(source, 0,
                             "not an evloc map (the file does not start with \"EVLOCMAP\"); "
                             "pass a .evmap file written by evloc-mapper");
  }
  if (file_size < kMapFileHeaderSize) {
    throw ParseError::AtByte(source, file_size,
                             "truncated evloc map: the header needs " +
                                 std::to_string(kMapFileHeaderSize) + " bytes but the file has " +
                                 std::to_string(file_size) + "; rewrite or re-copy the map");
  }
  const uint32_t header_crc = GetLittleEndian<uint32_t>(bytes, kHeaderCrcOffset);
  if (header_crc != ExtendCrc32c(0, bytes.data(), kHeaderCrcOffset)) {
    throw ParseError::AtByte(source, kHeaderCrcOffset,
                             "corrupted evloc map header (header checksum mismatch); "
                             "re-copy or rebuild the map");
  }
  MapFileHeader header;
  header.format_version = GetLittleEndian<uint32_t>(bytes, kVersionOffset);
  header.payload_crc32c = GetLittleEndian<uint32_t>(bytes, kPayloadCrcOffset);
  header.payload_length = GetLittleEndian<uint64_t>(bytes, kPayloadLengthOffset);
  if (std::find(std::begin(kSupportedVersions), std::end(kSupportedVersions),
                header.format_version) == std::end(kSupportedVersions)) {
    throw ParseError::AtByte(
        source, kVersionOffset,
        "evloc map format version " + std::to_string(header.format_version) +
            " is not supported; this build reads version(s) " + SupportedVersionsText() +
            (header.format_version > kMapFormatVersion ? "; update evloc to read it"
                                                       : "; rebuild the map"));
  }
  const uint64_t actual_payload = file_size - kMapFileHeaderSize;
  if (actual_payload < header.payload_length) {
    throw ParseError::AtByte(source, file_size,
                             "truncated evloc map: expected " +
                                 std::to_string(kMapFileHeaderSize + header.payload_length) +
                                 " bytes but the file has " + std::to_string(file_size) +
                                 "; the copy or write was interrupted, re-copy or rebuild it");
  }
  if (actual_payload > header.payload_length) {
    throw ParseError::AtByte(source, kMapFileHeaderSize + header.payload_length,
                             "evloc map has " +
                                 std::to_string(actual_payload - header.payload_length) +
                                 " unexpected bytes after the payload (expected " +
                                 std::to_string(kMapFileHeaderSize + header.payload_length) +
                                 " bytes, file has " + std::to_string(file_size) + ")");
  }
  return header;
}

// Opens `path` and validates its header against the file size. Leaves `stream` at the payload.
MapFileHeader ReadAndCheckHeader(const std::filesystem::path& path, std::ifstream& stream) {
  const std::string source = path.string();
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) {
    throw IoError("cannot read map '" + source + "': it is a directory (pass the .evmap file)");
  }
  stream.open(path, std::ios::binary);
  if (!stream) {
    throw IoError("cannot open map '" + source + "': " + std::strerror(errno));
  }
  const uint64_t file_size = std::filesystem::file_size(path, error);
  if (error) throw IoError("cannot read the size of map '" + source + "': " + error.message());
  HeaderBytes bytes{};
  const size_t header_bytes_read =
      static_cast<size_t>(std::min<uint64_t>(file_size, kMapFileHeaderSize));
  stream.read(reinterpret_cast<char*>(bytes.data()),
              static_cast<std::streamsize>(header_bytes_read));
  if (static_cast<size_t>(stream.gcount()) != header_bytes_read) {
    throw IoError("cannot read map '" + source + "': read error in the header");
  }
  return CheckHeader(bytes, header_bytes_read, file_size, source);
}

template <typename Element, typename Value>
void CopyToRepeated(const std::vector<Element>& values,
                    google::protobuf::RepeatedField<Value>* field) {
  static_assert(sizeof(Element) % sizeof(Value) == 0);
  const size_t count = values.size() * (sizeof(Element) / sizeof(Value));
  field->Resize(static_cast<int>(count), Value{});
  if (count > 0) std::memcpy(field->mutable_data(), values.data(), count * sizeof(Value));
}

pb::Relocalization RelocalizationToProto(const RelocalizationData& data) {
  pb::Relocalization out;
  out.set_landmark_count(data.landmarks.size());
  CopyToRepeated(data.landmarks, out.mutable_landmarks());
  CopyToRepeated(data.vocabulary, out.mutable_vocabulary());
  for (const KeyframeFeatures& features : data.keyframes) {
    pb::KeyframeFeatures* keyframe = out.add_keyframes();
    CopyToRepeated(features.keypoints, keyframe->mutable_keypoints());
    keyframe->set_descriptors(
        std::string(features.descriptors.begin(), features.descriptors.end()));
    CopyToRepeated(features.landmarks, keyframe->mutable_landmarks());
    CopyToRepeated(features.global_descriptor, keyframe->mutable_global_descriptor());
  }
  return out;
}

pb::MapFile ToProto(const Map& map) {
  pb::MapFile file;
  file.set_format_version(kMapFormatVersion);
  file.mutable_units()->set_length(kLengthUnit);
  file.mutable_units()->set_time(kTimeUnit);
  pb::Provenance* provenance = file.mutable_provenance();
  provenance->set_tool(map.provenance.tool);
  provenance->set_tool_version(map.provenance.tool_version);
  provenance->set_created_utc(map.provenance.created_utc);
  provenance->set_command_line(map.provenance.command_line);
  for (const std::string& input : map.provenance.inputs) provenance->add_inputs(input);
  for (const Camera& camera : map.cameras) *file.add_cameras() = CameraToProto(camera);
  for (const Keyframe& keyframe : map.keyframes) {
    pb::Keyframe* out = file.add_keyframes();
    *out->mutable_cam_from_world() = RigidToProto(keyframe.cam_from_world);
    out->set_camera_index(keyframe.camera_index);
    out->set_t_ns(keyframe.t_ns);
    out->set_image_name(keyframe.image_name);
    CopyToRepeated(keyframe.visible_points, out->mutable_visible_points());
  }
  pb::Points* points = file.mutable_points();
  points->set_count(map.size());
  CopyToRepeated(map.positions, points->mutable_positions());
  CopyToRepeated(map.gradients, points->mutable_gradients());
  CopyToRepeated(map.inverse_depth_sigma, points->mutable_inverse_depth_sigma());
  CopyToRepeated(map.gradient_magnitude, points->mutable_gradient_magnitude());
  CopyToRepeated(map.source_keyframe, points->mutable_source_keyframe());
  file.set_content_crc32c(ComputeMapContentChecksum(map));
  if (map.relocalization)
    *file.mutable_relocalization() = RelocalizationToProto(*map.relocalization);
  return file;
}

// The summary field of `map`, whose file (`file`, its own summary field ignored) is read or
// written, as SaveMap writes it and LoadMap expects it.
pb::Summary SummaryOf(const Map& map, const pb::MapFile& file) {
  pb::Summary summary;
  summary.set_num_points(map.size());
  summary.set_num_keyframes(map.keyframes.size());
  if (!map.positions.empty()) {
    const auto [low, high] = BoundingBox(map.positions);
    for (const float value : {low.x(), low.y(), low.z(), high.x(), high.y(), high.z()}) {
      summary.add_bounding_box(value);
    }
  }
  summary.set_has_relocalization(file.has_relocalization());
  summary.set_content_crc32c(file.content_crc32c());
  return summary;
}

// The Summary of a payload's summary field whose tag `in` has just read; throws what
// `invalid(problem)` returns when it is truncated, too long or malformed (SummaryFieldProblem).
pb::Summary ReadSummaryField(::google::protobuf::io::CodedInputStream& in,
                             const std::function<ParseError(const std::string&)>& invalid);

// What a summary reader may trust of a stored summary field: the bounding box has 0 values (and
// then no points) or 6 finite ones with min <= max. Returns the problem, empty when there is none.
std::string SummaryFieldProblem(const pb::Summary& summary) {
  if (summary.bounding_box_size() == 0) {
    return summary.num_points() == 0
               ? ""
               : "no bounding box for " + std::to_string(summary.num_points()) + " points";
  }
  if (summary.bounding_box_size() != 6) {
    return "bounding box has " + std::to_string(summary.bounding_box_size()) +
           " values; expected 6";
  }
  if (summary.num_points() == 0) return "a bounding box for 0 points";
  for (int axis = 0; axis < 3; ++axis) {
    const float low = summary.bounding_box(axis);
    const float high = summary.bounding_box(axis + 3);
    if (!std::isfinite(low) || !std::isfinite(high) || low > high) {
      return "bounding box axis " + std::to_string(axis) + " is not finite min <= max";
    }
  }
  return "";
}

// The message of a length-delimited field (`name`) whose tag `in` has just read, of at most
// `max_bytes`; throws what `invalid(problem)` returns when it is truncated, too long or not a
// `Message`.
template <typename Message>
Message ReadBoundedMessageField(::google::protobuf::io::CodedInputStream& in,
                                const std::function<ParseError(const std::string&)>& invalid,
                                const std::string& name, uint32_t max_bytes) {
  uint32_t length = 0;
  if (!in.ReadVarint32(&length)) throw invalid("truncated " + name);
  if (length > max_bytes) {
    throw invalid(name + " of " + std::to_string(length) + " bytes (at most " +
                  std::to_string(max_bytes) + ")");
  }
  std::string bytes;
  Message message;
  if (!in.ReadString(&bytes, static_cast<int>(length))) throw invalid("truncated " + name);
  if (!message.ParseFromString(bytes)) {
    throw invalid(name + " is not a " + Message::descriptor()->name() + " message");
  }
  return message;
}

pb::Summary ReadSummaryField(::google::protobuf::io::CodedInputStream& in,
                             const std::function<ParseError(const std::string&)>& invalid) {
  const auto summary = ReadBoundedMessageField<pb::Summary>(in, invalid, "summary field", 4096);
  if (const std::string problem = SummaryFieldProblem(summary); !problem.empty()) {
    throw invalid("summary field: " + problem);
  }
  return summary;
}

// The geo anchor of a payload's geo_anchor field whose tag `in` has just read, with
// GeoAnchorFromProto's checks; throws what `invalid(problem)` returns.
GeoAnchor ReadGeoAnchorField(::google::protobuf::io::CodedInputStream& in,
                             const std::function<ParseError(const std::string&)>& invalid) {
  // An anchor is about 100 bytes.
  const auto stored = ReadBoundedMessageField<pb::GeoAnchor>(in, invalid, "geo_anchor field", 1024);
  try {
    return GeoAnchorFromProto(stored, "geo_anchor");
  } catch (const InvalidArgumentError& error) {
    throw invalid(error.what());
  }
}

// a * b, or nullopt when the product does not fit in 64 bits (a forged count).
std::optional<uint64_t> CheckedMultiply(uint64_t a, uint64_t b) {
  uint64_t product = 0;
  if (__builtin_mul_overflow(a, b, &product)) return std::nullopt;
  return product;
}

// Copies a packed field into a vector of `count` elements; false when the sizes disagree. The
// element count is checked against the values the field holds (so against the bytes that were
// read) before anything is allocated, with a multiplication that cannot wrap.
template <typename Element, typename Value>
bool CopyFromRepeated(const google::protobuf::RepeatedField<Value>& field, uint64_t count,
                      std::vector<Element>* values) {
  constexpr size_t kValuesPerElement = sizeof(Element) / sizeof(Value);
  const std::optional<uint64_t> expected = CheckedMultiply(count, kValuesPerElement);
  if (!expected || *expected != static_cast<uint64_t>(field.size())) return false;
  values->resize(count);
  if (count > 0)
    std::memcpy(static_cast<void*>(values->data()), field.data(), count * sizeof(Element));
  return true;
}

// Reads the relocalization field; `payload_error` makes the ParseError naming the file. Sizes
// that disagree name the field; the values are checked by CheckRelocalizationData.
template <typename MakeError>
RelocalizationData RelocalizationFromProto(const pb::Relocalization& in,
                                           const MakeError& payload_error) {
  RelocalizationData data;
  const auto fail = [&](const std::string& field, size_t actual, const std::string& expected) {
    throw payload_error("relocalization." + field + " has " + std::to_string(actual) +
                        " values; expected " + expected);
  };
  if (!CopyFromRepeated(in.landmarks(), in.landmark_count(), &data.landmarks)) {
    fail("landmarks", static_cast<size_t>(in.landmarks_size()),
         "3 x " + std::to_string(in.landmark_count()) + " landmarks (landmark_count)");
  }
  data.vocabulary.assign(in.vocabulary().begin(), in.vocabulary().end());
  data.keyframes.resize(static_cast<size_t>(in.keyframes_size()));
  for (int k = 0; k < in.keyframes_size(); ++k) {
    const pb::KeyframeFeatures& features = in.keyframes(k);
    KeyframeFeatures& out = data.keyframes[static_cast<size_t>(k)];
    const std::string name = "keyframes[" + std::to_string(k) + "].";
    if (features.keypoints_size() % 2 != 0) {
      fail(name + "keypoints", static_cast<size_t>(features.keypoints_size()),
           "x y per keypoint (an even count)");
    }
    const uint64_t count = static_cast<uint64_t>(features.keypoints_size()) / 2;
    CopyFromRepeated(features.keypoints(), count, &out.keypoints);
    const std::optional<uint64_t> descriptor_bytes =
        CheckedMultiply(count, kRelocalizationDescriptorBytes);
    if (!descriptor_bytes || features.descriptors().size() != *descriptor_bytes) {
      throw payload_error("relocalization." + name + "descriptors has " +
                          std::to_string(features.descriptors().size()) + " bytes; expected " +
                          std::to_string(kRelocalizationDescriptorBytes) + " x " +
                          std::to_string(count) + " keypoints");
    }
    out.descriptors.assign(features.descriptors().begin(), features.descriptors().end());
    if (!CopyFromRepeated(features.landmarks(), count, &out.landmarks)) {
      fail(name + "landmarks", static_cast<size_t>(features.landmarks_size()),
           "one per keypoint (" + std::to_string(count) + ")");
    }
    out.global_descriptor.assign(features.global_descriptor().begin(),
                                 features.global_descriptor().end());
  }
  return data;
}

Map FromProto(const pb::MapFile& file, const std::string& source) {
  const auto payload_error = [&source](const std::string& what) {
    return ParseError::AtByte(source, kMapFileHeaderSize, "invalid evloc map payload: " + what);
  };
  if (file.units().length() != kLengthUnit || file.units().time() != kTimeUnit) {
    throw payload_error("units are length '" + file.units().length() + "', time '" +
                        file.units().time() + "'; expected 'm' and 'ns'");
  }
  Map map;
  map.provenance.tool = file.provenance().tool();
  map.provenance.tool_version = file.provenance().tool_version();
  map.provenance.created_utc = file.provenance().created_utc();
  map.provenance.command_line = file.provenance().command_line();
  map.provenance.inputs.assign(file.provenance().inputs().begin(),
                               file.provenance().inputs().end());
  map.keyframes.resize(static_cast<size_t>(file.keyframes_size()));
  try {
    for (int i = 0; i < file.cameras_size(); ++i) {
      map.cameras.push_back(CameraFromProto(file.cameras(i), "camera " + std::to_string(i)));
    }
    for (int i = 0; i < file.keyframes_size(); ++i) {
      // Not normalised, so that values round-trip bit for bit (the content checksum covers them).
      map.keyframes[static_cast<size_t>(i)].cam_from_world = RigidFromProtoExact(
          file.keyframes(i).cam_from_world(), "keyframe " + std::to_string(i) + " cam_from_world");
    }
  } catch (const InvalidArgumentError& error) {
    throw payload_error(error.what());
  }
  for (int i = 0; i < file.keyframes_size(); ++i) {
    const pb::Keyframe& in = file.keyframes(i);
    Keyframe& keyframe = map.keyframes[static_cast<size_t>(i)];
    keyframe.camera_index = in.camera_index();
    keyframe.t_ns = in.t_ns();
    keyframe.image_name = in.image_name();
    const auto& visible = in.visible_points();
    keyframe.visible_points.assign(visible.begin(), visible.end());
  }
  const pb::Points& points = file.points();
  const uint64_t count = points.count();
  const auto check = [&](bool ok, const char* name, int actual, int per_point) {
    if (!ok) {
      throw payload_error(std::string(name) + " has " + std::to_string(actual) +
                          " values; expected " + std::to_string(per_point) + " x " +
                          std::to_string(count) + " points");
    }
  };
  check(CopyFromRepeated(points.positions(), count, &map.positions), "positions",
        points.positions_size(), 3);
  check(CopyFromRepeated(points.gradients(), count, &map.gradients), "gradients",
        points.gradients_size(), 3);
  check(CopyFromRepeated(points.inverse_depth_sigma(), count, &map.inverse_depth_sigma),
        "inverse_depth_sigma", points.inverse_depth_sigma_size(), 1);
  check(CopyFromRepeated(points.gradient_magnitude(), count, &map.gradient_magnitude),
        "gradient_magnitude", points.gradient_magnitude_size(), 1);
  check(CopyFromRepeated(points.source_keyframe(), count, &map.source_keyframe), "source_keyframe",
        points.source_keyframe_size(), 1);
  if (file.has_relocalization()) {
    map.relocalization = RelocalizationFromProto(file.relocalization(), payload_error);
  }
  if (file.has_geo_anchor()) {
    try {
      map.geo_anchor = GeoAnchorFromProto(file.geo_anchor(), "geo_anchor");
    } catch (const InvalidArgumentError& error) {
      throw payload_error(error.what());
    }
  }
  return map;
}

// Decodes a payload whose header was checked (the bytes after the header); with
// `verify_checksums`, refuses it unless the payload and content checksums match.
Map ParsePayload(MapFileHeader header, std::string_view payload, const std::string& source,
                 bool verify_checksums = true) {
  if (payload.size() != header.payload_length) {
    throw ParseError::AtByte(source, kMapFileHeaderSize,
                             "truncated evloc map: the payload has " +
                                 std::to_string(payload.size()) + " bytes, the header says " +
                                 std::to_string(header.payload_length));
  }
  if (verify_checksums && Crc32c(payload) != header.payload_crc32c) {
    throw ParseError::AtByte(source, kMapFileHeaderSize,
                             "corrupted evloc map: payload checksum mismatch (the file was "
                             "damaged after it was written); re-copy or rebuild the map");
  }
  pb::MapFile file;
  if (!file.ParseFromArray(payload.data(), static_cast<int>(payload.size()))) {
    throw ParseError::AtByte(source, kMapFileHeaderSize,
                             "invalid evloc map payload: not a valid MapFile protobuf");
  }
  if (!verify_checksums) header.format_version = file.format_version();
  if (file.format_version() != header.format_version) {
    throw ParseError::AtByte(
        source, kMapFileHeaderSize,
        "invalid evloc map payload: format version " + std::to_string(file.format_version()) +
            " differs from the header's " + std::to_string(header.format_version));
  }
  if (header.format_version < 2 && file.has_relocalization()) {
    throw ParseError::AtByte(source, kMapFileHeaderSize,
                             "invalid evloc map payload: a format version 1 map carries the "
                             "version 2 relocalization field");
  }
  Map map = FromProto(file, source);
  if (verify_checksums && ComputeMapContentChecksum(map) != file.content_crc32c()) {
    throw ParseError::AtByte(source, kMapFileHeaderSize,
                             "invalid evloc map payload: content checksum mismatch (the writer "
                             "or reader is broken; report it)");
  }
  try {
    map.Check();
  } catch (const InvalidArgumentError& error) {
    throw ParseError::AtByte(source, kMapFileHeaderSize,
                             std::string("invalid evloc map content: ") + error.what());
  }
  // The summary as protobuf merges it (all occurrences of field 9) and, when the payload starts
  // with it, that first occurrence alone (what ReadMapFileSummary reads) must both describe the
  // content. Serialisation is deterministic for equal values: equal bytes, equal summaries.
  if (file.has_summary()) {
    const auto invalid = [&source](const std::string& what) {
      return ParseError::AtByte(source, kMapFileHeaderSize, "invalid evloc map payload: " + what);
    };
    const std::string expected = SummaryOf(map, file).SerializeAsString();
    const auto disagrees = [&](const pb::Summary& stored) {
      return stored.SerializeAsString() != expected;
    };
    bool wrong = disagrees(file.summary());
    ::google::protobuf::io::CodedInputStream in(reinterpret_cast<const uint8_t*>(payload.data()),
                                                static_cast<int>(payload.size()));
    const uint32_t tag = in.ReadTag();
    if (!wrong && WireFormatLite::GetTagFieldNumber(tag) == 9 &&
        WireFormatLite::GetTagWireType(tag) == WireFormatLite::WIRETYPE_LENGTH_DELIMITED) {
      wrong = disagrees(ReadSummaryField(in, invalid));
    }
    if (wrong) {
      throw invalid(
          "the summary field disagrees with the map's content (counts, bounding box or "
          "checksum); the file was edited by hand or by a broken writer: rebuild or re-save it");
    }
  }
  return map;
}

}  // namespace

void SaveMap(const std::filesystem::path& path, const Map& map) {
  map.Check();
  // The summary first, then the geo anchor, then the map: a summary reader stops after them.
  const pb::MapFile file = ToProto(map);
  pb::MapFile summary_only;
  *summary_only.mutable_summary() = SummaryOf(map, file);
  std::string payload = summary_only.SerializeAsString();
  if (map.geo_anchor) {
    pb::MapFile anchor_only;
    *anchor_only.mutable_geo_anchor() = GeoAnchorToProto(*map.geo_anchor);
    anchor_only.AppendToString(&payload);
  }
  if (!file.AppendToString(&payload)) {
    throw InvalidArgumentError("cannot serialise map for '" + path.string() +
                               "': the payload exceeds the protobuf limit of 2 GiB");
  }
  MapFileHeader header;
  header.format_version = kMapFormatVersion;
  header.payload_length = payload.size();
  header.payload_crc32c = Crc32c(payload);
  const HeaderBytes header_bytes = EncodeHeader(header);
  WriteFileAtomically(path, [&](std::ostream& stream) {
    stream.write(reinterpret_cast<const char*>(header_bytes.data()), header_bytes.size());
    stream.write(payload.data(), static_cast<std::streamsize>(payload.size()));
  });
}

uint64_t EncodedRelocalizationBytes(const RelocalizationData& data) {
  pb::MapFile file;
  *file.mutable_relocalization() = RelocalizationToProto(data);
  // And the summary's has_relocalization flag (the summary's own length stays one byte).
  pb::Summary flag;
  flag.set_has_relocalization(true);
  return file.ByteSizeLong() + flag.ByteSizeLong();
}

MapFileHeader ReadMapFileHeader(const std::filesystem::path& path) {
  std::ifstream stream;
  return ReadAndCheckHeader(path, stream);
}

MapFileSummary ReadMapFileSummary(const std::filesystem::path& path) {
  namespace io = ::google::protobuf::io;
  using WireFormat = WireFormatLite;
  const std::string source = path.string();
  MapFileSummary summary;
  std::ifstream stream;
  summary.header = ReadAndCheckHeader(path, stream);
  summary.file_bytes = kMapFileHeaderSize + summary.header.payload_length;
  summary.info.format_version = summary.header.format_version;
  stream.close();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw IoError("cannot open map '" + source + "': " + std::strerror(errno));
  io::FileInputStream file(fd);
  file.SetCloseOnDelete(true);
  if (!file.Skip(static_cast<int>(kMapFileHeaderSize))) {
    throw IoError("cannot read map '" + source + "': read error after the header");
  }
  io::LimitingInputStream payload(&file, static_cast<int64_t>(summary.header.payload_length));
  io::CodedInputStream in(&payload);
  const auto invalid = [&source](const std::string& what) {
    return ParseError::AtByte(source, kMapFileHeaderSize, "invalid evloc map payload: " + what);
  };
  uint64_t position_values = 0;
  Eigen::Vector3f position = Eigen::Vector3f::Zero();
  // One position value (x, y or z by its index) into the bounding box.
  const auto add_value = [&](uint32_t bits) {
    float value;
    std::memcpy(&value, &bits, sizeof(value));
    const int axis = static_cast<int>(position_values % 3);
    position[axis] = value;
    if (axis == 2) {
      if (position_values == 2) {
        summary.info.bounding_box_min = summary.info.bounding_box_max = position;
      } else {
        summary.info.bounding_box_min = summary.info.bounding_box_min.cwiseMin(position);
        summary.info.bounding_box_max = summary.info.bounding_box_max.cwiseMax(position);
      }
    }
    ++position_values;
  };
  const auto read_length = [&](const char* field) {
    uint32_t length = 0;
    if (!in.ReadVarint32(&length)) throw invalid(std::string("truncated ") + field);
    return static_cast<int>(length);
  };
  // A file written by SaveMap starts with its summary field (and geo anchor): the rest is not
  // read.
  uint32_t tag = in.ReadTag();
  if (WireFormat::GetTagFieldNumber(tag) == 9 &&
      WireFormat::GetTagWireType(tag) == WireFormat::WIRETYPE_LENGTH_DELIMITED) {
    const pb::Summary stored = ReadSummaryField(in, invalid);
    summary.info.num_points = stored.num_points();
    summary.info.num_keyframes = stored.num_keyframes();
    if (stored.bounding_box_size() == 6) {
      summary.info.bounding_box_min = {stored.bounding_box(0), stored.bounding_box(1),
                                       stored.bounding_box(2)};
      summary.info.bounding_box_max = {stored.bounding_box(3), stored.bounding_box(4),
                                       stored.bounding_box(5)};
    }
    summary.info.has_relocalization = stored.has_relocalization();
    summary.info.content_crc32c = stored.content_crc32c();
    // And the geo anchor SaveMap writes right after it.
    tag = in.ReadTag();
    if (WireFormat::GetTagFieldNumber(tag) == 10 &&
        WireFormat::GetTagWireType(tag) == WireFormat::WIRETYPE_LENGTH_DELIMITED) {
      summary.info.geo_anchor = ReadGeoAnchorField(in, invalid);
    }
    return summary;
  }
  for (; tag != 0; tag = in.ReadTag()) {
    const int field = WireFormat::GetTagFieldNumber(tag);
    const auto wire_type = WireFormat::GetTagWireType(tag);
    bool read = false;
    if (field == 5 && wire_type == WireFormat::WIRETYPE_LENGTH_DELIMITED) {
      ++summary.info.num_keyframes;
      read = in.Skip(read_length("keyframe"));
    } else if (field == 6 && wire_type == WireFormat::WIRETYPE_LENGTH_DELIMITED) {
      const io::CodedInputStream::Limit points = in.PushLimit(read_length("points"));
      while (const uint32_t point_tag = in.ReadTag()) {
        const int point_field = WireFormat::GetTagFieldNumber(point_tag);
        const auto point_wire_type = WireFormat::GetTagWireType(point_tag);
        if (point_field == 1 && point_wire_type == WireFormat::WIRETYPE_VARINT) {
          if (!in.ReadVarint64(&summary.info.num_points)) throw invalid("truncated points.count");
        } else if (point_field == 2 && point_wire_type == WireFormat::WIRETYPE_LENGTH_DELIMITED) {
          const int length = read_length("points.positions");
          if (length % 4 != 0) throw invalid("points.positions is not a whole number of floats");
          for (int i = 0; i < length / 4; ++i) {
            uint32_t bits = 0;
            if (!in.ReadLittleEndian32(&bits)) throw invalid("truncated points.positions");
            add_value(bits);
          }
        } else if (point_field == 2 && point_wire_type == WireFormat::WIRETYPE_FIXED32) {
          uint32_t bits = 0;
          if (!in.ReadLittleEndian32(&bits)) throw invalid("truncated points.positions");
          add_value(bits);
        } else if (!WireFormat::SkipField(&in, point_tag)) {
          throw invalid("truncated points field " + std::to_string(point_field));
        }
      }
      if (!in.ConsumedEntireMessage()) throw invalid("malformed points message");
      in.PopLimit(points);
      read = true;
    } else if (field == 7 && wire_type == WireFormat::WIRETYPE_FIXED32) {
      read = in.ReadLittleEndian32(&summary.info.content_crc32c);
    } else if (field == 10 && wire_type == WireFormat::WIRETYPE_LENGTH_DELIMITED) {
      // The last occurrence (protobuf would merge several; LoadMap checks the merged one).
      summary.info.geo_anchor = ReadGeoAnchorField(in, invalid);
      read = true;
    } else {
      // As protobuf: a known field with another wire type is an unknown field.
      if (field == 8 && wire_type == WireFormat::WIRETYPE_LENGTH_DELIMITED) {
        summary.info.has_relocalization = true;
      }
      read = WireFormat::SkipField(&in, tag);
    }
    if (!read) throw invalid("truncated field " + std::to_string(field));
  }
  if (!in.ConsumedEntireMessage() ||
      payload.ByteCount() != static_cast<int64_t>(summary.header.payload_length)) {
    throw invalid("not a valid MapFile protobuf");
  }
  const std::optional<uint64_t> expected_values = CheckedMultiply(summary.info.num_points, 3);
  if (!expected_values || *expected_values != position_values) {
    throw invalid("positions has " + std::to_string(position_values) + " values; expected 3 x " +
                  std::to_string(summary.info.num_points) + " points");
  }
  return summary;
}

Map LoadMap(const std::filesystem::path& path) {
  const std::string source = path.string();
  std::ifstream stream;
  const MapFileHeader header = ReadAndCheckHeader(path, stream);
  if (header.payload_length > static_cast<uint64_t>(std::numeric_limits<int>::max())) {
    throw ParseError::AtByte(source, kPayloadLengthOffset,
                             "evloc map payload of " + std::to_string(header.payload_length) +
                                 " bytes exceeds the protobuf limit of 2 GiB");
  }
  std::string payload(header.payload_length, '\0');
  stream.read(payload.data(), static_cast<std::streamsize>(payload.size()));
  if (static_cast<uint64_t>(stream.gcount()) != header.payload_length) {
    throw IoError("cannot read map '" + source + "': read error in the payload");
  }
  return ParsePayload(header, payload, source);
}

Map DecodeMapPayloadUnchecked(std::string_view payload, const std::string& source) {
  MapFileHeader header;
  header.payload_length = payload.size();
  return ParsePayload(header, payload, source, /*verify_checksums=*/false);
}

Map LoadMapFromBytes(std::string_view bytes, const std::string& source) {
  HeaderBytes header_bytes{};
  const size_t header_size = std::min(bytes.size(), kMapFileHeaderSize);
  std::memcpy(header_bytes.data(), bytes.data(), header_size);
  const MapFileHeader header = CheckHeader(header_bytes, header_size, bytes.size(), source);
  if (header.payload_length > static_cast<uint64_t>(std::numeric_limits<int>::max())) {
    throw ParseError::AtByte(source, kPayloadLengthOffset,
                             "evloc map payload of " + std::to_string(header.payload_length) +
                                 " bytes exceeds the protobuf limit of 2 GiB");
  }
  return ParsePayload(header, bytes.substr(kMapFileHeaderSize), source);
}

}  // namespace evloc
