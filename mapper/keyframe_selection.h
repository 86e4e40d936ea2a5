// Keyframe selection and neighbour choice for the semi-dense stage (docs/mapper.md, "Keyframes"):
// a view becomes a keyframe when it has moved or turned enough from the last keyframe, or sees
// too few of its sparse points; each keyframe gets the registered views it shares most sparse
// points with, among those with a usable baseline, as stereo neighbours.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "core/geometry/rigid3.h"

namespace evloc::mapper {

// A registered image with the sparse points it observes.
struct RegisteredView {
  // Image name relative to the image folder.
  std::string image_name;
  // Capture time, nanoseconds (0 when unknown).
  int64_t t_ns = 0;
  // Pose: p_cam = cam_from_world * p_world.
  Rigid3d cam_from_world;
  // Ids of the sparse 3D points the view observes (keys of the sparse point map).
  std::vector<uint64_t> observed_points;
};

// Options of SelectKeyframes.
struct KeyframeSelectionOptions {
  // At most this many keyframes (evenly thinned out in view order); std::nullopt: no limit.
  std::optional<int> max_keyframes;
  // At least this many keyframes when there are that many views (and max_keyframes allows):
  // when the thresholds below give
  // fewer (short video-like sequences), the baseline and rotation thresholds are halved until
  // they give enough, and as a last resort the keyframes are spread evenly over the views.
  int min_keyframes = 12;
  // A view becomes a keyframe when it shares less than this fraction of the last keyframe's
  // sparse points.
  double max_shared_fraction = 0.7;
  // A view becomes a keyframe when its distance to the last keyframe exceeds this fraction of
  // the last keyframe's median scene depth.
  double max_baseline_ratio = 0.1;
  // A view becomes a keyframe when its orientation differs from the last keyframe's by more
  // than this, degrees.
  double max_rotation_deg = 15.0;
  // Stereo neighbours per keyframe (6-10 is the usual range, docs/mapper.md).
  int num_neighbours = 6;
  // A neighbour must share at least this many sparse points with the keyframe.
  int min_shared_points = 15;
  // A neighbour's baseline must be at least this fraction of the keyframe's median depth.
  double min_neighbour_baseline_ratio = 0.02;
  // Neighbours are ranked by shared sparse points times min(1, baseline / (this fraction of the
  // keyframe's median depth)): among views that share the structure, wider baselines (more
  // precise depth) come first up to this ratio.
  double preferred_neighbour_baseline_ratio = 0.08;
  // A neighbour's optical axis must be within this angle of the keyframe's, degrees.
  double max_neighbour_angle_deg = 50.0;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// The selected keyframes and their neighbours.
struct KeyframeSelection {
  // Indices into the views of the keyframes, increasing.
  std::vector<size_t> keyframes;
  // For each keyframe, indices into the views of its stereo neighbours, best first.
  std::vector<std::vector<size_t>> neighbours;
  // For each keyframe, the median depth of its sparse points (0 when it sees none).
  std::vector<double> median_depths;
};

// Selects keyframes among `views` (in capture order) and their neighbours among all views.
// `sparse_points` maps point ids to world positions. Throws InvalidArgumentError when the options
// are bad, `views` is empty, or a view refers to an unknown point.
KeyframeSelection SelectKeyframes(
    const std::vector<RegisteredView>& views,
    const std::unordered_map<uint64_t, Eigen::Vector3d>& sparse_points,
    const KeyframeSelectionOptions& options);

}  // namespace evloc::mapper
