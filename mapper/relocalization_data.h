// The relocalization data of a map (format v2, docs/mapper.md "Relocalization data"): SIFT
// features of every keyframe image, matched with the keyframes nearest by pose, triangulated
// with the keyframes' known poses into landmarks (feature tracks merged across keyframes), the
// features that see a landmark, a visual vocabulary trained on them, and each keyframe's VLAD.
// One computation for `evloc-mapper build` (a stage) and `evloc-mapper upgrade`.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/features/features.h"
#include "core/features/vocabulary.h"
#include "maps/map.h"

namespace evloc::mapper {

// Options of ComputeRelocalizationData.
struct RelocalizationDataOptions {
  // SIFT extraction on every keyframe image (core/features defaults).
  features::FeatureOptions features;
  // Matching between keyframes (mutual, ratio 0.8).
  features::MatchOptions matching;
  // The vocabulary trained on the features that see a landmark (32 words, fixed seed).
  features::VocabularyOptions vocabulary;
  // Each keyframe is matched with this many other keyframes, nearest camera centres first.
  int num_neighbours = 4;
  // Keyframes whose optical axes differ by more than this are not matched, degrees.
  double max_neighbour_angle_deg = 60.0;
  // A landmark must be seen (within the reprojection limit) by at least this many keyframes: two
  // views cannot refute a wrong match along the epipolar line, a third can.
  int min_views = 3;
  // A landmark needs two of its viewing rays at least this far apart, degrees.
  double min_parallax_deg = 2.0;
  // A landmark must reproject within this distance of its keypoint in every keyframe that keeps
  // it, pixels; views beyond it are dropped (worst first) while min_views remain.
  double max_reprojection_error_px = 2.0;
  // Threads for feature extraction and matching; the result does not depend on it.
  int num_threads = 1;

  // Throws InvalidArgumentError when a field is outside its domain.
  void Check() const;
};

// Figures of one ComputeRelocalizationData run (report.json "relocalization").
struct RelocalizationDataStatistics {
  // SIFT features extracted, summed over keyframes.
  size_t num_features_extracted = 0;
  // Keyframe pairs matched.
  size_t num_matched_pairs = 0;
  // Matches that passed the two-view check, summed over pairs.
  size_t num_verified_matches = 0;
  // Landmarks kept.
  size_t num_landmarks = 0;
  // Keyframe features kept (those that see a landmark).
  size_t num_features_kept = 0;
  // Bytes the data adds to the .evmap file.
  uint64_t bytes_added = 0;
};

// Computes the relocalization data of `map` (keyframes, cameras and poses; not changed) from the
// keyframe images given by `load_image(keyframe index)` (8-bit grey, the keyframe camera's size).
// Deterministic. Throws InvalidArgumentError when an image has the wrong size or fewer features
// see a landmark than the vocabulary has words, and what load_image throws.
RelocalizationData ComputeRelocalizationData(
    const Map& map, const std::function<cv::Mat(size_t keyframe)>& load_image,
    const RelocalizationDataOptions& options, RelocalizationDataStatistics* statistics = nullptr);

// ComputeRelocalizationData with the keyframe images read from `image_dir` by
// Keyframe::image_name. Throws IoError naming a missing or unreadable image.
RelocalizationData ComputeRelocalizationData(const Map& map, const std::filesystem::path& image_dir,
                                             const RelocalizationDataOptions& options,
                                             RelocalizationDataStatistics* statistics = nullptr);

}  // namespace evloc::mapper
