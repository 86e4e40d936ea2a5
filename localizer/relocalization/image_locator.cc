#include "localizer/relocalization/image_locator.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "core/common/error.h"
#include "core/features/vocabulary.h"

namespace evloc::relocalization {
namespace {

// Throws InvalidArgumentError unless the relocalization data fits the map and the descriptors.
void CheckRelocalizationData(const Map& map, const RelocalizationData& data) {
  const auto fail = [](const std::string& what) {
    throw InvalidArgumentError("locate: the map's relocalization data is inconsistent: " + what);
  };
  if (data.keyframes.size() != map.keyframes.size()) {
    fail(std::to_string(data.keyframes.size()) + " keyframe feature sets for " +
         std::to_string(map.keyframes.size()) + " keyframes");
  }
  if (data.vocabulary.empty() || data.vocabulary.size() % kRelocalizationDescriptorBytes != 0) {
    fail("a vocabulary of " + std::to_string(data.vocabulary.size()) +
         " floats is not a positive number of 128-float words");
  }
  for (size_t k = 0; k < data.keyframes.size(); ++k) {
    const KeyframeFeatures& keyframe = data.keyframes[k];
    const std::string name = "keyframe " + std::to_string(k) + ": ";
    if (keyframe.descriptors.size() != keyframe.keypoints.size() * kRelocalizationDescriptorBytes ||
        keyframe.landmarks.size() != keyframe.keypoints.size()) {
      fail(name + "keypoints, descriptors and landmarks differ in number");
    }
    if (keyframe.global_descriptor.size() != data.vocabulary.size()) {
      fail(name + "the global descriptor's length differs from the vocabulary's");
    }
    for (const uint32_t landmark : keyframe.landmarks) {
      if (landmark >= data.landmarks.size()) fail(name + "a landmark index is out of range");
    }
  }
}

// Median of the depths of `points` in the camera at `world_from_cam` (1 when there are none).
double MedianDepth(const Rigid3d& world_from_cam, const std::vector<Eigen::Vector3d>& points,
                   const std::vector<int>& indices) {
  const Rigid3d cam_from_world = world_from_cam.Inverse();
  std::vector<double> depths;
  for (const int i : indices) depths.push_back((cam_from_world * points[i]).z());
  if (depths.empty()) return 1.0;
  std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
  return depths[depths.size() / 2];
}

}  // namespace

AbsolutePoseOptions LocateOptions::DefaultPoseOptions() {
  AbsolutePoseOptions options;
  options.min_inliers = 20;
  options.min_inlier_ratio = 0.2;
  return options;
}

tracking::TrackerOptions LocateOptions::DefaultVerificationOptions() {
  tracking::TrackerOptions options;
  options.input = tracking::TrackerInput::kFrames;
  // One step from the PnP pose: a failed step must not be rescued by the recovery search.
  options.enable_recovery = false;
  return options;
}

void LocateOptions::Check() const {
  features.Check();
  matching.Check();
  pose.Check();
  verification.Check();
  if (top_k < 1) throw InvalidArgumentError("LocateOptions: top_k must be at least 1");
  if (max_site_tiles < 1) {
    throw InvalidArgumentError("LocateOptions: max_site_tiles must be at least 1");
  }
  if (search_center) {
    tracking::CheckSearchRegion(*search_center, search_radius_m,
                                "LocateOptions: the search region");
  }
  if (verification.input != tracking::TrackerInput::kFrames) {
    throw InvalidArgumentError("LocateOptions: the verification tracker must take frames");
  }
  if (!(max_verification_shift > 0) || !std::isfinite(max_verification_shift)) {
    throw InvalidArgumentError("LocateOptions: max_verification_shift must be positive");
  }
  if (!(max_verification_rotation_deg > 0) || !std::isfinite(max_verification_rotation_deg)) {
    throw InvalidArgumentError("LocateOptions: max_verification_rotation_deg must be positive");
  }
}

const char* LocateStatusName(LocateStatus status) {
  return status == LocateStatus::kFound ? "FOUND" : "NOT_FOUND";
}

LocateResult LocateImage(const Map& map, const Camera& query_camera, const cv::Mat& gray,
                         const LocateOptions& options) {
  if (!map.relocalization) throw InvalidArgumentError(kNoRelocalizationDataMessage);
  const VisibilityIndex visibility(map);
  return LocateImage(map, visibility, query_camera, gray, options);
}

namespace {

// Throws InvalidArgumentError unless `gray` is an 8-bit grey image of the camera's size.
void CheckQueryImage(const Camera& query_camera, const cv::Mat& gray) {
  if (gray.type() != CV_8UC1 || gray.cols != query_camera.width ||
      gray.rows != query_camera.height) {
    std::ostringstream message;
    message << "locate: the image must be 8-bit grey of the camera's size " << query_camera.width
            << "x" << query_camera.height << ", not " << gray.cols << "x" << gray.rows << " with "
            << gray.channels() << " channel(s) of type " << gray.depth();
    throw InvalidArgumentError(message.str());
  }
}

// The vocabulary of relocalization data (CheckRelocalizationData checked its size).
features::Vocabulary VocabularyOf(const RelocalizationData& data) {
  const int dimension = static_cast<int>(kRelocalizationDescriptorBytes);
  return features::Vocabulary::FromVector(static_cast<int>(data.vocabulary.size()) / dimension,
                                          dimension, data.vocabulary);
}

// A keyframe retrieval may return: its global descriptor, and its landmark features from every
// copy searched (a whole map holds one; each tile of a site keeps the features of the keyframe
// that see the tile's landmarks).
struct SearchedKeyframe {
  const std::vector<float>* global_descriptor = nullptr;
  // Per copy: the features and the landmark positions their indices refer to.
  std::vector<std::pair<const KeyframeFeatures*, const std::vector<Eigen::Vector3f>*>> copies;
  // What LocateResult reports of it: its index among its map's (or owning tile's) keyframes, and
  // the tile's position in the site manifest (-1 for a whole map).
  int keyframe = 0;
  int tile = -1;
};

// One frame-tracker step from a PnP pose against the map's edges; `depth_m` is the median depth
// of the PnP inliers (how far the camera sees what it matched).
using VerificationStep = std::function<std::optional<tracking::PoseEstimate>(
    const Rigid3d& world_from_cam, double depth_m)>;

// The keyframe's features pooled over its copies, each (keypoint, landmark) once in the order
// met, and the position of the landmark each one sees.
void PoolCopies(const SearchedKeyframe& keyframe, features::Features* pooled,
                std::vector<Eigen::Vector3f>* landmarks) {
  std::set<std::array<float, 5>> seen;
  for (const auto& [features, positions] : keyframe.copies) {
    for (size_t f = 0; f < features->keypoints.size(); ++f) {
      const Eigen::Vector2f& keypoint = features->keypoints[f];
      const Eigen::Vector3f& landmark = (*positions)[features->landmarks[f]];
      if (keyframe.copies.size() > 1 &&
          !seen.insert({keypoint.x(), keypoint.y(), landmark.x(), landmark.y(), landmark.z()})
               .second) {
        continue;
      }
      pooled->keypoints.push_back(keypoint);
      pooled->descriptors.insert(
          pooled->descriptors.end(),
          features->descriptors.begin() +
              static_cast<std::ptrdiff_t>(f * kRelocalizationDescriptorBytes),
          features->descriptors.begin() +
              static_cast<std::ptrdiff_t>((f + 1) * kRelocalizationDescriptorBytes));
      landmarks->push_back(landmark);
    }
  }
}

// Retrieval among `keyframes` (not empty), matching, absolute pose and verification by `verify`.
LocateResult LocateAmong(const std::vector<SearchedKeyframe>& keyframes,
                         const features::Vocabulary& vocabulary, const Camera& query_camera,
                         const cv::Mat& gray, const LocateOptions& options,
                         const VerificationStep& verify) {
  LocateResult result;
  // Retrieval.
  const features::Features query = features::ExtractFeatures(gray, options.features);
  std::vector<std::vector<float>> database;
  database.reserve(keyframes.size());
  for (const SearchedKeyframe& keyframe : keyframes) {
    database.push_back(*keyframe.global_descriptor);
  }
  const std::vector<features::RetrievalHit> hits =
      features::Retrieve(vocabulary.EncodeVlad(query), database, options.top_k);
  const auto report = [&](int searched) {
    result.keyframe = keyframes[static_cast<size_t>(searched)].keyframe;
    result.tile = keyframes[static_cast<size_t>(searched)].tile;
  };
  report(hits.front().index);
  result.retrieval_similarity = hits.front().similarity;

  // Matching: one landmark per query keypoint, from the match with the smallest distance.
  struct Correspondence {
    Eigen::Vector3f landmark;
    float distance = 0;
    int keyframe = 0;  // Position in `keyframes`.
  };
  std::unordered_map<int, Correspondence> by_keypoint;
  for (const features::RetrievalHit& hit : hits) {
    features::Features pooled;
    std::vector<Eigen::Vector3f> landmarks;
    PoolCopies(keyframes[static_cast<size_t>(hit.index)], &pooled, &landmarks);
    for (const features::FeatureMatch& match :
         features::MatchFeatures(query, pooled, options.matching)) {
      const Correspondence candidate{landmarks[static_cast<size_t>(match.index_b)], match.distance,
                                     hit.index};
      const auto [it, inserted] = by_keypoint.emplace(match.index_a, candidate);
      if (!inserted && candidate.distance < it->second.distance) it->second = candidate;
    }
  }
  std::vector<int> keypoints;
  for (const auto& [keypoint, correspondence] : by_keypoint) keypoints.push_back(keypoint);
  std::sort(keypoints.begin(), keypoints.end());
  std::vector<Eigen::Vector2d> pixels;
  std::vector<Eigen::Vector3d> points;
  std::vector<int> source_keyframe;
  for (const int keypoint : keypoints) {
    const Correspondence& correspondence = by_keypoint.at(keypoint);
    pixels.push_back(query.keypoints[keypoint].cast<double>());
    points.push_back(correspondence.landmark.cast<double>());
    source_keyframe.push_back(correspondence.keyframe);
  }
  result.correspondences = static_cast<int>(pixels.size());

  // Absolute pose.
  const AbsolutePoseResult pose = EstimateAbsolutePose(query_camera, pixels, points, options.pose);
  if (!pose.success) {
    result.inliers = static_cast<int>(pose.inliers.size());
    result.reason = "no pose from " + std::to_string(result.correspondences) +
                    " 2D-3D correspondences with " + std::to_string(hits.size()) +
                    " retrieved keyframes: " + pose.reason;
    return result;
  }
  result.inliers = static_cast<int>(pose.inliers.size());
  result.pnp_world_from_cam = pose.world_from_cam;
  std::unordered_map<int, int> inliers_per_keyframe;
  for (const int inlier : pose.inliers) ++inliers_per_keyframe[source_keyframe[inlier]];
  int most = 0;
  for (const features::RetrievalHit& hit : hits) {
    if (inliers_per_keyframe[hit.index] > most) {
      most = inliers_per_keyframe[hit.index];
      report(hit.index);
    }
  }
  std::ostringstream account;
  account << pose.inliers.size() << " inliers of " << result.correspondences
          << " correspondences (RMS " << pose.rms_reprojection_error_px << " px)";
  if (!options.verify) {
    result.status = LocateStatus::kFound;
    result.world_from_cam = pose.world_from_cam;
    result.covariance = pose.covariance;
    result.reason = account.str() + ", not verified";
    return result;
  }

  // Verification: one Canny-VT step from the PnP pose against the map's edges.
  const double depth = MedianDepth(pose.world_from_cam, points, pose.inliers);
  const std::optional<tracking::PoseEstimate> step = verify(pose.world_from_cam, depth);
  if (!step) throw InvalidArgumentError("locate: the verification tracker ran no step");
  const tracking::TrackingQuality& quality = step->quality;
  result.score = quality.alignment;
  const double shift = (step->world_from_cam.translation - pose.world_from_cam.translation).norm();
  const double rotation_deg =
      AngleBetween(step->world_from_cam.rotation, pose.world_from_cam.rotation) * 180.0 / M_PI;
  account << "; edges: alignment " << quality.alignment << ", on-edge " << quality.on_edge_fraction
          << " of " << quality.points_used << " points, shift " << shift / depth * 100.0
          << " % of the depth, " << rotation_deg << " deg";
  result.reason = account.str();
  if (step->status != tracking::TrackingStatus::kTracking) {
    result.reason = "the map's edges do not confirm the pose: " + result.reason;
    return result;
  }
  if (shift > options.max_verification_shift * depth ||
      rotation_deg > options.max_verification_rotation_deg) {
    result.reason = "the edge registration moved away from the pose: " + result.reason;
    return result;
  }
  result.status = LocateStatus::kFound;
  result.world_from_cam = pose.world_from_cam;
  result.covariance = pose.covariance;
  return result;
}

// True when the camera centre `centre` lies outside the options' search region.
bool OutsideSearch(const LocateOptions& options, const Eigen::Vector3d& centre) {
  return options.search_center &&
         (centre - *options.search_center).norm() > options.search_radius_m;
}

std::string NothingWithinSearchMessage(const LocateOptions& options, const std::string& what) {
  return "no keyframe of the " + what + " lies within " + std::to_string(options.search_radius_m) +
         " m of the search prior";
}

}  // namespace

LocateResult LocateImage(const Map& map, const VisibilityIndex& visibility,
                         const Camera& query_camera, const cv::Mat& gray,
                         const LocateOptions& options) {
  options.Check();
  query_camera.Check();
  if (!map.relocalization) throw InvalidArgumentError(kNoRelocalizationDataMessage);
  const RelocalizationData& data = *map.relocalization;
  CheckRelocalizationData(map, data);
  CheckQueryImage(query_camera, gray);

  LocateResult result;
  if (map.keyframes.empty()) {
    result.reason = "the map has no keyframes";
    return result;
  }
  // The keyframes retrieval may return: all, or those within the search prior's radius.
  std::vector<SearchedKeyframe> searched;
  for (size_t k = 0; k < data.keyframes.size(); ++k) {
    if (OutsideSearch(options, map.keyframes[k].cam_from_world.Inverse().translation)) continue;
    searched.push_back({&data.keyframes[k].global_descriptor,
                        {{&data.keyframes[k], &data.landmarks}},
                        static_cast<int>(k)});
  }
  if (searched.empty()) {
    result.reason = NothingWithinSearchMessage(options, "map");
    return result;
  }
  return LocateAmong(searched, VocabularyOf(data), query_camera, gray, options,
                     [&](const Rigid3d& world_from_cam, double /*depth_m*/) {
                       tracking::Tracker tracker(map, &visibility, query_camera,
                                                 options.verification);
                       tracker.Reset(world_from_cam, 0);
                       return tracker.AddFrame(1, gray);
                     });
}

LocateResult LocateImageInSite(const std::shared_ptr<const Site>& site,
                               const std::shared_ptr<TileCache>& cache, const Camera& query_camera,
                               const cv::Mat& gray, const LocateOptions& options,
                               const tracking::TileSelectionOptions& verification_tiles) {
  options.Check();
  verification_tiles.Check();
  query_camera.Check();
  CheckQueryImage(query_camera, gray);
  const SiteManifest& manifest = site->manifest;
  const std::string where = "locate in site '" + manifest.name + "': ";

  // The tiles searched: those keeping keyframes, within the search region when there is one, and
  // their neighbours, which hold what those keyframes see beyond the overlap.
  std::vector<TileIndex> seeds;
  for (const SiteTile& tile : manifest.tiles) {
    if (tile.num_keyframes == 0) continue;
    if (options.search_center &&
        tile.core.DistanceTo(options.search_center->x(), options.search_center->y()) >
            options.search_radius_m) {
      continue;
    }
    seeds.push_back(tile.index);
  }
  LocateResult result;
  if (seeds.empty()) {
    result.reason = options.search_center ? NothingWithinSearchMessage(options, "site")
                                          : "the site has no keyframes";
    return result;
  }
  std::vector<size_t> chosen;
  for (size_t t = 0; t < manifest.tiles.size(); ++t) {
    const TileIndex index = manifest.tiles[t].index;
    if (std::any_of(seeds.begin(), seeds.end(), [&](const TileIndex& seed) {
          return std::abs(int64_t{seed.ix} - index.ix) <= 1 &&
                 std::abs(int64_t{seed.iy} - index.iy) <= 1;
        })) {
      chosen.push_back(t);
    }
  }
  if (chosen.size() > options.max_site_tiles) {
    throw InvalidArgumentError(
        where + "the " + std::to_string(seeds.size()) + " tiles keeping keyframes" +
        (options.search_center ? " within the search radius" : "") + " and their neighbours are " +
        std::to_string(chosen.size()) + " tiles, more than the " +
        std::to_string(options.max_site_tiles) +
        " one locate may load (LocateOptions::max_site_tiles): give a search prior (a GNSS fix) "
        "that narrows it");
  }
  // Load returns a resident tile as it is (the cache's hit and miss counters stay the sessions').
  std::vector<std::shared_ptr<const LoadedTile>> tiles;
  for (const size_t t : chosen) tiles.push_back(cache->Load(site, t));

  // Every keyframe within the search region once, whichever tiles keep it (a tile keeps the
  // keyframes that see its points, with the features that see its landmarks): its copies are
  // pooled, and it is reported in the tile owning its camera centre when that one is loaded.
  std::vector<SearchedKeyframe> searched;
  std::map<std::tuple<int64_t, std::string, double, double, double>, size_t> by_identity;
  const RelocalizationData* first = nullptr;
  for (const std::shared_ptr<const LoadedTile>& loaded : tiles) {
    const Map& map = loaded->map;
    const std::string tile_name = "tile " + loaded->entry.file_name + ": ";
    if (!map.relocalization) {
      throw InvalidArgumentError(where + tile_name + kNoRelocalizationDataMessage);
    }
    const RelocalizationData& data = *map.relocalization;
    CheckRelocalizationData(map, data);
    if (first == nullptr) first = &data;
    if (data.vocabulary != first->vocabulary) {
      throw InvalidArgumentError(where + tile_name +
                                 "its vocabulary differs from the other tiles' (a site's tiles "
                                 "share one: tile the map again with evloc-mapper tile)");
    }
    for (size_t k = 0; k < map.keyframes.size(); ++k) {
      const Keyframe& keyframe = map.keyframes[k];
      const Eigen::Vector3d centre = keyframe.cam_from_world.Inverse().translation;
      if (OutsideSearch(options, centre)) continue;
      const SearchedKeyframe copy{&data.keyframes[k].global_descriptor,
                                  {{&data.keyframes[k], &data.landmarks}},
                                  static_cast<int>(k),
                                  static_cast<int>(loaded->tile)};
      const auto [found, inserted] = by_identity.emplace(
          std::make_tuple(keyframe.t_ns, keyframe.image_name, centre.x(), centre.y(), centre.z()),
          searched.size());
      if (inserted) {
        searched.push_back(copy);
        continue;
      }
      SearchedKeyframe& kept = searched[found->second];
      kept.copies.push_back(copy.copies.front());
      if (manifest.grid.IndexOf(centre.x(), centre.y()) == loaded->entry.index) {
        kept.keyframe = copy.keyframe;
        kept.tile = copy.tile;
      }
    }
  }
  if (searched.empty()) {
    result.reason = NothingWithinSearchMessage(options, "site");
    return result;
  }
  result = LocateAmong(searched, VocabularyOf(*first), query_camera, gray, options,
                       [&](const Rigid3d& world_from_cam, double depth_m) {
                         // Against the tiles a session at the pose would track against, and
                         // those around what the camera matched, at the inliers' depth on its
                         // axis.
                         tracking::TileSelectionOptions selection = verification_tiles;
                         selection.synchronous = true;
                         selection.view_distance_m = std::max(selection.view_distance_m, depth_m);
                         tracking::TiledMapSource source(site, cache, selection);
                         source.LoadNow(world_from_cam);
                         tracking::Tracker tracker(source, query_camera, options.verification);
                         tracker.Reset(world_from_cam, 0);
                         return tracker.AddFrame(1, gray);
                       });
  result.reason += " (" + std::to_string(tiles.size()) + " tiles searched)";
  return result;
}

}  // namespace evloc::relocalization
