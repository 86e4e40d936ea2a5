#include "localizer/relocalization/image_locator.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <unordered_map>
#include <vector>

#include "core/common/error.h"
#include "core/features/vocabulary.h"

namespace evloc::relocalization {
namespace {

// The keyframe's landmark features as a features::Features (keypoints and descriptors only).
features::Features KeyframeAsFeatures(const KeyframeFeatures& keyframe) {
  features::Features result;
  result.keypoints = keyframe.keypoints;
  result.descriptors = keyframe.descriptors;
  return result;
}

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
  if (search_center && (!search_center->allFinite() || !(search_radius_m > 0.0) ||
                        !std::isfinite(search_radius_m))) {
    throw InvalidArgumentError(
        "LocateOptions: a search centre must be finite and its radius finite and positive");
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

LocateResult LocateImage(const Map& map, const VisibilityIndex& visibility,
                         const Camera& query_camera, const cv::Mat& gray,
                         const LocateOptions& options) {
  options.Check();
  query_camera.Check();
  if (!map.relocalization) throw InvalidArgumentError(kNoRelocalizationDataMessage);
  const RelocalizationData& data = *map.relocalization;
  CheckRelocalizationData(map, data);
  if (gray.type() != CV_8UC1 || gray.cols != query_camera.width ||
      gray.rows != query_camera.height) {
    std::ostringstream message;
    message << "locate: the image must be 8-bit grey of the camera's size " << query_camera.width
            << "x" << query_camera.height << ", not " << gray.cols << "x" << gray.rows << " with "
            << gray.channels() << " channel(s) of type " << gray.depth();
    throw InvalidArgumentError(message.str());
  }

  LocateResult result;
  if (map.keyframes.empty()) {
    result.reason = "the map has no keyframes";
    return result;
  }
  // Retrieval.
  const features::Features query = features::ExtractFeatures(gray, options.features);
  const int dimension = static_cast<int>(kRelocalizationDescriptorBytes);
  const features::Vocabulary vocabulary = features::Vocabulary::FromVector(
      static_cast<int>(data.vocabulary.size()) / dimension, dimension, data.vocabulary);
  // The keyframes retrieval may return: all, or those within the search prior's radius.
  std::vector<std::vector<float>> database;
  std::vector<int> database_keyframes;
  database.reserve(data.keyframes.size());
  for (size_t k = 0; k < data.keyframes.size(); ++k) {
    if (options.search_center &&
        (map.keyframes[k].cam_from_world.Inverse().translation - *options.search_center).norm() >
            options.search_radius_m) {
      continue;
    }
    database.push_back(data.keyframes[k].global_descriptor);
    database_keyframes.push_back(static_cast<int>(k));
  }
  if (database.empty()) {
    result.reason = "no keyframe of the map lies within " +
                    std::to_string(options.search_radius_m) + " m of the search prior";
    result.keyframe = -1;
    return result;
  }
  std::vector<features::RetrievalHit> hits =
      features::Retrieve(vocabulary.EncodeVlad(query), database, options.top_k);
  for (features::RetrievalHit& hit : hits) hit.index = database_keyframes[hit.index];
  result.keyframe = hits.front().index;
  result.retrieval_similarity = hits.front().similarity;

  // Matching: one landmark per query keypoint, from the match with the smallest distance.
  struct Correspondence {
    uint32_t landmark = 0;
    float distance = 0;
    int keyframe = 0;
  };
  std::unordered_map<int, Correspondence> by_keypoint;
  for (const features::RetrievalHit& hit : hits) {
    const KeyframeFeatures& keyframe = data.keyframes[hit.index];
    for (const features::FeatureMatch& match :
         features::MatchFeatures(query, KeyframeAsFeatures(keyframe), options.matching)) {
      const Correspondence candidate{keyframe.landmarks[match.index_b], match.distance, hit.index};
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
    points.push_back(data.landmarks[correspondence.landmark].cast<double>());
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
      result.keyframe = hit.index;
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
  tracking::Tracker tracker(map, &visibility, query_camera, options.verification);
  tracker.Reset(pose.world_from_cam, 0);
  const std::optional<tracking::PoseEstimate> step = tracker.AddFrame(1, gray);
  if (!step) throw InvalidArgumentError("locate: the verification tracker ran no step");
  const tracking::TrackingQuality& quality = step->quality;
  result.score = quality.alignment;
  const double depth = MedianDepth(pose.world_from_cam, points, pose.inliers);
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

}  // namespace evloc::relocalization
