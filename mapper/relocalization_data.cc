#include "mapper/relocalization_data.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <optional>
#include <string>

#include <Eigen/SVD>
#include <opencv2/imgcodecs.hpp>

#include "core/common/error.h"
#include "mapper/parallel_for.h"

namespace evloc::mapper {
namespace {

constexpr double kDegrees = M_PI / 180.0;

// One keypoint seen in one keyframe.
struct Observation {
  // Keyframe index.
  uint32_t keyframe = 0;
  // Feature index in that keyframe.
  uint32_t feature = 0;
};

// A keyframe prepared for triangulation.
struct View {
  // Pose p_cam = cam_from_world * p_world.
  Rigid3d cam_from_world;
  // Its camera.
  const Camera* camera = nullptr;
  // Features of the image.
  features::Features features;
  // Per feature: the undistorted ray with z = 1, or nullopt when Unproject fails.
  std::vector<std::optional<Eigen::Vector3d>> rays;
};

// Union-find over (keyframe, feature) nodes; the root of a set is its smallest node.
class UnionFind {
 public:
  explicit UnionFind(size_t size) : parent_(size) {
    std::iota(parent_.begin(), parent_.end(), size_t{0});
  }
  size_t Find(size_t node) {
    while (parent_[node] != node) node = parent_[node] = parent_[parent_[node]];
    return node;
  }
  void Union(size_t a, size_t b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }

 private:
  std::vector<size_t> parent_;
};

// Linear (DLT) triangulation from normalised rays, refined by Gauss-Newton on the pixel
// reprojection errors through the cameras' models; nullopt when degenerate.
std::optional<Eigen::Vector3d> Triangulate(const std::vector<View>& views,
                                           const std::vector<Observation>& observations) {
  Eigen::MatrixXd system(2 * observations.size(), 4);
  for (size_t i = 0; i < observations.size(); ++i) {
    const View& view = views[observations[i].keyframe];
    const Eigen::Vector3d& ray = *view.rays[observations[i].feature];
    Eigen::Matrix<double, 3, 4> projection;
    projection.leftCols<3>() = view.cam_from_world.rotation.toRotationMatrix();
    projection.col(3) = view.cam_from_world.translation;
    system.row(2 * i) = ray.x() * projection.row(2) - projection.row(0);
    system.row(2 * i + 1) = ray.y() * projection.row(2) - projection.row(1);
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(system, Eigen::ComputeFullV);
  const Eigen::Vector4d homogeneous = svd.matrixV().col(3);
  if (std::abs(homogeneous.w()) < 1e-12) return std::nullopt;
  Eigen::Vector3d point = homogeneous.head<3>() / homogeneous.w();
  for (int iteration = 0; iteration < 5; ++iteration) {
    Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
    Eigen::Vector3d gradient = Eigen::Vector3d::Zero();
    for (const Observation& observation : observations) {
      const View& view = views[observation.keyframe];
      const Eigen::Vector3d in_cam = view.cam_from_world * point;
      Eigen::Vector2d pixel;
      Eigen::Matrix<double, 2, 3> d_pixel;
      if (!view.camera->Project(in_cam, &pixel, &d_pixel)) return std::nullopt;
      const Eigen::Matrix<double, 2, 3> jacobian =
          d_pixel * view.cam_from_world.rotation.toRotationMatrix();
      const Eigen::Vector2d residual =
          pixel - view.features.keypoints[observation.feature].cast<double>();
      normal += jacobian.transpose() * jacobian;
      gradient += jacobian.transpose() * residual;
    }
    const Eigen::Vector3d step = normal.ldlt().solve(-gradient);
    if (!step.allFinite()) break;
    point += step;
    if (step.norm() < 1e-12 * (1.0 + point.norm())) break;
  }
  if (!point.allFinite()) return std::nullopt;
  return point;
}

// Pixel reprojection error of `point` in each observation; infinity where it does not project.
std::vector<double> ReprojectionErrors(const std::vector<View>& views,
                                       const std::vector<Observation>& observations,
                                       const Eigen::Vector3d& point) {
  std::vector<double> errors;
  for (const Observation& observation : observations) {
    const View& view = views[observation.keyframe];
    Eigen::Vector2d pixel;
    errors.push_back(
        view.camera->Project(view.cam_from_world * point, &pixel)
            ? (pixel - view.features.keypoints[observation.feature].cast<double>()).norm()
            : std::numeric_limits<double>::infinity());
  }
  return errors;
}

// Largest angle between two viewing rays of `point`, radians.
double MaxParallax(const std::vector<View>& views, const std::vector<Observation>& observations,
                   const Eigen::Vector3d& point) {
  std::vector<Eigen::Vector3d> directions;
  for (const Observation& observation : observations) {
    const Rigid3d& pose = views[observation.keyframe].cam_from_world;
    const Eigen::Vector3d centre = -(pose.rotation.inverse() * pose.translation);
    directions.push_back((point - centre).normalized());
  }
  double largest = 0.0;
  for (size_t a = 0; a < directions.size(); ++a) {
    for (size_t b = a + 1; b < directions.size(); ++b) {
      largest =
          std::max(largest, std::acos(std::clamp(directions[a].dot(directions[b]), -1.0, 1.0)));
    }
  }
  return largest;
}

// Triangulates a track, dropping the worst view while it exceeds the reprojection limit and
// min_views remain; nullopt when no consistent landmark with enough parallax is left.
std::optional<Eigen::Vector3d> TriangulateTrack(const std::vector<View>& views,
                                                const RelocalizationDataOptions& options,
                                                std::vector<Observation>* observations) {
  while (observations->size() >= static_cast<size_t>(options.min_views)) {
    const std::optional<Eigen::Vector3d> point = Triangulate(views, *observations);
    if (!point) return std::nullopt;
    const std::vector<double> errors = ReprojectionErrors(views, *observations, *point);
    const auto worst = std::max_element(errors.begin(), errors.end());
    if (*worst <= options.max_reprojection_error_px) {
      if (MaxParallax(views, *observations, *point) < options.min_parallax_deg * kDegrees) {
        return std::nullopt;
      }
      return point;
    }
    observations->erase(observations->begin() + (worst - errors.begin()));
  }
  return std::nullopt;
}

// For each keyframe, the other keyframes nearest by camera centre whose optical axes are within
// the angle limit; returned as unordered pairs (a < b), sorted.
std::vector<std::pair<uint32_t, uint32_t>> NeighbourPairs(
    const Map& map, const RelocalizationDataOptions& options) {
  const size_t count = map.keyframes.size();
  std::vector<Eigen::Vector3d> centres;
  std::vector<Eigen::Vector3d> axes;
  for (const Keyframe& keyframe : map.keyframes) {
    const Eigen::Quaterniond world_from_cam = keyframe.cam_from_world.rotation.inverse();
    centres.push_back(-(world_from_cam * keyframe.cam_from_world.translation));
    axes.push_back(world_from_cam * Eigen::Vector3d::UnitZ());
  }
  const double min_cos = std::cos(options.max_neighbour_angle_deg * kDegrees);
  std::vector<std::pair<uint32_t, uint32_t>> pairs;
  for (uint32_t k = 0; k < count; ++k) {
    std::vector<std::pair<double, uint32_t>> candidates;
    for (uint32_t j = 0; j < count; ++j) {
      if (j == k || axes[k].dot(axes[j]) < min_cos) continue;
      const double distance = (centres[j] - centres[k]).norm();
      if (distance > 0.0) candidates.emplace_back(distance, j);
    }
    std::sort(candidates.begin(), candidates.end());
    for (size_t i = 0; i < candidates.size() && i < static_cast<size_t>(options.num_neighbours);
         ++i) {
      pairs.emplace_back(std::min(k, candidates[i].second), std::max(k, candidates[i].second));
    }
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

}  // namespace

void RelocalizationDataOptions::Check() const {
  features.Check();
  matching.Check();
  vocabulary.Check();
  if (num_neighbours < 1) throw InvalidArgumentError("num_neighbours must be at least 1");
  if (min_views < 2) throw InvalidArgumentError("min_views must be at least 2");
  if (!(max_neighbour_angle_deg > 0.0 && max_neighbour_angle_deg <= 180.0)) {
    throw InvalidArgumentError("max_neighbour_angle_deg must be in (0, 180]");
  }
  if (!(min_parallax_deg >= 0.0 && min_parallax_deg < 90.0)) {
    throw InvalidArgumentError("min_parallax_deg must be in [0, 90)");
  }
  if (!(max_reprojection_error_px > 0.0 && std::isfinite(max_reprojection_error_px))) {
    throw InvalidArgumentError("max_reprojection_error_px must be finite and > 0");
  }
  if (num_threads < 1) throw InvalidArgumentError("num_threads must be at least 1");
}

RelocalizationData ComputeRelocalizationData(
    const Map& map, const std::function<cv::Mat(size_t keyframe)>& load_image,
    const RelocalizationDataOptions& options, RelocalizationDataStatistics* statistics) {
  options.Check();
  const size_t count = map.keyframes.size();
  RelocalizationDataStatistics figures;
  // 1. Features and undistorted rays of every keyframe image.
  std::vector<View> views(count);
  ParallelFor(
      count, options.num_threads,
      [&](size_t begin, size_t end) {
        for (size_t k = begin; k < end; ++k) {
          const Keyframe& keyframe = map.keyframes[k];
          View& view = views[k];
          view.cam_from_world = keyframe.cam_from_world;
          view.camera = &map.cameras.at(keyframe.camera_index);
          const cv::Mat image = load_image(k);
          if (image.cols != view.camera->width || image.rows != view.camera->height) {
            throw InvalidArgumentError("keyframe " + std::to_string(k) + " image '" +
                                       keyframe.image_name + "' is " + std::to_string(image.cols) +
                                       "x" + std::to_string(image.rows) + " but its camera is " +
                                       std::to_string(view.camera->width) + "x" +
                                       std::to_string(view.camera->height));
          }
          view.features = features::ExtractFeatures(image, options.features);
          for (const Eigen::Vector2f& keypoint : view.features.keypoints) {
            Eigen::Vector3d ray;
            view.rays.push_back(view.camera->Unproject(keypoint.cast<double>(), &ray)
                                    ? std::optional<Eigen::Vector3d>(ray)
                                    : std::nullopt);
          }
        }
      },
      1);
  std::vector<size_t> first_node(count + 1, 0);
  for (size_t k = 0; k < count; ++k) {
    first_node[k + 1] = first_node[k] + views[k].features.keypoints.size();
  }
  figures.num_features_extracted = first_node[count];

  // 2. Matches between neighbouring keyframes, each checked by two-view triangulation.
  const std::vector<std::pair<uint32_t, uint32_t>> pairs = NeighbourPairs(map, options);
  std::vector<std::vector<features::FeatureMatch>> pair_matches(pairs.size());
  ParallelFor(
      pairs.size(), options.num_threads,
      [&](size_t begin, size_t end) {
        for (size_t p = begin; p < end; ++p) {
          const auto [a, b] = pairs[p];
          for (const features::FeatureMatch& match :
               features::MatchFeatures(views[a].features, views[b].features, options.matching)) {
            if (!views[a].rays[match.index_a] || !views[b].rays[match.index_b]) continue;
            std::vector<Observation> two = {{a, static_cast<uint32_t>(match.index_a)},
                                            {b, static_cast<uint32_t>(match.index_b)}};
            const std::optional<Eigen::Vector3d> point = Triangulate(views, two);
            if (!point) continue;
            const std::vector<double> errors = ReprojectionErrors(views, two, *point);
            if (std::max(errors[0], errors[1]) <= options.max_reprojection_error_px) {
              pair_matches[p].push_back(match);
            }
          }
        }
      },
      1);
  figures.num_matched_pairs = pairs.size();

  // 3. Tracks: union-find over the verified matches.
  UnionFind tracks(first_node[count]);
  for (size_t p = 0; p < pairs.size(); ++p) {
    figures.num_verified_matches += pair_matches[p].size();
    for (const features::FeatureMatch& match : pair_matches[p]) {
      tracks.Union(first_node[pairs[p].first] + match.index_a,
                   first_node[pairs[p].second] + match.index_b);
    }
  }
  std::vector<std::vector<Observation>> members(first_node[count]);
  for (uint32_t k = 0; k < count; ++k) {
    for (size_t f = 0; f < views[k].features.keypoints.size(); ++f) {
      members[tracks.Find(first_node[k] + f)].push_back({k, static_cast<uint32_t>(f)});
    }
  }

  // 4. Landmarks, in the order of their tracks' first node; a track that sees one keyframe twice
  // is ambiguous and dropped.
  RelocalizationData data;
  data.keyframes.resize(count);
  std::vector<uint32_t> landmark_of_node(first_node[count], kNoKeyframe);
  for (size_t root = 0; root < members.size(); ++root) {
    std::vector<Observation>& observations = members[root];
    if (observations.size() < static_cast<size_t>(options.min_views)) continue;
    bool repeated = false;
    for (size_t i = 1; i < observations.size(); ++i) {
      for (size_t j = 0; j < i; ++j) {
        repeated = repeated || observations[i].keyframe == observations[j].keyframe;
      }
    }
    if (repeated) continue;
    const std::optional<Eigen::Vector3d> point = TriangulateTrack(views, options, &observations);
    if (!point) continue;
    const uint32_t landmark = static_cast<uint32_t>(data.landmarks.size());
    data.landmarks.push_back(point->cast<float>());
    for (const Observation& observation : observations) {
      landmark_of_node[first_node[observation.keyframe] + observation.feature] = landmark;
    }
  }

  // 5. Per keyframe, the features that see a landmark, in extraction order.
  cv::Mat kept_descriptors;
  for (size_t k = 0; k < count; ++k) {
    const features::Features& extracted = views[k].features;
    KeyframeFeatures& kept = data.keyframes[k];
    for (size_t f = 0; f < extracted.keypoints.size(); ++f) {
      const uint32_t landmark = landmark_of_node[first_node[k] + f];
      if (landmark == kNoKeyframe) continue;
      kept.keypoints.push_back(extracted.keypoints[f]);
      kept.landmarks.push_back(landmark);
      const uint8_t* row = extracted.descriptors.data() + f * features::kDescriptorSize;
      kept.descriptors.insert(kept.descriptors.end(), row, row + features::kDescriptorSize);
      cv::Mat descriptor(1, features::kDescriptorSize, CV_32F);
      for (int i = 0; i < features::kDescriptorSize; ++i) descriptor.at<float>(0, i) = row[i];
      kept_descriptors.push_back(descriptor);
    }
    figures.num_features_kept += kept.keypoints.size();
  }
  figures.num_landmarks = data.landmarks.size();
  if (kept_descriptors.rows < options.vocabulary.num_words) {
    throw InvalidArgumentError(
        "only " + std::to_string(kept_descriptors.rows) + " keyframe features see a landmark (" +
        std::to_string(data.landmarks.size()) + " landmarks from " + std::to_string(count) +
        " keyframes); the vocabulary needs at least " +
        std::to_string(options.vocabulary.num_words) + ": the images may lack texture or baseline");
  }

  // 6. The vocabulary, trained on the kept features, and every keyframe's VLAD over all of its
  // features (a query image is encoded from all of its features too).
  const features::Vocabulary vocabulary =
      features::Vocabulary::Train(kept_descriptors, options.vocabulary);
  data.vocabulary = vocabulary.ToVector();
  for (size_t k = 0; k < count; ++k) {
    data.keyframes[k].global_descriptor = vocabulary.EncodeVlad(views[k].features);
  }
  figures.bytes_added = EncodedRelocalizationBytes(data);
  if (statistics != nullptr) *statistics = figures;
  return data;
}

RelocalizationData ComputeRelocalizationData(const Map& map, const std::filesystem::path& image_dir,
                                             const RelocalizationDataOptions& options,
                                             RelocalizationDataStatistics* statistics) {
  for (size_t k = 0; k < map.keyframes.size(); ++k) {
    const std::filesystem::path path = image_dir / map.keyframes[k].image_name;
    std::error_code error;
    if (map.keyframes[k].image_name.empty() || !std::filesystem::is_regular_file(path, error)) {
      throw IoError("keyframe " + std::to_string(k) + " image '" + map.keyframes[k].image_name +
                    "' is not in " + image_dir.string() +
                    " (--images must be the folder the map was built from)");
    }
  }
  return ComputeRelocalizationData(
      map,
      [&](size_t keyframe) {
        const std::filesystem::path path = image_dir / map.keyframes[keyframe].image_name;
        const cv::Mat image = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
        if (image.empty()) throw IoError("cannot read keyframe image " + path.string());
        return image;
      },
      options, statistics);
}

}  // namespace evloc::mapper
