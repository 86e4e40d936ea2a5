#include "mapper/feature_matching.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "mapper/colmap_model.h"
#include "mapper/parallel_for.h"

namespace evloc::mapper {
namespace {

// COLMAP stores unit descriptors scaled by 512: the dot product of two is at most 512^2.
constexpr double kDescriptorNormSquared = 512.0 * 512.0;
// Rows of the first image's descriptors per block of dot products (bounds the block's memory).
constexpr size_t kMatchBlockRows = 512;

using DescriptorMatrix = Eigen::Matrix<float, Eigen::Dynamic, kSiftDescriptorSize, Eigen::RowMajor>;

DescriptorMatrix ToFloatMatrix(const std::vector<uint8_t>& descriptors) {
  const size_t rows = descriptors.size() / kSiftDescriptorSize;
  DescriptorMatrix matrix(static_cast<Eigen::Index>(rows), kSiftDescriptorSize);
  for (size_t i = 0; i < descriptors.size(); ++i) {
    matrix.data()[i] = static_cast<float>(descriptors[i]);
  }
  return matrix;
}

// Best and second-best dot product of one descriptor against the other image's.
struct BestTwo {
  float best = -1.0f;
  float second = -1.0f;
  int index = -1;

  // Ties keep the earlier candidate (candidates arrive in increasing index order).
  void Update(float dot, int candidate) {
    if (dot > best) {
      second = best;
      best = dot;
      index = candidate;
    } else if (dot > second) {
      second = dot;
    }
  }
};

// The angle between two descriptors of dot product `dot` (COLMAP's normalised distance).
double DescriptorAngle(float dot) {
  return std::acos(std::min(std::max(static_cast<double>(dot), 0.0) / kDescriptorNormSquared, 1.0));
}

// COLMAP's one-way acceptance: best angle within max_distance and below max_ratio times the
// second best.
bool PassesRatioTest(const BestTwo& candidate, const FeatureMatchingOptions& options) {
  if (candidate.index < 0) return false;
  const double best = DescriptorAngle(candidate.best);
  if (best > options.max_distance) return false;
  return best < options.max_ratio * DescriptorAngle(candidate.second);
}

// The inlier subset of `matches` selected by a RANSAC mask (indices into `kept`).
FeatureMatches InliersOf(const FeatureMatches& matches, const std::vector<size_t>& kept,
                         const cv::Mat& mask) {
  FeatureMatches inliers;
  for (size_t i = 0; i < kept.size(); ++i) {
    if (mask.at<uint8_t>(static_cast<int>(i)) != 0) inliers.push_back(matches[kept[i]]);
  }
  return inliers;
}

Eigen::Matrix3d ToEigen(const cv::Mat& matrix) {
  Eigen::Matrix3d result;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) result(r, c) = matrix.at<double>(r, c);
  }
  return result;
}

}  // namespace

void FeatureMatchingOptions::Check() const {
  if (!(max_ratio > 0.0 && max_ratio <= 1.0)) {
    throw InvalidArgumentError("matching max_ratio must be in (0, 1]");
  }
  if (!(max_distance > 0.0 && max_distance <= std::numbers::pi / 2)) {
    throw InvalidArgumentError("matching max_distance must be in (0, pi/2] radians");
  }
  if (!(max_error_px > 0.0 && max_error_px <= 100.0)) {
    throw InvalidArgumentError("matching max_error_px must be in (0, 100] pixels");
  }
  if (!(confidence > 0.0 && confidence < 1.0)) {
    throw InvalidArgumentError("matching confidence must be in (0, 1)");
  }
  if (max_num_trials < 1) throw InvalidArgumentError("matching max_num_trials must be >= 1");
  if (min_num_inliers < 8) throw InvalidArgumentError("matching min_num_inliers must be >= 8");
  if (num_threads < 1) throw InvalidArgumentError("matching num_threads must be >= 1");
}

std::vector<std::pair<size_t, size_t>> ExhaustivePairs(size_t num_images) {
  std::vector<std::pair<size_t, size_t>> pairs;
  for (size_t i = 0; i < num_images; ++i) {
    for (size_t j = i + 1; j < num_images; ++j) pairs.emplace_back(i, j);
  }
  return pairs;
}

std::vector<std::pair<size_t, size_t>> SequentialPairs(size_t num_images, int overlap) {
  std::set<std::pair<size_t, size_t>> pairs;
  for (size_t i = 0; i < num_images; ++i) {
    for (int k = 0; k < overlap; ++k) {
      const size_t linear = i + static_cast<size_t>(k);
      if (linear >= num_images) break;
      if (linear != i) pairs.emplace(i, linear);
      if (k < 63) {
        const size_t quadratic = i + (size_t{1} << k);
        if (quadratic < num_images) pairs.emplace(i, quadratic);
      }
    }
  }
  return {pairs.begin(), pairs.end()};
}

FeatureMatches MatchDescriptors(const std::vector<uint8_t>& descriptors1,
                                const std::vector<uint8_t>& descriptors2,
                                const FeatureMatchingOptions& options) {
  const DescriptorMatrix first = ToFloatMatrix(descriptors1);
  const DescriptorMatrix second = ToFloatMatrix(descriptors2);
  const Eigen::Index rows1 = first.rows();
  const Eigen::Index rows2 = second.rows();
  if (rows1 == 0 || rows2 == 0) return {};
  std::vector<BestTwo> forward(static_cast<size_t>(rows1));
  std::vector<BestTwo> backward(static_cast<size_t>(rows2));
  // Products of bytes summed in float are exact (every partial sum is an integer below 2^24), so
  // the dot products do not depend on the order of the sums.
  for (Eigen::Index begin = 0; begin < rows1; begin += kMatchBlockRows) {
    const Eigen::Index count = std::min<Eigen::Index>(kMatchBlockRows, rows1 - begin);
    const Eigen::MatrixXf dots = first.middleRows(begin, count) * second.transpose();
    for (Eigen::Index j = 0; j < rows2; ++j) {
      BestTwo& column = backward[static_cast<size_t>(j)];
      for (Eigen::Index r = 0; r < count; ++r) {
        const float dot = dots(r, j);
        forward[static_cast<size_t>(begin + r)].Update(dot, static_cast<int>(j));
        column.Update(dot, static_cast<int>(begin + r));
      }
    }
  }
  FeatureMatches matches;
  for (size_t i = 0; i < forward.size(); ++i) {
    if (!PassesRatioTest(forward[i], options)) continue;
    const auto j = static_cast<size_t>(forward[i].index);
    if (options.cross_check &&
        (backward[j].index != static_cast<int>(i) || !PassesRatioTest(backward[j], options))) {
      continue;
    }
    matches.emplace_back(static_cast<uint32_t>(i), static_cast<uint32_t>(j));
  }
  return matches;
}

void VerifyPair(const ImageFeatures& image1, const ImageFeatures& image2,
                const std::optional<Camera>& camera, const FeatureMatchingOptions& options,
                PairGeometry* pair) {
  pair->inlier_matches.clear();
  pair->config = TwoViewConfig::kUndefined;
  pair->F.setZero();
  pair->E.setZero();
  pair->H.setZero();
  const FeatureMatches& matches = pair->matches;
  if (matches.size() < static_cast<size_t>(options.min_num_inliers)) return;
  std::vector<cv::Point2d> points1;
  std::vector<cv::Point2d> points2;
  std::vector<size_t> kept;
  for (size_t i = 0; i < matches.size(); ++i) {
    if (matches[i].first >= image1.keypoints.size() ||
        matches[i].second >= image2.keypoints.size()) {
      throw InvalidArgumentError("match " + std::to_string(i) + " of images " + image1.name +
                                 " and " + image2.name + " indexes a missing keypoint");
    }
    const Eigen::Vector2d pixel1 =
        image1.keypoints[matches[i].first].cast<double>().array() - kColmapPixelOffset;
    const Eigen::Vector2d pixel2 =
        image2.keypoints[matches[i].second].cast<double>().array() - kColmapPixelOffset;
    if (camera) {
      Eigen::Vector3d ray1;
      Eigen::Vector3d ray2;
      if (!camera->Unproject(pixel1, &ray1) || !camera->Unproject(pixel2, &ray2)) continue;
      points1.emplace_back(ray1.x(), ray1.y());
      points2.emplace_back(ray2.x(), ray2.y());
    } else {
      points1.emplace_back(pixel1.x(), pixel1.y());
      points2.emplace_back(pixel2.x(), pixel2.y());
    }
    kept.push_back(i);
  }
  pair->config = TwoViewConfig::kDegenerate;
  if (kept.size() < static_cast<size_t>(options.min_num_inliers)) return;
  // OpenCV's RANSAC (RANSACPointSetRegistrator) draws its samples from a cv::RNG seeded with a
  // constant on each call: the same inputs give the same model and mask.
  cv::Mat mask;
  cv::Mat model;
  try {
    if (camera) {
      const double threshold = options.max_error_px / (0.5 * (camera->fx + camera->fy));
      model = cv::findEssentialMat(points1, points2, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC,
                                   options.confidence, threshold, options.max_num_trials, mask);
    } else {
      model = cv::findFundamentalMat(points1, points2, cv::FM_RANSAC, options.max_error_px,
                                     options.confidence, options.max_num_trials, mask);
    }
  } catch (const cv::Exception&) {
    return;  // A degenerate configuration OpenCV refuses: no geometry.
  }
  if (model.rows < 3 || model.cols != 3 || mask.empty()) return;
  FeatureMatches inliers = InliersOf(matches, kept, mask);
  if (inliers.size() < static_cast<size_t>(options.min_num_inliers)) return;
  pair->inlier_matches = std::move(inliers);
  const Eigen::Matrix3d estimated = ToEigen(model.rowRange(0, 3));
  if (camera) {
    // F of the pinhole part in COLMAP's pixels (exact without lens distortion).
    Eigen::Matrix3d k = Eigen::Matrix3d::Identity();
    k << camera->fx, 0, camera->cx + kColmapPixelOffset, 0, camera->fy,
        camera->cy + kColmapPixelOffset, 0, 0, 1;
    const Eigen::Matrix3d k_inverse = k.inverse();
    pair->config = TwoViewConfig::kCalibrated;
    pair->E = estimated;
    pair->F = k_inverse.transpose() * estimated * k_inverse;
  } else {
    pair->config = TwoViewConfig::kUncalibrated;
    pair->F = estimated;
  }
}

std::vector<PairGeometry> MatchImagePairs(const std::vector<ImageFeatures>& images,
                                          const std::vector<std::pair<size_t, size_t>>& pairs,
                                          const std::optional<Camera>& camera,
                                          const FeatureMatchingOptions& options) {
  options.Check();
  if (camera) camera->Check();
  for (const auto& [first, second] : pairs) {
    if (first >= images.size() || second >= images.size() ||
        !(images[first].image_id < images[second].image_id)) {
      throw InvalidArgumentError("image pair (" + std::to_string(first) + ", " +
                                 std::to_string(second) +
                                 ") is out of range or its image ids are not increasing");
    }
  }
  std::vector<PairGeometry> results(pairs.size());
  // One pair per block, dealt round-robin: pair k always runs alone on worker k mod threads and
  // writes only results[k].
  ParallelFor(
      pairs.size(), options.num_threads,
      [&](size_t begin, size_t end) {
        for (size_t k = begin; k < end; ++k) {
          const ImageFeatures& image1 = images[pairs[k].first];
          const ImageFeatures& image2 = images[pairs[k].second];
          PairGeometry& result = results[k];
          result.image_id1 = image1.image_id;
          result.image_id2 = image2.image_id;
          result.matches = MatchDescriptors(image1.descriptors, image2.descriptors, options);
          VerifyPair(image1, image2, camera, options, &result);
        }
      },
      /*block=*/1);
  return results;
}

DatabaseMatchingSummary MatchDatabase(const std::filesystem::path& database_path,
                                      int sequential_overlap, const std::optional<Camera>& camera,
                                      const FeatureMatchingOptions& options) {
  options.Check();
  if (sequential_overlap < 0) {
    throw InvalidArgumentError("sequential_overlap must be >= 0 (0: exhaustive)");
  }
  const std::vector<ImageFeatures> images = ReadImageFeatures(database_path);
  std::vector<std::pair<size_t, size_t>> pairs =
      sequential_overlap == 0 ? ExhaustivePairs(images.size())
                              : SequentialPairs(images.size(), sequential_overlap);
  for (auto& [first, second] : pairs) {
    if (images[first].image_id > images[second].image_id) std::swap(first, second);
  }
  std::sort(pairs.begin(), pairs.end(), [&](const auto& a, const auto& b) {
    return ColmapPairId(images[a.first].image_id, images[a.second].image_id) <
           ColmapPairId(images[b.first].image_id, images[b.second].image_id);
  });
  const std::vector<PairGeometry> results = MatchImagePairs(images, pairs, camera, options);
  WritePairGeometries(database_path, results);
  DatabaseMatchingSummary summary;
  summary.num_images = images.size();
  summary.num_pairs = results.size();
  for (const PairGeometry& result : results) {
    summary.num_matches += result.matches.size();
    summary.num_inlier_matches += result.inlier_matches.size();
    if (!result.inlier_matches.empty()) ++summary.num_verified_pairs;
  }
  return summary;
}

}  // namespace evloc::mapper
