// The evloc map (docs/map-format.md, docs/map-format.md): semi-dense, gradient-augmented points
// of appearance edges, the keyframes they were built from, and the cameras of those keyframes.
// This is the contract between the mapper and the localizer.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/camera/camera.h"
#include "core/geo/geo_anchor.h"
#include "core/geometry/rigid3.h"

namespace evloc {

// Marks a point that was not triangulated in any keyframe (for example an imported PCD point).
inline constexpr uint32_t kNoKeyframe = 0xffffffff;

// The format version of .evmap files written by SaveMap (2: optional relocalization data; LoadMap
// also reads version 1, which has none).
inline constexpr uint32_t kMapFormatVersion = 2;

// A camera pose from which part of the map was built.
struct Keyframe {
  // Pose: p_cam = cam_from_world * p_world.
  Rigid3d cam_from_world;
  // Index into Map::cameras.
  uint32_t camera_index = 0;
  // Capture time, nanoseconds.
  int64_t t_ns = 0;
  // Name of the source image (relative path as given to the mapper); may be empty.
  std::string image_name;
  // Indices into the point arrays of the points this keyframe sees, strictly increasing.
  std::vector<uint32_t> visible_points;
};

// Who made a map, from what, and when.
struct MapProvenance {
  // Program that wrote the map, e.g. "evloc-mapper import-pcd".
  std::string tool;
  // Version of that program.
  std::string tool_version;
  // Creation time, UTC, ISO 8601 with a trailing Z ("2024-05-01T12:00:00Z").
  std::string created_utc;
  // Command line that produced the map.
  std::string command_line;
  // Input files or data sets the map was built from.
  std::vector<std::string> inputs;
};

// The local features of one keyframe that see a relocalization landmark (map format v2).
struct KeyframeFeatures {
  // Feature positions in the keyframe's image, pixels (centres at integer coordinates).
  std::vector<Eigen::Vector2f> keypoints;
  // Descriptors, kRelocalizationDescriptorBytes bytes per keypoint, row-major (root-SIFT of
  // core/features, quantised to uint8).
  std::vector<uint8_t> descriptors;
  // Index into RelocalizationData::landmarks of the 3D point each keypoint sees.
  std::vector<uint32_t> landmarks;
  // Global descriptor of the keyframe image (VLAD over RelocalizationData::vocabulary), unit
  // L2 norm; vocabulary words x kRelocalizationDescriptorBytes floats.
  std::vector<float> global_descriptor;
};

// Bytes of one local feature descriptor in the map (SIFT: 128).
inline constexpr size_t kRelocalizationDescriptorBytes = 128;

// What global relocalization needs beyond the edge map (map format v2): sparse 3D landmarks, the
// features of every keyframe that see them, a visual vocabulary and each keyframe's global
// descriptor. Absent from v1 maps and from imported maps.
struct RelocalizationData {
  // Landmark positions p_world, metres.
  std::vector<Eigen::Vector3f> landmarks;
  // Visual words, row-major, words x kRelocalizationDescriptorBytes floats (the
  // core/features Vocabulary::ToVector layout).
  std::vector<float> vocabulary;
  // Per keyframe, in the order of Map::keyframes (same size).
  std::vector<KeyframeFeatures> keyframes;
};

// A semi-dense point map. Per-point data is struct-of-arrays: every per-point vector has size().
struct Map {
  // Positions p_world, metres.
  std::vector<Eigen::Vector3f> positions;
  // Unit 3D gradient directions g_world (docs/mapper.md, "3D gradients").
  std::vector<Eigen::Vector3f> gradients;
  // Standard deviation of the inverse depth, 1/m; 0 when unknown.
  std::vector<float> inverse_depth_sigma;
  // Image gradient modulus at the source pixel (intensity in [0, 1] per pixel); 0 when unknown.
  std::vector<float> gradient_magnitude;
  // Index into keyframes of the point's source keyframe, or kNoKeyframe.
  std::vector<uint32_t> source_keyframe;
  // Keyframes; empty for imported maps.
  std::vector<Keyframe> keyframes;
  // Cameras referenced by Keyframe::camera_index.
  std::vector<Camera> cameras;
  // How the map was made.
  MapProvenance provenance;
  // Relocalization data (format v2); nullopt for v1 and imported maps.
  std::optional<RelocalizationData> relocalization;
  // Where the map is on the Earth (docs/geo.md); nullopt for a map without geo-reference.
  std::optional<GeoAnchor> geo_anchor;

  // Number of points.
  size_t size() const { return positions.size(); }
  // Appends one point with the given attributes.
  void AddPoint(const Eigen::Vector3f& position, const Eigen::Vector3f& gradient,
                float point_inverse_depth_sigma = 0.0f, float point_gradient_magnitude = 0.0f,
                uint32_t point_source_keyframe = kNoKeyframe);
  // Pre-allocates room for `count` points.
  void Reserve(size_t count);
  // Throws InvalidArgumentError naming the first bad element unless: every per-point vector has
  // size() entries; positions are finite; gradients are unit vectors (|g| within 1e-3 of 1);
  // sigmas and magnitudes are finite and >= 0; source keyframes are valid indices or
  // kNoKeyframe; keyframe poses are finite with unit quaternions, camera indices valid, visible
  // points valid and strictly increasing; every camera passes Camera::Check(); and, with
  // relocalization data, CheckRelocalizationData(*this); and a geo anchor passes
  // GeoAnchor::Check().
  void Check() const;
};

// Throws InvalidArgumentError naming the first bad element unless map.relocalization is absent or
// consistent: one feature set per keyframe; finite landmarks; a non-empty vocabulary of finite
// values, a multiple of kRelocalizationDescriptorBytes long; per keyframe finite keypoints,
// kRelocalizationDescriptorBytes descriptor bytes and one valid landmark index per keypoint, and
// a finite global descriptor as long as the vocabulary with unit (or zero) L2 norm.
void CheckRelocalizationData(const Map& map);

// True when `map` carries relocalization data with at least one landmark.
bool HasRelocalizationData(const Map& map);

// The message for a relocalization request on a map without relocalization data (v1 or
// imported), naming `map_path` and how to upgrade it; the CLI and the service use these words.
std::string MissingRelocalizationDataMessage(const std::string& map_path);

// Throws InvalidArgumentError with MissingRelocalizationDataMessage(map_path) unless
// HasRelocalizationData(map).
void RequireRelocalizationData(const Map& map, const std::string& map_path);

// Allowed deviation of |gradient| from 1 in Map::Check().
inline constexpr float kGradientNormTolerance = 1e-3f;

// Allowed deviation of a keyframe's global descriptor L2 norm from 1 in CheckRelocalizationData.
inline constexpr double kGlobalDescriptorNormTolerance = 1e-3;

// CRC32C (Castagnoli) of the map content (points, cameras, keyframes, then the relocalization data
// when present; not provenance, not the geo anchor: readers older than the anchor load anchored
// maps) in the canonical little-endian layout of docs/map-format.md. Equal content gives an equal
// value; a map without relocalization data has its v1 value.
uint32_t ComputeMapContentChecksum(const Map& map);

// Writes `map` to a .evmap file (header + protobuf payload, docs/map-format.md), atomically: a
// crash or error never leaves a half-written `path`. Calls map.Check() first (throws
// InvalidArgumentError) and throws IoError when the file cannot be written.
void SaveMap(const std::filesystem::path& path, const Map& map);

// Bytes the relocalization data adds to a .evmap file (its encoded protobuf field and the
// summary's flag that says the file has it).
uint64_t EncodedRelocalizationBytes(const RelocalizationData& data);

// Reads a .evmap file (format version 1 or 2) and verifies it: magic ("not an evloc map"), format
// version, payload length (truncated files), payload checksum, content checksum, and Map::Check().
// Throws IoError when the file cannot be read and ParseError naming the file and byte offset when
// it is not a valid map.
Map LoadMap(const std::filesystem::path& path);

// Reads a whole .evmap file held in memory (`source` names it in errors), with LoadMap's checks
// and errors (ParseError only): for maps received over the network and for the fuzzer.
Map LoadMapFromBytes(std::string_view bytes, const std::string& source);

// Decodes a MapFile protobuf payload (the bytes after the header) without the payload and
// content checksums but with every other check of LoadMap (units, sizes, Map::Check()); throws
// ParseError. For the fuzzer, whose mutations would otherwise stop at the checksums.
Map DecodeMapPayloadUnchecked(std::string_view payload, const std::string& source);

// The fixed-size header of a .evmap file.
struct MapFileHeader {
  // Format version of the payload.
  uint32_t format_version = 0;
  // Payload length, bytes.
  uint64_t payload_length = 0;
  // CRC32C of the payload bytes.
  uint32_t payload_crc32c = 0;
};

// Size of the .evmap header, bytes.
inline constexpr size_t kMapFileHeaderSize = 32;

// Reads and validates only the header of a .evmap file (magic, version, header checksum, and that
// the file holds payload_length bytes after it). Throws like LoadMap.
MapFileHeader ReadMapFileHeader(const std::filesystem::path& path);

// A summary of a map for humans and logs.
struct MapInfo {
  // Number of points.
  size_t num_points = 0;
  // Number of keyframes.
  size_t num_keyframes = 0;
  // Number of cameras.
  size_t num_cameras = 0;
  // Sum over keyframes of their visible point counts.
  size_t num_visibility_entries = 0;
  // Points with a known (non-zero) inverse-depth sigma.
  size_t num_points_with_inverse_depth_sigma = 0;
  // Points with a known (non-zero) gradient magnitude.
  size_t num_points_with_gradient_magnitude = 0;
  // Points with a source keyframe.
  size_t num_points_with_source_keyframe = 0;
  // Axis-aligned bounding box of the positions, metres (zero for an empty map).
  Eigen::Vector3f bounding_box_min = Eigen::Vector3f::Zero();
  // Upper corner of the bounding box, metres.
  Eigen::Vector3f bounding_box_max = Eigen::Vector3f::Zero();
  // Median inverse-depth sigma over points where it is known, 1/m; 0 when none is.
  float median_inverse_depth_sigma = 0.0f;
  // Earliest and latest keyframe time, nanoseconds (0 without keyframes).
  int64_t first_keyframe_t_ns = 0;
  // Latest keyframe time, nanoseconds.
  int64_t last_keyframe_t_ns = 0;
  // ComputeMapContentChecksum of the map.
  uint32_t content_crc32c = 0;
  // Whether the map carries relocalization data (format v2).
  bool has_relocalization = false;
  // Relocalization landmarks.
  size_t num_landmarks = 0;
  // Keyframe features that see a landmark, summed over keyframes.
  size_t num_relocalization_features = 0;
  // Words of the relocalization vocabulary.
  size_t num_vocabulary_words = 0;
  // The map's geo anchor, if it has one.
  std::optional<GeoAnchor> geo_anchor;
  // Format version the map is (or would be) stored with.
  uint32_t format_version = kMapFormatVersion;
  // Provenance of the map.
  MapProvenance provenance;
  // Cameras, as one line each ("pinhole 640x480 fx=... ").
  std::vector<std::string> camera_descriptions;

  // bounding_box_max - bounding_box_min, metres.
  Eigen::Vector3f Extent() const { return bounding_box_max - bounding_box_min; }
};

// Summarises a map.
MapInfo SummarizeMap(const Map& map);

// Axis-aligned bounding box of `positions` as {min, max}; both zero when there are none.
std::pair<Eigen::Vector3f, Eigen::Vector3f> BoundingBox(
    const std::vector<Eigen::Vector3f>& positions);

// What ReadMapFileSummary reads of a .evmap file without loading its points.
struct MapFileSummary {
  // The file's header.
  MapFileHeader header;
  // Size of the file, bytes.
  uint64_t file_bytes = 0;
  // As SummarizeMap gives them: num_points, num_keyframes, the bounding box, content_crc32c (the
  // checksum the file declares), has_relocalization, geo_anchor and format_version; the rest is
  // left unset.
  MapInfo info;
};

// Reads what describes a map (header, point and keyframe counts, bounding box, content checksum)
// with constant memory. A file whose payload starts with the summary field (every file SaveMap
// writes) is read no further than that field; otherwise (files of earlier writers) it streams
// through the payload: the positions are read for the bounding box, every other field (keyframe
// contents, the other per-point arrays, relocalization data) is skipped. Checks the header like
// ReadMapFileHeader and the structure of what it reads, but not the payload checksum nor that the
// summary agrees with the content (LoadMap does): a file that summarises may still fail LoadMap.
// Throws IoError when the file cannot be read and ParseError when it is not a valid map.
MapFileSummary ReadMapFileSummary(const std::filesystem::path& path);

// A readable multi-line description of `info`, for the CLI and logs.
std::string FormatMapInfo(const MapInfo& info);

}  // namespace evloc
