#include "maps/map.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <tuple>

#include "core/common/error.h"
#include "maps/crc32c.h"

namespace evloc {
namespace {

static_assert(std::endian::native == std::endian::little,
              "the canonical map layout is little-endian; add byte swapping for this host");

std::string PointName(size_t index) { return "map point " + std::to_string(index); }

std::string FormatVector(const Eigen::Vector3f& vector) {
  std::ostringstream text;
  text << "(" << vector.x() << ", " << vector.y() << ", " << vector.z() << ")";
  return text.str();
}

// Feeds values in the canonical little-endian layout into a running CRC32C.
class ContentHasher {
 public:
  template <typename T>
  void Add(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    crc_ = ExtendCrc32c(crc_, &value, sizeof(T));
  }
  void AddBytes(const void* data, size_t size) { crc_ = ExtendCrc32c(crc_, data, size); }
  uint32_t crc() const { return crc_; }

 private:
  uint32_t crc_ = 0;
};

// Numeric model codes of the canonical layout (equal to the proto enum values).
uint32_t CameraModelCode(CameraModel model) {
  switch (model) {
    case CameraModel::kPinhole:
      return 1;
    case CameraModel::kRadialTangential:
      return 2;
    case CameraModel::kEquidistant:
      return 3;
  }
  return 0;
}

}  // namespace

void Map::AddPoint(const Eigen::Vector3f& position, const Eigen::Vector3f& gradient,
                   float point_inverse_depth_sigma, float point_gradient_magnitude,
                   uint32_t point_source_keyframe) {
  positions.push_back(position);
  gradients.push_back(gradient);
  inverse_depth_sigma.push_back(point_inverse_depth_sigma);
  gradient_magnitude.push_back(point_gradient_magnitude);
  source_keyframe.push_back(point_source_keyframe);
}

void Map::Reserve(size_t count) {
  positions.reserve(count);
  gradients.reserve(count);
  inverse_depth_sigma.reserve(count);
  gradient_magnitude.reserve(count);
  source_keyframe.reserve(count);
}

void Map::Check() const {
  const size_t count = size();
  const auto check_size = [count](size_t actual, const char* name) {
    if (actual != count) {
      throw InvalidArgumentError("map has " + std::to_string(count) + " positions but " +
                                 std::to_string(actual) + " " + name +
                                 "; every per-point array needs one entry per point");
    }
  };
  check_size(gradients.size(), "gradients");
  check_size(inverse_depth_sigma.size(), "inverse-depth sigmas");
  check_size(gradient_magnitude.size(), "gradient magnitudes");
  check_size(source_keyframe.size(), "source keyframes");
  if (count > kNoKeyframe) {
    throw InvalidArgumentError("map has " + std::to_string(count) +
                               " points; point indices are 32-bit, at most 4294967295");
  }

  for (size_t i = 0; i < cameras.size(); ++i) {
    try {
      cameras[i].Check();
    } catch (const InvalidArgumentError& error) {
      throw InvalidArgumentError("map camera " + std::to_string(i) + ": " + error.what());
    }
  }
  for (size_t i = 0; i < count; ++i) {
    if (!positions[i].allFinite()) {
      throw InvalidArgumentError(PointName(i) + " has a non-finite position " +
                                 FormatVector(positions[i]));
    }
    const float norm = gradients[i].norm();
    if (!std::isfinite(norm) || std::abs(norm - 1.0f) > kGradientNormTolerance) {
      throw InvalidArgumentError(PointName(i) + " has gradient " + FormatVector(gradients[i]) +
                                 " of length " + std::to_string(norm) +
                                 "; gradients must be unit vectors");
    }
    if (!std::isfinite(inverse_depth_sigma[i]) || inverse_depth_sigma[i] < 0.0f) {
      throw InvalidArgumentError(PointName(i) + " has inverse-depth sigma " +
                                 std::to_string(inverse_depth_sigma[i]) +
                                 "; it must be finite and >= 0 (0 = unknown)");
    }
    if (!std::isfinite(gradient_magnitude[i]) || gradient_magnitude[i] < 0.0f) {
      throw InvalidArgumentError(PointName(i) + " has gradient magnitude " +
                                 std::to_string(gradient_magnitude[i]) +
                                 "; it must be finite and >= 0 (0 = unknown)");
    }
    if (source_keyframe[i] != kNoKeyframe && source_keyframe[i] >= keyframes.size()) {
      throw InvalidArgumentError(PointName(i) + " has source keyframe " +
                                 std::to_string(source_keyframe[i]) + " but the map has " +
                                 std::to_string(keyframes.size()) + " keyframes");
    }
  }
  for (size_t k = 0; k < keyframes.size(); ++k) {
    const Keyframe& keyframe = keyframes[k];
    const std::string name = "map keyframe " + std::to_string(k);
    if (!keyframe.cam_from_world.IsFinite()) {
      throw InvalidArgumentError(name + " has a non-finite pose");
    }
    if (std::abs(keyframe.cam_from_world.rotation.norm() - 1.0) > 1e-6) {
      throw InvalidArgumentError(name + " has a rotation quaternion of norm " +
                                 std::to_string(keyframe.cam_from_world.rotation.norm()) +
                                 "; it must be a unit quaternion");
    }
    if (keyframe.camera_index >= cameras.size()) {
      throw InvalidArgumentError(name + " uses camera " + std::to_string(keyframe.camera_index) +
                                 " but the map has " + std::to_string(cameras.size()) + " cameras");
    }
    for (size_t j = 0; j < keyframe.visible_points.size(); ++j) {
      const uint32_t point = keyframe.visible_points[j];
      if (point >= count) {
        throw InvalidArgumentError(name + " lists visible point " + std::to_string(point) +
                                   " (entry " + std::to_string(j) + ") but the map has " +
                                   std::to_string(count) + " points");
      }
      if (j > 0 && point <= keyframe.visible_points[j - 1]) {
        throw InvalidArgumentError(name + " visible points are not strictly increasing at entry " +
                                   std::to_string(j) + " (" +
                                   std::to_string(keyframe.visible_points[j - 1]) + " then " +
                                   std::to_string(point) + "); sort them and remove duplicates");
      }
    }
  }
  CheckRelocalizationData(*this);
  if (geo_anchor) geo_anchor->Check();
}

void CheckRelocalizationData(const Map& map) {
  if (!map.relocalization) return;
  const RelocalizationData& data = *map.relocalization;
  const std::string prefix = "map relocalization data: ";
  if (data.keyframes.size() != map.keyframes.size()) {
    throw InvalidArgumentError(
        prefix + "has feature sets for " + std::to_string(data.keyframes.size()) +
        " keyframes but the map has " + std::to_string(map.keyframes.size()) + " keyframes");
  }
  if (data.landmarks.size() >= kNoKeyframe) {
    throw InvalidArgumentError(prefix + "has " + std::to_string(data.landmarks.size()) +
                               " landmarks; landmark indices are 32-bit");
  }
  for (size_t i = 0; i < data.landmarks.size(); ++i) {
    if (!data.landmarks[i].allFinite()) {
      throw InvalidArgumentError(prefix + "landmark " + std::to_string(i) +
                                 " has a non-finite position " + FormatVector(data.landmarks[i]));
    }
  }
  if (data.vocabulary.empty() || data.vocabulary.size() % kRelocalizationDescriptorBytes != 0) {
    throw InvalidArgumentError(prefix + "the vocabulary has " +
                               std::to_string(data.vocabulary.size()) +
                               " values; expected words x " +
                               std::to_string(kRelocalizationDescriptorBytes) + " with words >= 1");
  }
  for (size_t i = 0; i < data.vocabulary.size(); ++i) {
    if (!std::isfinite(data.vocabulary[i])) {
      throw InvalidArgumentError(prefix + "vocabulary value " + std::to_string(i) +
                                 " is not finite");
    }
  }
  for (size_t k = 0; k < data.keyframes.size(); ++k) {
    const KeyframeFeatures& features = data.keyframes[k];
    const std::string name = prefix + "keyframe " + std::to_string(k);
    const size_t count = features.keypoints.size();
    if (features.descriptors.size() != count * kRelocalizationDescriptorBytes) {
      throw InvalidArgumentError(name + " has " + std::to_string(features.descriptors.size()) +
                                 " descriptor bytes for " + std::to_string(count) +
                                 " keypoints; expected keypoints x " +
                                 std::to_string(kRelocalizationDescriptorBytes));
    }
    if (features.landmarks.size() != count) {
      throw InvalidArgumentError(name + " has " + std::to_string(features.landmarks.size()) +
                                 " landmark indices for " + std::to_string(count) +
                                 " keypoints; expected one per keypoint");
    }
    for (size_t i = 0; i < count; ++i) {
      if (!features.keypoints[i].allFinite()) {
        throw InvalidArgumentError(name + " keypoint " + std::to_string(i) + " is not finite");
      }
      if (features.landmarks[i] >= data.landmarks.size()) {
        throw InvalidArgumentError(name + " keypoint " + std::to_string(i) + " sees landmark " +
                                   std::to_string(features.landmarks[i]) + " but there are " +
                                   std::to_string(data.landmarks.size()) + " landmarks");
      }
    }
    if (features.global_descriptor.size() != data.vocabulary.size()) {
      throw InvalidArgumentError(name + " has a global descriptor of " +
                                 std::to_string(features.global_descriptor.size()) +
                                 " values; expected the vocabulary size " +
                                 std::to_string(data.vocabulary.size()));
    }
    double squared_norm = 0.0;
    for (const float value : features.global_descriptor) {
      if (!std::isfinite(value)) {
        throw InvalidArgumentError(name + " has a non-finite global descriptor value");
      }
      squared_norm += static_cast<double>(value) * value;
    }
    const double norm = std::sqrt(squared_norm);
    if (norm != 0.0 && std::abs(norm - 1.0) > kGlobalDescriptorNormTolerance) {
      throw InvalidArgumentError(name + " has a global descriptor of L2 norm " +
                                 std::to_string(norm) + "; it must be 1 (or 0 without features)");
    }
  }
}

bool HasRelocalizationData(const Map& map) {
  return map.relocalization.has_value() && !map.relocalization->landmarks.empty();
}

std::string MissingRelocalizationDataMessage(const std::string& map_path) {
  return map_path +
         " has no relocalization data (format v1 or imported); run `evloc-mapper upgrade --map " +
         map_path + " --images DIR` or rebuild it with evloc-mapper build";
}

void RequireRelocalizationData(const Map& map, const std::string& map_path) {
  if (!HasRelocalizationData(map)) {
    throw InvalidArgumentError(MissingRelocalizationDataMessage(map_path));
  }
}

uint32_t ComputeMapContentChecksum(const Map& map) {
  ContentHasher hasher;
  const size_t count = map.size();
  hasher.Add(static_cast<uint64_t>(count));
  // Vector3f is three packed floats (no padding), so the arrays hash as raw bytes.
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float));
  hasher.AddBytes(map.positions.data(), count * sizeof(Eigen::Vector3f));
  hasher.AddBytes(map.gradients.data(), map.gradients.size() * sizeof(Eigen::Vector3f));
  hasher.AddBytes(map.inverse_depth_sigma.data(), map.inverse_depth_sigma.size() * sizeof(float));
  hasher.AddBytes(map.gradient_magnitude.data(), map.gradient_magnitude.size() * sizeof(float));
  hasher.AddBytes(map.source_keyframe.data(), map.source_keyframe.size() * sizeof(uint32_t));
  hasher.Add(static_cast<uint64_t>(map.cameras.size()));
  for (const Camera& camera : map.cameras) {
    hasher.Add(CameraModelCode(camera.model));
    hasher.Add(static_cast<uint32_t>(camera.width));
    hasher.Add(static_cast<uint32_t>(camera.height));
    hasher.Add(camera.fx);
    hasher.Add(camera.fy);
    hasher.Add(camera.cx);
    hasher.Add(camera.cy);
    hasher.Add(static_cast<uint64_t>(camera.distortion.size()));
    hasher.AddBytes(camera.distortion.data(), camera.distortion.size() * sizeof(double));
  }
  hasher.Add(static_cast<uint64_t>(map.keyframes.size()));
  for (const Keyframe& keyframe : map.keyframes) {
    const Eigen::Quaterniond& rotation = keyframe.cam_from_world.rotation;
    const Eigen::Vector3d& translation = keyframe.cam_from_world.translation;
    for (const double value : {rotation.w(), rotation.x(), rotation.y(), rotation.z(),
                               translation.x(), translation.y(), translation.z()}) {
      hasher.Add(value);
    }
    hasher.Add(keyframe.camera_index);
    hasher.Add(keyframe.t_ns);
    hasher.Add(static_cast<uint64_t>(keyframe.image_name.size()));
    hasher.AddBytes(keyframe.image_name.data(), keyframe.image_name.size());
    hasher.Add(static_cast<uint64_t>(keyframe.visible_points.size()));
    hasher.AddBytes(keyframe.visible_points.data(),
                    keyframe.visible_points.size() * sizeof(uint32_t));
  }
  // Relocalization data (v2) only when present: a map without it keeps its v1 checksum.
  if (map.relocalization) {
    const RelocalizationData& data = *map.relocalization;
    const auto add_array = [&hasher](const auto& values) {
      using Value = typename std::decay_t<decltype(values)>::value_type;
      hasher.Add(static_cast<uint64_t>(values.size()));
      hasher.AddBytes(values.data(), values.size() * sizeof(Value));
    };
    static_assert(sizeof(Eigen::Vector2f) == 2 * sizeof(float));
    add_array(data.landmarks);
    add_array(data.vocabulary);
    hasher.Add(static_cast<uint64_t>(data.keyframes.size()));
    for (const KeyframeFeatures& features : data.keyframes) {
      add_array(features.keypoints);
      add_array(features.descriptors);
      add_array(features.landmarks);
      add_array(features.global_descriptor);
    }
  }
  return hasher.crc();
}

std::pair<Eigen::Vector3f, Eigen::Vector3f> BoundingBox(
    const std::vector<Eigen::Vector3f>& positions) {
  if (positions.empty()) return {Eigen::Vector3f::Zero(), Eigen::Vector3f::Zero()};
  std::pair<Eigen::Vector3f, Eigen::Vector3f> box{positions.front(), positions.front()};
  for (const Eigen::Vector3f& position : positions) {
    box.first = box.first.cwiseMin(position);
    box.second = box.second.cwiseMax(position);
  }
  return box;
}

MapInfo SummarizeMap(const Map& map) {
  MapInfo info;
  info.num_points = map.size();
  info.num_keyframes = map.keyframes.size();
  info.num_cameras = map.cameras.size();
  for (const Keyframe& keyframe : map.keyframes) {
    info.num_visibility_entries += keyframe.visible_points.size();
  }
  std::tie(info.bounding_box_min, info.bounding_box_max) = BoundingBox(map.positions);
  std::vector<float> known_sigmas;
  for (const float sigma : map.inverse_depth_sigma) {
    if (sigma > 0.0f) known_sigmas.push_back(sigma);
  }
  info.num_points_with_inverse_depth_sigma = known_sigmas.size();
  if (!known_sigmas.empty()) {
    auto middle = known_sigmas.begin() + known_sigmas.size() / 2;
    std::nth_element(known_sigmas.begin(), middle, known_sigmas.end());
    info.median_inverse_depth_sigma = *middle;
  }
  info.num_points_with_gradient_magnitude = static_cast<size_t>(std::count_if(
      map.gradient_magnitude.begin(), map.gradient_magnitude.end(), [](float m) { return m > 0; }));
  info.num_points_with_source_keyframe =
      static_cast<size_t>(std::count_if(map.source_keyframe.begin(), map.source_keyframe.end(),
                                        [](uint32_t k) { return k != kNoKeyframe; }));
  if (!map.keyframes.empty()) {
    const auto [earliest, latest] =
        std::minmax_element(map.keyframes.begin(), map.keyframes.end(),
                            [](const Keyframe& a, const Keyframe& b) { return a.t_ns < b.t_ns; });
    info.first_keyframe_t_ns = earliest->t_ns;
    info.last_keyframe_t_ns = latest->t_ns;
  }
  info.content_crc32c = ComputeMapContentChecksum(map);
  if (map.relocalization) {
    info.has_relocalization = true;
    info.num_landmarks = map.relocalization->landmarks.size();
    info.num_vocabulary_words =
        map.relocalization->vocabulary.size() / kRelocalizationDescriptorBytes;
    for (const KeyframeFeatures& features : map.relocalization->keyframes) {
      info.num_relocalization_features += features.keypoints.size();
    }
  }
  info.geo_anchor = map.geo_anchor;
  info.provenance = map.provenance;
  for (const Camera& camera : map.cameras) {
    std::ostringstream text;
    text << CameraModelName(camera.model) << " " << camera.width << "x" << camera.height
         << " fx=" << camera.fx << " fy=" << camera.fy << " cx=" << camera.cx
         << " cy=" << camera.cy;
    if (!camera.distortion.empty()) {
      text << " distortion=[";
      for (size_t i = 0; i < camera.distortion.size(); ++i) {
        text << (i ? " " : "") << camera.distortion[i];
      }
      text << "]";
    }
    info.camera_descriptions.push_back(text.str());
  }
  return info;
}

std::string FormatMapInfo(const MapInfo& info) {
  std::ostringstream text;
  text << std::fixed << std::setprecision(3);
  const auto percent = [&info](size_t part) {
    return info.num_points == 0 ? 0.0 : 100.0 * static_cast<double>(part) / info.num_points;
  };
  text << "format version:   " << info.format_version << "\n";
  text << "content CRC32C:   " << std::hex << std::setw(8) << std::setfill('0')
       << info.content_crc32c << std::dec << std::setfill(' ') << "\n";
  text << "points:           " << info.num_points << "\n";
  text << "  with inverse-depth sigma: " << info.num_points_with_inverse_depth_sigma << " ("
       << std::setprecision(1) << percent(info.num_points_with_inverse_depth_sigma) << "%), median "
       << std::setprecision(4) << info.median_inverse_depth_sigma << " 1/m\n";
  text << "  with gradient magnitude:  " << info.num_points_with_gradient_magnitude << " ("
       << std::setprecision(1) << percent(info.num_points_with_gradient_magnitude) << "%)\n";
  text << "  with source keyframe:     " << info.num_points_with_source_keyframe << " ("
       << percent(info.num_points_with_source_keyframe) << "%)\n";
  text << std::setprecision(3);
  const auto vector = [&text](const Eigen::Vector3f& v) {
    text << "[" << v.x() << ", " << v.y() << ", " << v.z() << "]";
  };
  text << "bounding box (m): min ";
  vector(info.bounding_box_min);
  text << " max ";
  vector(info.bounding_box_max);
  text << "\nextent (m):       ";
  vector(info.Extent());
  text << "\nkeyframes:        " << info.num_keyframes;
  if (info.num_keyframes > 0) {
    text << ", t_ns " << info.first_keyframe_t_ns << " .. " << info.last_keyframe_t_ns << ", "
         << info.num_visibility_entries << " visibility entries";
  } else {
    text << " (visibility from a voxel index of the points)";
  }
  text << "\nrelocalization:   ";
  if (info.has_relocalization) {
    text << info.num_landmarks << " landmarks, " << info.num_relocalization_features
         << " keyframe features, " << info.num_vocabulary_words << " vocabulary words";
  } else {
    text << "none (format v1 or imported; evloc-mapper upgrade adds it)";
  }
  text << "\ngeo anchor:       ";
  if (info.geo_anchor) {
    const GeoAnchor& anchor = *info.geo_anchor;
    text << std::setprecision(8) << anchor.origin.latitude_deg << ", "
         << anchor.origin.longitude_deg << std::setprecision(3) << ", " << anchor.origin.altitude_m
         << " m (WGS84), source " << anchor.source << ", sigma " << anchor.horizontal_sigma_m
         << " m horizontal, " << anchor.vertical_sigma_m << " m vertical";
  } else {
    text << "none (evloc-mapper georef adds one)";
  }
  text << "\ncameras:          " << info.num_cameras << "\n";
  for (size_t i = 0; i < info.camera_descriptions.size(); ++i) {
    text << "  [" << i << "] " << info.camera_descriptions[i] << "\n";
  }
  const MapProvenance& provenance = info.provenance;
  text << "provenance:\n";
  text << "  tool:         " << provenance.tool << " " << provenance.tool_version << "\n";
  text << "  created (UTC): " << provenance.created_utc << "\n";
  text << "  command line: " << provenance.command_line << "\n";
  for (const std::string& input : provenance.inputs) text << "  input:        " << input << "\n";
  return text.str();
}

}  // namespace evloc
