// evloc's deterministic replacement of COLMAP 3.8's exhaustive_matcher / sequential_matcher
// (docs/mapper.md, "Reproducible maps"): the SIFT features COLMAP's feature_extractor wrote into
// the database are matched by brute force (each descriptor's two nearest neighbours by exact
// integer L2 distance, then COLMAP's ratio and distance tests on their dot products, mutual
// cross-check, COLMAP's default thresholds), each pair is verified with fixed-seed RANSACs
// (OpenCV's essential matrix on undistorted normalised coordinates for a calibrated camera, the
// fundamental matrix and the homography on pixels, and COLMAP 3.8's choice among them), and the
// matches and two-view geometries are written back
// for COLMAP's mapper and point_triangulator. The result depends only on the features: the same
// bytes for any run and any thread count.
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <utility>
#include <vector>

#include "core/camera/camera.h"
#include "mapper/colmap_database.h"

namespace evloc::mapper {

// Options of evloc's matcher; the defaults are COLMAP 3.8's SiftMatchingOptions and
// TwoViewGeometry::Options.
struct FeatureMatchingOptions {
  // Lowe ratio test: best / second-best descriptor angle must be below this.
  double max_ratio = 0.8;
  // Maximum angle (radians) between two unit-normalised descriptors of a match.
  double max_distance = 0.7;
  // Keep only mutual best matches.
  bool cross_check = true;
  // RANSAC inlier threshold (pixels; Sampson distance for the essential and fundamental matrix).
  double max_error_px = 4.0;
  // RANSAC confidence.
  double confidence = 0.999;
  // Maximum RANSAC iterations.
  int max_num_trials = 10000;
  // Minimum raw matches to verify a pair and minimum inliers to keep its geometry.
  int min_num_inliers = 15;
  // Worker threads over pairs (the result does not depend on it).
  int num_threads = 1;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// Indices (into an image list sorted by name) of the pairs COLMAP 3.8's exhaustive_matcher
// matches: every pair (i, j), i < j.
std::vector<std::pair<size_t, size_t>> ExhaustivePairs(size_t num_images);

// Indices of the pairs COLMAP 3.8's sequential_matcher matches without loop detection: each image
// i with i + 1 ... i + overlap - 1 and, with quadratic overlap (its default), i + 2^k for
// k < overlap while i + k is in range; duplicates removed, sorted.
std::vector<std::pair<size_t, size_t>> SequentialPairs(size_t num_images, int overlap);

// Pairs of each image with its `neighbours` most similar images by image retrieval, as COLMAP's
// vocab_tree_matcher chooses them (which needs a vocabulary file Debian does not ship): a VLAD
// vector per image (core/features: a 32-word vocabulary trained by k-means on at most 50,000 of
// the images' own SIFT descriptors, taken at an even stride) and their cosine similarities.
// Indices into `images`, each pair (i, j) with i < j, duplicates removed, sorted. Deterministic.
// Images without features pair with nothing.
std::vector<std::pair<size_t, size_t>> RetrievalPairs(const std::vector<ImageFeatures>& images,
                                                      int neighbours);

// Which pairs MatchDatabase matches: every pair (both zero), or the union of SequentialPairs with
// sequential_overlap (when > 0) and RetrievalPairs with retrieval_neighbours (when > 0).
struct PairChoice {
  int sequential_overlap = 0;
  int retrieval_neighbours = 0;
};

// Brute-force descriptor matching of two images (rows x 128 SIFT bytes, COLMAP's normalisation
// to a norm of about 512), as COLMAP 3.8's CPU matcher does it without FLANN's approximation:
// each descriptor's two nearest neighbours by L2 distance; of these, the larger dot product is
// the match, whose angle must be within max_distance and below max_ratio times the other's;
// mutual with cross_check. (Ranking by dot product instead differs where the byte descriptors'
// norms differ and gave 1.4 % fewer matches than COLMAP's on the room circle.) Distances and dot
// products are exact integers, ties go to the lower index: the result does not depend on how it
// is computed. Sorted by first index.
FeatureMatches MatchDescriptors(const std::vector<uint8_t>& descriptors1,
                                const std::vector<uint8_t>& descriptors2,
                                const FeatureMatchingOptions& options);

// Geometric verification of `pair.matches` between two images' keypoints (COLMAP pixels): fills
// inlier_matches, config and the matrices, as COLMAP 3.8's TwoViewGeometry::EstimateCalibrated
// chooses them. Estimated: with `camera` (both images) the essential matrix on undistorted
// normalised coordinates (threshold max_error_px / mean focal length); the fundamental matrix
// and the homography on the pixels (max_error_px). kCalibrated when E has at least
// min_num_inliers and more than 95 % of F's inliers, keeping the larger of the E and F inlier
// sets; else kUncalibrated with F's; a homography with more than 80 % of those inliers makes it
// kPlanarOrPanoramic, keeping H's inliers when more; H alone also gives kPlanarOrPanoramic.
// Fewer raw matches than min_num_inliers: left kUndefined; no model with min_num_inliers:
// kDegenerate without inliers. F is E's through the pinhole intrinsics when calibrated.
void VerifyPair(const ImageFeatures& image1, const ImageFeatures& image2,
                const std::optional<Camera>& camera, const FeatureMatchingOptions& options,
                PairGeometry* pair);

// Matches and verifies `pairs` (indices into `images`; each pair's ids are sorted) on
// options.num_threads threads with a fixed partition; results in the order of `pairs`.
std::vector<PairGeometry> MatchImagePairs(const std::vector<ImageFeatures>& images,
                                          const std::vector<std::pair<size_t, size_t>>& pairs,
                                          const std::optional<Camera>& camera,
                                          const FeatureMatchingOptions& options);

// Counts of one database matching run.
struct DatabaseMatchingSummary {
  // Images read from the database.
  size_t num_images = 0;
  // Pairs matched.
  size_t num_pairs = 0;
  // Raw matches over all pairs.
  size_t num_matches = 0;
  // Pairs with a verified geometry.
  size_t num_verified_pairs = 0;
  // Inlier matches over all pairs.
  size_t num_inlier_matches = 0;
};

// Reads the features of `database_path`, matches the pairs `choice` names (in the database's
// image order, by name) and replaces its matches and two-view geometries, ordered by pair id.
// Throws InvalidArgumentError for a negative count, and like ReadImageFeatures and
// WritePairGeometries.
DatabaseMatchingSummary MatchDatabase(const std::filesystem::path& database_path,
                                      const PairChoice& choice, const std::optional<Camera>& camera,
                                      const FeatureMatchingOptions& options);

}  // namespace evloc::mapper
