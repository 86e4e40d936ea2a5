#include "core/features/features.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <string>
#include <tuple>

#include <Eigen/Core>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"

namespace evloc::features {
namespace {

// OpenCV's SIFT detector always starts from the image upsampled twice (octave -1) and reports
// positions as upsampled position / 2. The upsampling (resize, INTER_LINEAR_EXACT) uses
// half-pixel centres, so the centre of upsampled pixel X lies at source coordinate X / 2 - 0.25;
// the coarser octaves take every second pixel of the one above and inherit that offset. OpenCV's
// positions are therefore 0.25 px right of and below evloc's integer-centre convention, in every
// octave (measured on Gaussian blobs in features_test.cc).
constexpr float kOpenCvSiftOffset = 0.25f;

// An OpenCV SIFT keypoint's position in evloc's convention.
Eigen::Vector2f ToEvlocPixel(const cv::KeyPoint& keypoint) {
  return {keypoint.pt.x - kOpenCvSiftOffset, keypoint.pt.y - kOpenCvSiftOffset};
}

// Strongest first; ties broken by position, size and angle so that the order never depends on
// the order OpenCV's threads found the keypoints in.
bool StrongerFirst(const cv::KeyPoint& a, const cv::KeyPoint& b) {
  return std::make_tuple(-a.response, a.pt.y, a.pt.x, a.size, a.angle) <
         std::make_tuple(-b.response, b.pt.y, b.pt.x, b.size, b.angle);
}

// Indices (into `keypoints`, sorted strongest first) of at most `max_features` keypoints: first
// the strongest ones of each grid cell up to an equal quota, then the strongest remaining ones.
std::vector<int> SpreadOverGrid(const std::vector<cv::KeyPoint>& keypoints, int width, int height,
                                const FeatureOptions& options) {
  const int cells = options.grid_columns * options.grid_rows;
  const int quota = (options.max_features + cells - 1) / cells;
  std::vector<int> per_cell(cells, 0);
  std::vector<bool> taken(keypoints.size(), false);
  int count = 0;
  for (size_t i = 0; i < keypoints.size() && count < options.max_features; ++i) {
    const int column =
        std::clamp(static_cast<int>(keypoints[i].pt.x * options.grid_columns / width), 0,
                   options.grid_columns - 1);
    const int row = std::clamp(static_cast<int>(keypoints[i].pt.y * options.grid_rows / height), 0,
                               options.grid_rows - 1);
    int& in_cell = per_cell[row * options.grid_columns + column];
    if (in_cell < quota) {
      ++in_cell;
      taken[i] = true;
      ++count;
    }
  }
  for (size_t i = 0; i < keypoints.size() && count < options.max_features; ++i) {
    if (!taken[i]) {
      taken[i] = true;
      ++count;
    }
  }
  std::vector<int> selected;
  selected.reserve(count);
  for (size_t i = 0; i < keypoints.size(); ++i) {
    if (taken[i]) selected.push_back(static_cast<int>(i));
  }
  return selected;
}

// Converts one OpenCV SIFT descriptor row (floats holding integers 0..255) into a uint8 row.
void StoreDescriptor(const float* sift, bool root_sift, uint8_t* out) {
  if (!root_sift) {
    for (int k = 0; k < kDescriptorSize; ++k) out[k] = cv::saturate_cast<uint8_t>(sift[k]);
    return;
  }
  double l1 = 0;
  for (int k = 0; k < kDescriptorSize; ++k) l1 += std::abs(sift[k]);
  if (l1 <= 0) l1 = 1;
  for (int k = 0; k < kDescriptorSize; ++k) {
    out[k] = cv::saturate_cast<uint8_t>(255.0 * std::sqrt(std::abs(sift[k]) / l1));
  }
}

}  // namespace

void FeatureOptions::Check() const {
  if (max_features < 1) {
    throw InvalidArgumentError("FeatureOptions: max_features must be at least 1, got " +
                               std::to_string(max_features));
  }
  if (!(contrast_threshold > 0) || !std::isfinite(contrast_threshold)) {
    throw InvalidArgumentError("FeatureOptions: contrast_threshold must be positive and finite");
  }
  if (!(edge_threshold > 1) || !std::isfinite(edge_threshold)) {
    throw InvalidArgumentError("FeatureOptions: edge_threshold must be above 1 and finite");
  }
  if (grid_columns < 1 || grid_rows < 1 || grid_columns * grid_rows > max_features) {
    throw InvalidArgumentError(
        "FeatureOptions: grid_columns and grid_rows must be at least 1, with no more cells than "
        "max_features");
  }
}

cv::Mat Features::DescriptorsAsFloat() const {
  cv::Mat rows(size(), kDescriptorSize, CV_8U, const_cast<uint8_t*>(descriptors.data()));
  cv::Mat as_float;
  rows.convertTo(as_float, CV_32F);
  return as_float;
}

Features ExtractFeatures(const cv::Mat& image, const FeatureOptions& options) {
  options.Check();
  if (image.empty()) throw InvalidArgumentError("ExtractFeatures: the image is empty");
  cv::Mat grey;
  if (image.type() == CV_8UC1) {
    grey = image;
  } else if (image.type() == CV_8UC3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else {
    throw InvalidArgumentError("ExtractFeatures: the image must be 8-bit grey or BGR, got type " +
                               std::to_string(image.type()));
  }

  const cv::Ptr<cv::SIFT> sift =
      cv::SIFT::create(0, 3, options.contrast_threshold, options.edge_threshold, 1.6, CV_32F);
  std::vector<cv::KeyPoint> keypoints;
  sift->detect(grey, keypoints);
  std::sort(keypoints.begin(), keypoints.end(), StrongerFirst);
  std::vector<cv::KeyPoint> selected;
  for (const int index : SpreadOverGrid(keypoints, grey.cols, grey.rows, options)) {
    selected.push_back(keypoints[index]);
  }
  cv::Mat sift_descriptors;
  sift->compute(grey, selected, sift_descriptors);  // Keeps the keypoints and their order.
  assert(sift_descriptors.rows == static_cast<int>(selected.size()));

  Features features;
  const int count = static_cast<int>(selected.size());
  features.keypoints.reserve(count);
  features.descriptors.resize(static_cast<size_t>(count) * kDescriptorSize);
  for (int i = 0; i < count; ++i) {
    features.keypoints.push_back(ToEvlocPixel(selected[i]));
    features.sizes.push_back(selected[i].size);
    features.orientations.push_back(selected[i].angle * static_cast<float>(CV_PI / 180.0));
    StoreDescriptor(sift_descriptors.ptr<float>(i), options.root_sift,
                    features.descriptors.data() + static_cast<size_t>(i) * kDescriptorSize);
  }
  return features;
}

void MatchOptions::Check() const {
  if (!(max_ratio > 0 && max_ratio <= 1)) {
    throw InvalidArgumentError("MatchOptions: max_ratio must lie in (0, 1], got " +
                               std::to_string(max_ratio));
  }
}

std::vector<FeatureMatch> MatchFeatures(const Features& a, const Features& b,
                                        const MatchOptions& options) {
  options.Check();
  std::vector<FeatureMatch> matches;
  if (a.size() == 0 || b.size() < 2) return matches;
  // Exhaustive, as a brute-force matcher, but the squared distances come from one matrix
  // product, |x|^2 + |y|^2 - 2 x.y, with Eigen's blocked GEMM, several times faster than
  // OpenCV's BFMatcher, which computes each pair's distance on its own (docs/relocalization.md,
  // "Timings"), and mutual matching reads both directions from the same products. Exact:
  // the descriptors are integers below 256 in 128 dimensions, so every product, norm and sum
  // is an integer below 2^24, which a float holds exactly whatever the order of the additions.
  using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const int rows_a = a.size();
  const int rows_b = b.size();
  const RowMatrix descriptors_a =
      Eigen::Map<const Eigen::Matrix<uint8_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          a.descriptors.data(), rows_a, kDescriptorSize)
          .cast<float>();
  const RowMatrix descriptors_b =
      Eigen::Map<const Eigen::Matrix<uint8_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          b.descriptors.data(), rows_b, kDescriptorSize)
          .cast<float>();
  const Eigen::VectorXf norms_a = descriptors_a.rowwise().squaredNorm();
  const Eigen::RowVectorXf norms_b = descriptors_b.rowwise().squaredNorm().transpose();
  // Per row of a, its best and second-best squared distance in b; per row of b, its best in a.
  std::vector<int> best_b(rows_a, -1);
  std::vector<float> best_a_distance(rows_a), second_a_distance(rows_a);
  std::vector<int> best_a(rows_b, -1);
  std::vector<float> best_b_distance(rows_b, std::numeric_limits<float>::infinity());
  // In blocks of rows of a, so that the distance block stays small (256 x rows_b floats).
  constexpr int kBlock = 256;
  RowMatrix block;
  for (int begin = 0; begin < rows_a; begin += kBlock) {
    const int count = std::min(kBlock, rows_a - begin);
    block.noalias() = descriptors_a.middleRows(begin, count) * descriptors_b.transpose();
    for (int i = 0; i < count; ++i) {
      const int row = begin + i;
      float best = std::numeric_limits<float>::infinity();
      float second = best;
      int best_index = -1;
      for (int j = 0; j < rows_b; ++j) {
        const float distance = std::max(0.0f, norms_a(row) + norms_b(j) - 2 * block(i, j));
        if (distance < best) {
          second = best;
          best = distance;
          best_index = j;
        } else if (distance < second) {
          second = distance;
        }
        if (distance < best_b_distance[j]) {
          best_b_distance[j] = distance;
          best_a[j] = row;
        }
      }
      best_b[row] = best_index;
      best_a_distance[row] = best;
      second_a_distance[row] = second;
    }
  }
  for (int row = 0; row < rows_a; ++row) {
    const float best = std::sqrt(best_a_distance[row]);
    if (!(best < options.max_ratio * std::sqrt(second_a_distance[row]))) continue;
    if (options.mutual && best_a[best_b[row]] != row) continue;
    matches.push_back({row, best_b[row], best});
  }
  return matches;
}

}  // namespace evloc::features
