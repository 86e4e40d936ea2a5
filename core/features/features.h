// Local image features for relocalization: SIFT keypoints spread over the image by a grid, with
// (root-)SIFT descriptors stored as compact uint8 rows, and mutual nearest-neighbour matching with
// Lowe's ratio test. Keypoints follow evloc's pixel convention: pixel centres at integer
// coordinates, (0, 0) the centre of the top-left pixel (docs/relocalization.md).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

namespace evloc::features {

// Length of one SIFT descriptor.
inline constexpr int kDescriptorSize = 128;

// Options of ExtractFeatures.
struct FeatureOptions {
  // Most keypoints kept per image, after the grid spreading.
  int max_features = 2000;
  // SIFT's contrast threshold on the difference of Gaussians (OpenCV's scale, 0.04 by default);
  // lower finds more keypoints in low-contrast images.
  double contrast_threshold = 0.02;
  // SIFT's edge threshold: keypoints on edges with a larger principal-curvature ratio are rejected.
  double edge_threshold = 10.0;
  // Columns of the grid that spreads keypoints evenly; 1 disables the spreading.
  int grid_columns = 4;
  // Rows of that grid; 1 disables the spreading.
  int grid_rows = 4;
  // Root-SIFT (Arandjelovic and Zisserman 2012): L1-normalise, then take square roots, so that
  // Euclidean distances between descriptors compare like the Hellinger kernel.
  bool root_sift = true;

  // Throws InvalidArgumentError when a field is outside its domain.
  void Check() const;
};

// Keypoints and descriptors of one image.
struct Features {
  // Keypoint positions in pixels, evloc convention (integer pixel centres).
  std::vector<Eigen::Vector2f> keypoints;
  // Keypoint scales: the diameter of the SIFT neighbourhood, pixels.
  std::vector<float> sizes;
  // Keypoint orientations, radians in [0, 2 pi): OpenCV's KeyPoint::angle in radians, which
  // OpenCV measures clockwise on screen, i.e. from +x towards +y (image down).
  std::vector<float> orientations;
  // Descriptors, row-major, kDescriptorSize bytes per keypoint. For root-SIFT each row is the
  // square-rooted L1-normalised descriptor (unit L2 norm) scaled by 255 and rounded.
  std::vector<uint8_t> descriptors;

  // Number of keypoints.
  int size() const { return static_cast<int>(keypoints.size()); }
  // The descriptors as a float matrix (one row per keypoint), a copy.
  cv::Mat DescriptorsAsFloat() const;
};

// Detects SIFT keypoints in an 8-bit grey or BGR image and describes them. Deterministic: the
// same image and options give the same features, in the same order (strongest response first
// within the selection). Throws InvalidArgumentError for an empty image or an unsupported type.
Features ExtractFeatures(const cv::Mat& image, const FeatureOptions& options);

// Options of MatchFeatures.
struct MatchOptions {
  // Lowe's ratio: a match is kept when its distance is below this fraction of the second-best.
  double max_ratio = 0.8;
  // Keep only mutual nearest neighbours (a's best in b is b's best in a).
  bool mutual = true;

  // Throws InvalidArgumentError when max_ratio is outside (0, 1].
  void Check() const;
};

// One correspondence between two feature sets.
struct FeatureMatch {
  // Index of the keypoint in the first set.
  int index_a = 0;
  // Index of the keypoint in the second set.
  int index_b = 0;
  // Euclidean distance between the two descriptors (in the units of the uint8 rows).
  float distance = 0;
};

// Matches two feature sets by brute-force nearest neighbours with the ratio test (and mutual
// check), sorted by index_a. Deterministic.
std::vector<FeatureMatch> MatchFeatures(const Features& a, const Features& b,
                                        const MatchOptions& options);

}  // namespace evloc::features
