// Test helper: an in-memory map of the Middlebury templeSparseRing with relocalization data, built
// from chosen views with their calibrated poses (what the mapper's known-poses build provides):
// per keyframe, SIFT features triangulated with the neighbouring keyframes (landmarks), a VLAD
// vocabulary and global descriptors, and edge points: Canny edge pixels of each keyframe lifted
// at the median depth of the landmarks around them (where those agree).
#pragma once

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/test_data.h"
#include "core/dataset/testing/middlebury.h"
#include "core/features/features.h"
#include "core/features/testing/synthetic_images.h"
#include "core/features/vocabulary.h"
#include "maps/edge_lifting.h"
#include "maps/map.h"
#include "maps/site.h"

namespace evloc::relocalization::testing {

// The temple's views (16) with their images.
struct TempleData {
  // Calibrated views, in file order.
  std::vector<evloc::testing::MiddleburyView> views;
  // Grey images, same order.
  std::vector<cv::Mat> images;
  // The camera of every view (they share the intrinsics to within 1e-3).
  Camera camera;
};

// Reads the temple's parameters and images.
inline TempleData ReadTemple(const std::filesystem::path& parameters) {
  TempleData temple;
  temple.views = evloc::testing::ReadMiddleburyParameters(parameters);
  for (const auto& view : temple.views) {
    temple.images.push_back(features::testing::ReadGrey(parameters.parent_path() / view.name));
  }
  temple.camera = evloc::testing::MiddleburyCamera(temple.views.at(0), 640, 480);
  return temple;
}

// A world point of a match between views a and b, or false when it reprojects worse than 1 px.
inline bool TriangulateMatch(const evloc::testing::MiddleburyView& a, const Eigen::Vector2d& pa,
                             const evloc::testing::MiddleburyView& b, const Eigen::Vector2d& pb,
                             Eigen::Vector3d* point) {
  const auto projection = [](const evloc::testing::MiddleburyView& view) {
    const Eigen::Matrix<double, 3, 4> p = view.calibration * view.cam_from_world.ToMatrix3x4();
    cv::Mat matrix(3, 4, CV_64F);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) matrix.at<double>(r, c) = p(r, c);
    }
    return matrix;
  };
  cv::Mat xa = (cv::Mat_<double>(2, 1) << pa.x(), pa.y());
  cv::Mat xb = (cv::Mat_<double>(2, 1) << pb.x(), pb.y());
  cv::Mat homogeneous;
  cv::triangulatePoints(projection(a), projection(b), xa, xb, homogeneous);
  const double w = homogeneous.at<double>(3, 0);
  *point = Eigen::Vector3d(homogeneous.at<double>(0, 0), homogeneous.at<double>(1, 0),
                           homogeneous.at<double>(2, 0)) /
           w;
  for (const auto* view : {&a, &b}) {
    const Eigen::Vector3d in_cam = view->cam_from_world * *point;
    if (!point->allFinite() || in_cam.z() <= 0) return false;
    const Eigen::Vector3d h = view->calibration * in_cam;
    const Eigen::Vector2d observed = view == &a ? pa : pb;
    if ((h.head<2>() / h.z() - observed).norm() > 1.0) return false;
  }
  return true;
}

// The map of the views `keyframe_views` (indices into temple.views, ordered along the ring):
// every keyframe's features are triangulated with its two ring neighbours among the keyframes.
inline Map BuildTempleMap(const TempleData& temple, const std::vector<int>& keyframe_views) {
  Map map;
  map.cameras.push_back(temple.camera);
  RelocalizationData data;
  std::vector<features::Features> all_features;
  for (const int v : keyframe_views) {
    all_features.push_back(features::ExtractFeatures(temple.images[v], features::FeatureOptions()));
  }
  features::VocabularyOptions vocabulary_options;
  const features::Vocabulary vocabulary =
      features::Vocabulary::Train(all_features, vocabulary_options);
  data.vocabulary = vocabulary.ToVector();
  const int n = static_cast<int>(keyframe_views.size());
  for (int k = 0; k < n; ++k) {
    const auto& view = temple.views[keyframe_views[k]];
    Keyframe keyframe;
    keyframe.cam_from_world = view.cam_from_world;
    keyframe.t_ns = static_cast<int64_t>(k) * 1000000000;
    keyframe.image_name = view.name;
    KeyframeFeatures kf;
    kf.global_descriptor = vocabulary.EncodeVlad(all_features[k]);
    const features::Features& mine = all_features[k];
    std::vector<int> landmark_of(mine.size(), -1);
    for (const int neighbour : {(k + n - 1) % n, (k + 1) % n}) {
      if (neighbour == k) continue;
      const auto& other_view = temple.views[keyframe_views[neighbour]];
      for (const features::FeatureMatch& match :
           features::MatchFeatures(mine, all_features[neighbour], features::MatchOptions())) {
        if (landmark_of[match.index_a] >= 0) continue;
        Eigen::Vector3d point;
        if (!TriangulateMatch(view, mine.keypoints[match.index_a].cast<double>(), other_view,
                              all_features[neighbour].keypoints[match.index_b].cast<double>(),
                              &point)) {
          continue;
        }
        landmark_of[match.index_a] = static_cast<int>(data.landmarks.size());
        data.landmarks.push_back(point.cast<float>());
      }
    }
    // Landmark features, and their pixels and depths for the edge depths below.
    std::vector<Eigen::Vector2d> landmark_pixels;
    std::vector<double> landmark_depths;
    for (int i = 0; i < mine.size(); ++i) {
      if (landmark_of[i] < 0) continue;
      kf.keypoints.push_back(mine.keypoints[i]);
      kf.descriptors.insert(kf.descriptors.end(),
                            mine.descriptors.begin() + i * features::kDescriptorSize,
                            mine.descriptors.begin() + (i + 1) * features::kDescriptorSize);
      kf.landmarks.push_back(static_cast<uint32_t>(landmark_of[i]));
      landmark_pixels.push_back(mine.keypoints[i].cast<double>());
      landmark_depths.push_back(
          (view.cam_from_world * data.landmarks[landmark_of[i]].cast<double>()).z());
    }
    // Edge points: Canny pixels (every second row and column) with at least 3 landmarks within
    // 15 px whose depths agree to 1 %.
    const cv::Mat& image = temple.images[keyframe_views[k]];
    cv::Mat edges, gx, gy;
    cv::Canny(image, edges, 50, 150);
    cv::Sobel(image, gx, CV_32F, 1, 0);
    cv::Sobel(image, gy, CV_32F, 0, 1);
    const Rigid3d world_from_cam = view.cam_from_world.Inverse();
    for (int y = 0; y < edges.rows; y += 2) {
      for (int x = 0; x < edges.cols; x += 2) {
        if (!edges.at<uint8_t>(y, x)) continue;
        std::vector<double> near;
        for (size_t l = 0; l < landmark_pixels.size(); ++l) {
          if ((landmark_pixels[l] - Eigen::Vector2d(x, y)).squaredNorm() < 15.0 * 15.0) {
            near.push_back(landmark_depths[l]);
          }
        }
        if (near.size() < 3) continue;
        std::sort(near.begin(), near.end());
        const double depth = near[near.size() / 2];
        if (near.back() - near.front() > 0.01 * depth) continue;
        const Eigen::Vector2d gradient(gx.at<float>(y, x), gy.at<float>(y, x));
        Eigen::Vector3d ray;
        if (gradient.norm() == 0 || !temple.camera.Unproject(Eigen::Vector2d(x, y), &ray)) {
          continue;
        }
        const Eigen::Vector3d in_cam = ray / ray.z() * depth;
        Eigen::Vector3d gradient_in_cam;
        if (!ComputeGradient3d(temple.camera, Eigen::Vector2d(x, y), gradient.normalized(), in_cam,
                               &gradient_in_cam)) {
          continue;
        }
        keyframe.visible_points.push_back(static_cast<uint32_t>(map.size()));
        map.AddPoint((world_from_cam * in_cam).cast<float>(),
                     (world_from_cam.rotation * gradient_in_cam).normalized().cast<float>(), 0.0f,
                     static_cast<float>(gradient.norm() / (8.0 * 255.0)), static_cast<uint32_t>(k));
      }
    }
    map.keyframes.push_back(keyframe);
    data.keyframes.push_back(kf);
  }
  map.relocalization = std::move(data);
  map.Check();
  return map;
}

// The temple data and the map of its even views (the odd views held out as queries).
struct TempleFixture {
  // The 16 views and images.
  TempleData temple;
  // The map of views 0, 2, ..., 14.
  Map map;
};

// The path of the temple's parameter file in the shared data (relative).
inline constexpr const char* kTempleParameters = "middlebury/templeSparseRing/templeSR_par.txt";

// The temple fixture, built once per process; nullptr when the shared data is absent (skip with
// evloc::testing::MissingDataReason(kTempleParameters)).
inline const TempleFixture* SharedTemple() {
  static const TempleFixture* fixture = []() -> const TempleFixture* {
    const auto parameters = evloc::testing::SharedDataFile(kTempleParameters);
    if (!parameters) return nullptr;
    auto* result = new TempleFixture;
    result->temple = ReadTemple(*parameters);
    result->map = BuildTempleMap(result->temple, {0, 2, 4, 6, 8, 10, 12, 14});
    return result;
  }();
  return fixture;
}

// A site's grid lies in the x-y plane of a z-up frame; the Middlebury frame has the ring of
// views in its x-z plane. The same map and poses in the frame turned 90 degrees about x (y -> z).
inline const Rigid3d kZUpFromTemple(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2,
                                                                         Eigen::Vector3d::UnitX())),
                                    Eigen::Vector3d::Zero());

inline Map ZUpTempleMap(const Map& map) {
  Map turned = map;
  const Eigen::Matrix3f rotation = kZUpFromTemple.rotation.toRotationMatrix().cast<float>();
  for (Eigen::Vector3f& p : turned.positions) p = rotation * p;
  for (Eigen::Vector3f& g : turned.gradients) g = rotation * g;
  for (Keyframe& keyframe : turned.keyframes) {
    keyframe.cam_from_world = keyframe.cam_from_world * kZUpFromTemple.Inverse();
  }
  for (Eigen::Vector3f& landmark : turned.relocalization->landmarks) landmark = rotation * landmark;
  return turned;
}

// The tiling of the z-up temple in the site tests: 0.4 m squares with 0.1 m of overlap (the
// model's points over a few tiles, the cameras 0.55 m away over empty squares).
inline TilingOptions TempleTiling() {
  TilingOptions tiling;
  tiling.tile_size_m = 0.4;
  tiling.overlap_m = 0.1;
  return tiling;
}

}  // namespace evloc::relocalization::testing
