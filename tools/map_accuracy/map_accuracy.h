// Accuracy of a built map against an exact scene (docs/mapper.md, "Accuracy on synthetic
// sequences"): depth error against rendered depth maps, distance to the ground-truth edge map and
// the angle between 3D gradients; and, for real images, how far the map projects from the
// keyframe images' edges.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "maps/map.h"

namespace evloc::mapper {

// A rendered depth map with its camera and pose.
struct DepthView {
  // Intrinsics of the depth map.
  Camera camera;
  // Pose: p_cam = cam_from_world * p_world.
  Rigid3d cam_from_world;
  // z along the optical axis, metres, CV_32F; 0 where nothing was hit.
  cv::Mat depth_m;
  // Capture time, nanoseconds: the view of a map keyframe with the same t_ns is the one whose
  // rays observed the keyframe's points.
  std::optional<int64_t> t_ns;
};

// The rendered depth maps of an evloc-sim dataset, every `stride`-th one of depth.txt, read with
// core/dataset (ReadDataset, ReadDepthPng) and posed by groundtruth.txt; a depth map outside the
// ground truth's time span is left out. Throws IoError / ParseError (naming the file and line) for
// missing, unreadable or malformed files, InvalidArgumentError for a stride below 1.
std::vector<DepthView> ReadDatasetDepthViews(const std::filesystem::path& dataset, int stride = 1);

// Options of MeasureMapAccuracy.
struct MapAccuracyOptions {
  // Points within this distance count as accurate, metres (the "within" fractions).
  double within_m = 0.02;
  // The depth error of a point is the smallest |z - depth| over a window of this half-size around
  // its projection (an edge point may fall on either side of a depth discontinuity), pixels.
  int depth_window_half_size_px = 1;
  // Two nearest ground-truth points closer than this to each other form an edge segment whose
  // distance is used (the ground truth samples edges discretely), metres.
  double max_segment_length_m = 0.025;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// The measured accuracy.
struct MapAccuracy {
  // Points of the measured map.
  size_t num_points = 0;
  // Points that project into a depth view with valid depth nearby.
  size_t num_depth_compared = 0;
  // Of those, the points compared in the view of their source keyframe (along the rays that
  // observed them); the others in the nearest view by camera centre.
  size_t num_depth_in_source_view = 0;
  // Median depth error along the optical axis of the compared view (the source keyframe's when
  // a view has its time, else the nearest by camera centre, which may see the point occluded),
  // metres.
  double median_depth_error_m = 0.0;
  // Median of the signed depth error (map depth minus rendered depth), metres: a bias, e.g. from a
  // scale error of estimated poses, shows here.
  double median_signed_depth_error_m = 0.0;
  // Fraction of the compared points with a depth error within within_m.
  double depth_within_fraction = 0.0;
  // Median distance to the ground-truth edges (segment of the two nearest points), metres.
  double median_edge_distance_m = 0.0;
  // Fraction of the points within within_m of the ground-truth edges.
  double edge_within_fraction = 0.0;
  // Median angle between a point's 3D gradient and its nearest ground-truth point's, degrees.
  double median_gradient_angle_deg = 0.0;
  // Fraction of the points whose 3D gradient is within 10 degrees of the ground truth's.
  double gradient_within_10deg_fraction = 0.0;
  // Fraction of the points whose 3D gradient is more than 90 degrees off (opposite sign).
  double gradient_opposite_fraction = 0.0;
  // Median angle between the two gradients projected into the nearest depth view, degrees
  // (what tracking uses: the 3D gradient of method.md §3.4 is only defined up to the viewing
  // direction).
  double median_image_gradient_angle_deg = 0.0;
  // The gradient measures restricted to points whose nearest ground-truth point has a defined
  // gradient (reference_gradient_defined; all points without it).
  size_t num_gradient_defined = 0;
  double median_gradient_angle_defined_deg = 0.0;
  double gradient_within_10deg_defined_fraction = 0.0;
  double gradient_opposite_defined_fraction = 0.0;
};

// The measures of one map point (NaN where not measured).
struct PointAccuracy {
  // Smallest |depth error| around the projection into the nearest depth view, metres.
  double depth_error_m = 0.0;
  // Distance to the ground-truth edges, metres.
  double edge_distance_m = 0.0;
  // 3D gradient angle to the nearest ground-truth point's, degrees.
  double gradient_angle_deg = 0.0;
  // Angle of the two gradients projected into the nearest depth view, degrees.
  double image_gradient_angle_deg = 0.0;
  // Index of the nearest ground-truth point.
  uint32_t reference_index = 0;
};

// Measures `map` against the exact `reference` map and rendered `views`; with `per_point`, also
// the measures of every map point (same order as the map). `reference_gradient_defined` (one flag
// per reference point, or empty: all defined) marks the reference points whose gradient an image
// can show: false for convex creases, which are occluding contours from some viewpoints (their
// image contrast is against the background, docs/sim-scene.md) or hidden behind a touching box.
// Throws InvalidArgumentError when the options are bad, either map is empty, or the flags do not
// match the reference.
MapAccuracy MeasureMapAccuracy(const Map& map, const Map& reference,
                               const std::vector<DepthView>& views,
                               const MapAccuracyOptions& options,
                               std::vector<PointAccuracy>* per_point = nullptr,
                               const std::vector<bool>& reference_gradient_defined = {});

// Edge distance of a map on real images: for each keyframe, the Canny edges (thresholds 40/100 on
// 8 bits, L2 gradient) of its image `image_dir / keyframe.image_name`, their distance transform,
// and its bilinear value at the projection of each of the keyframe's visible points (through the
// keyframe's camera, distortion included). All distances pooled, pixels, sorted ascending. Throws
// IoError when a keyframe image cannot be read.
std::vector<double> KeyframeEdgeDistances(const Map& map, const std::filesystem::path& image_dir);

}  // namespace evloc::mapper
