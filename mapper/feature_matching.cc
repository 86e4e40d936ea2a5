#include "mapper/feature_matching.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <set>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "core/features/vocabulary.h"
#include "mapper/colmap_model.h"
#include "mapper/parallel_for.h"

namespace evloc::mapper {
namespace {

// COLMAP stores unit descriptors scaled by 512: the dot product of two is at most 512^2.
constexpr double kDescriptorNormSquared = 512.0 * 512.0;
// Below this squared norm a descriptor is not one COLMAP normalised (clamping bytes at 255 removes
// little of the 512^2): COLMAP 3.8's feature_extractor occasionally writes such a descriptor (one
// of 551 of slider_depth's frame 72 was [255, 0, 0, ...] in one of two runs, a normal one in the
// other). With an L2 search its small norm makes it the second-nearest neighbour of many
// descriptors, which changes their ratio tests; it takes no part in the matching.
constexpr float kMinDescriptorNormSquared = 0.5f * 512.0f * 512.0f;
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

// A descriptor's two nearest neighbours in the other image by L2 distance, as COLMAP 3.8's CPU
// matcher searches them (FLANN, approximately; exactly here), with their dot products. The key
// of a candidate is its squared L2 distance less the query's own squared norm: |c|^2 - 2 q.c.
struct NearestTwo {
  struct Neighbour {
    float key = std::numeric_limits<float>::max();
    float dot = 0.0f;
    int index = -1;
  };
  Neighbour best;
  Neighbour second;

  // Ties keep the earlier candidate (candidates arrive in increasing index order).
  void Update(float key, float dot, int candidate) {
    if (key < best.key) {
      second = best;
      best = {key, dot, candidate};
    } else if (key < second.key) {
      second = {key, dot, candidate};
    }
  }
};

// COLMAP's choice among the two neighbours: the larger dot product is the match (the nearer
// neighbour on a tie), the other one is the second best; a zero dot product is no match.
struct BestTwo {
  float best = 0.0f;
  float second = 0.0f;
  int index = -1;

  explicit BestTwo(const NearestTwo& nearest) {
    for (const NearestTwo::Neighbour& neighbour : {nearest.best, nearest.second}) {
      if (neighbour.index < 0) continue;
      if (neighbour.dot > best) {
        second = best;
        best = neighbour.dot;
        index = neighbour.index;
      } else if (neighbour.dot > second) {
        second = neighbour.dot;
      }
    }
  }
};

// The angle between two descriptors of dot product `dot` (COLMAP's normalised distance).
double DescriptorAngle(float dot) {
  return std::acos(std::min(static_cast<double>(dot) / kDescriptorNormSquared, 1.0));
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

// COLMAP 3.8's TwoViewGeometry::Options: min_E_F_inlier_ratio and max_H_inlier_ratio.
constexpr double kMinEssentialToFundamentalInliers = 0.95;
constexpr double kMaxHomographyToEpipolarInliers = 0.8;

// A RANSAC model (its first 3x3 solution) and its inlier mask; no inliers when it failed.
struct RansacResult {
  cv::Mat model;
  cv::Mat mask;
  size_t num_inliers = 0;
};

// Runs `estimate(&mask)`; a failure or a configuration OpenCV refuses gives no inliers.
template <typename Estimate>
RansacResult RunRansac(const Estimate& estimate) {
  RansacResult result;
  cv::Mat model;
  try {
    model = estimate(&result.mask);
  } catch (const cv::Exception&) {
    return {};
  }
  if (model.rows < 3 || model.cols != 3 || result.mask.empty()) return {};
  result.model = model.rowRange(0, 3).clone();
  result.num_inliers = static_cast<size_t>(cv::countNonZero(result.mask));
  return result;
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

std::vector<std::pair<size_t, size_t>> RetrievalPairs(const std::vector<ImageFeatures>& images,
                                                      int neighbours) {
  if (neighbours < 1) throw InvalidArgumentError("retrieval neighbours must be >= 1");
  const features::VocabularyOptions vocabulary_options;
  size_t total = 0;
  for (const ImageFeatures& image : images) total += image.keypoints.size();
  if (total < static_cast<size_t>(vocabulary_options.num_words)) return {};
  // The training sample, taken at an even stride over all descriptors (never all of them in
  // float: a chunk holds millions).
  const size_t stride =
      std::max<size_t>(1, total / static_cast<size_t>(vocabulary_options.max_training_descriptors));
  cv::Mat sample;
  size_t index = 0;
  for (const ImageFeatures& image : images) {
    for (size_t k = 0; k < image.keypoints.size(); ++k, ++index) {
      if (index % stride != 0) continue;
      cv::Mat row(1, kSiftDescriptorSize, CV_32F);
      for (int d = 0; d < kSiftDescriptorSize; ++d) {
        row.at<float>(0, d) = image.descriptors[k * kSiftDescriptorSize + d];
      }
      sample.push_back(row);
    }
  }
  const features::Vocabulary vocabulary = features::Vocabulary::Train(sample, vocabulary_options);
  std::vector<std::vector<float>> vlad(images.size());
  for (size_t i = 0; i < images.size(); ++i) {
    const ImageFeatures& image = images[i];
    if (image.keypoints.empty()) {
      vlad[i].assign(static_cast<size_t>(vocabulary.vlad_size()), 0.0f);
      continue;
    }
    cv::Mat descriptors(static_cast<int>(image.keypoints.size()), kSiftDescriptorSize, CV_8U,
                        const_cast<uint8_t*>(image.descriptors.data()));
    cv::Mat as_float;
    descriptors.convertTo(as_float, CV_32F);
    vlad[i] = vocabulary.EncodeVlad(as_float);
  }
  const Eigen::MatrixXf similarity = features::CosineSimilarities(vlad);
  const std::vector<std::vector<size_t>> nearest =
      features::MostSimilar(similarity, static_cast<size_t>(neighbours));
  std::set<std::pair<size_t, size_t>> pairs;
  for (size_t i = 0; i < images.size(); ++i) {
    if (images[i].keypoints.empty()) continue;
    for (const size_t j : nearest[i]) {
      if (!images[j].keypoints.empty()) pairs.emplace(std::min(i, j), std::max(i, j));
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
  std::vector<NearestTwo> forward_nearest(static_cast<size_t>(rows1));
  std::vector<NearestTwo> backward_nearest(static_cast<size_t>(rows2));
  const Eigen::VectorXf norms1 = first.rowwise().squaredNorm();
  const Eigen::VectorXf norms2 = second.rowwise().squaredNorm();
  // Products of bytes summed in float are exact (every partial sum, squared norms included, is an
  // integer below 2^24, and so is each key |c|^2 - 2 q.c in magnitude), so the keys and dot
  // products do not depend on the order of the sums.
  for (Eigen::Index begin = 0; begin < rows1; begin += kMatchBlockRows) {
    const Eigen::Index count = std::min<Eigen::Index>(kMatchBlockRows, rows1 - begin);
    const Eigen::MatrixXf dots = first.middleRows(begin, count) * second.transpose();
    for (Eigen::Index j = 0; j < rows2; ++j) {
      if (norms2(j) < kMinDescriptorNormSquared) continue;
      NearestTwo& column = backward_nearest[static_cast<size_t>(j)];
      for (Eigen::Index r = 0; r < count; ++r) {
        if (norms1(begin + r) < kMinDescriptorNormSquared) continue;
        const float dot = dots(r, j);
        forward_nearest[static_cast<size_t>(begin + r)].Update(norms2(j) - 2.0f * dot, dot,
                                                               static_cast<int>(j));
        column.Update(norms1(begin + r) - 2.0f * dot, dot, static_cast<int>(begin + r));
      }
    }
  }
  const std::vector<BestTwo> forward(forward_nearest.begin(), forward_nearest.end());
  const std::vector<BestTwo> backward(backward_nearest.begin(), backward_nearest.end());
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
  std::vector<cv::Point2d> pixels1;
  std::vector<cv::Point2d> pixels2;
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
    }
    pixels1.emplace_back(pixel1.x(), pixel1.y());
    pixels2.emplace_back(pixel2.x(), pixel2.y());
    kept.push_back(i);
  }
  pair->config = TwoViewConfig::kDegenerate;
  if (kept.size() < static_cast<size_t>(options.min_num_inliers)) return;
  const size_t min_inliers = static_cast<size_t>(options.min_num_inliers);
  // OpenCV's RANSAC (RANSACPointSetRegistrator) draws its samples from a cv::RNG seeded with a
  // constant on each call: the same inputs give the same models and masks.
  const RansacResult fundamental = RunRansac([&](cv::Mat* mask) {
    // OpenCV's F error is the larger of the two point-to-epipolar-line distances; COLMAP's is the
    // Sampson distance, about 1/sqrt(2) of it: sqrt(2) * max_error_px selects the same points.
    return cv::findFundamentalMat(pixels1, pixels2, cv::FM_RANSAC,
                                  std::numbers::sqrt2 * options.max_error_px, options.confidence,
                                  options.max_num_trials, *mask);
  });
  const RansacResult homography = RunRansac([&](cv::Mat* mask) {
    return cv::findHomography(pixels1, pixels2, cv::RANSAC, options.max_error_px, *mask,
                              options.max_num_trials, options.confidence);
  });
  RansacResult essential;
  if (camera) {
    essential = RunRansac([&](cv::Mat* mask) {
      const double threshold = options.max_error_px / (0.5 * (camera->fx + camera->fy));
      return cv::findEssentialMat(points1, points2, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC,
                                  options.confidence, threshold, options.max_num_trials, *mask);
    });
  }
  // COLMAP 3.8's TwoViewGeometry::EstimateCalibrated: calibrated when E explains more than 95 %
  // of F's inliers, then the larger of the E and F inlier sets; else uncalibrated with F's; a
  // homography explaining more than 80 % of the epipolar inliers makes it planar or panoramic
  // and its inliers are kept when there are more of them; a homography alone also counts.
  const auto ratio = [](size_t numerator, size_t denominator) {
    return denominator == 0 ? 0.0
                            : static_cast<double>(numerator) / static_cast<double>(denominator);
  };
  const RansacResult* best = nullptr;
  size_t epipolar_inliers = 0;
  if (camera && essential.num_inliers >= min_inliers &&
      ratio(essential.num_inliers, fundamental.num_inliers) > kMinEssentialToFundamentalInliers) {
    best = essential.num_inliers >= fundamental.num_inliers ? &essential : &fundamental;
    epipolar_inliers = essential.num_inliers;
    pair->config = TwoViewConfig::kCalibrated;
  } else if (fundamental.num_inliers >= min_inliers) {
    best = &fundamental;
    epipolar_inliers = fundamental.num_inliers;
    pair->config = TwoViewConfig::kUncalibrated;
  } else if (homography.num_inliers >= min_inliers) {
    best = &homography;
    pair->config = TwoViewConfig::kPlanarOrPanoramic;
  } else {
    return;
  }
  if (best != &homography &&
      ratio(homography.num_inliers, epipolar_inliers) > kMaxHomographyToEpipolarInliers) {
    pair->config = TwoViewConfig::kPlanarOrPanoramic;
    if (homography.num_inliers > best->num_inliers) best = &homography;
  }
  pair->inlier_matches = InliersOf(matches, kept, best->mask);
  if (!homography.model.empty()) pair->H = ToEigen(homography.model);
  if (!fundamental.model.empty()) pair->F = ToEigen(fundamental.model);
  if (!essential.model.empty()) {
    // F of the pinhole part in COLMAP's pixels (exact without lens distortion).
    Eigen::Matrix3d k = Eigen::Matrix3d::Identity();
    k << camera->fx, 0, camera->cx + kColmapPixelOffset, 0, camera->fy,
        camera->cy + kColmapPixelOffset, 0, 0, 1;
    const Eigen::Matrix3d k_inverse = k.inverse();
    pair->E = ToEigen(essential.model);
    if (pair->config == TwoViewConfig::kCalibrated) {
      pair->F = k_inverse.transpose() * pair->E * k_inverse;
    }
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
                                      const PairChoice& choice, const std::optional<Camera>& camera,
                                      const FeatureMatchingOptions& options) {
  options.Check();
  if (choice.sequential_overlap < 0 || choice.retrieval_neighbours < 0) {
    throw InvalidArgumentError(
        "the sequential overlap and the retrieval neighbours must be >= 0 (both 0: exhaustive)");
  }
  const std::vector<ImageFeatures> images = ReadImageFeatures(database_path);
  std::vector<std::pair<size_t, size_t>> pairs;
  if (choice.sequential_overlap == 0 && choice.retrieval_neighbours == 0) {
    pairs = ExhaustivePairs(images.size());
  } else {
    std::set<std::pair<size_t, size_t>> chosen;
    if (choice.sequential_overlap > 0) {
      for (const auto& pair : SequentialPairs(images.size(), choice.sequential_overlap)) {
        chosen.insert(pair);
      }
    }
    if (choice.retrieval_neighbours > 0) {
      for (const auto& pair : RetrievalPairs(images, choice.retrieval_neighbours)) {
        chosen.insert(pair);
      }
    }
    pairs.assign(chosen.begin(), chosen.end());
  }
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
