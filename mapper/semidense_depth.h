// Semi-dense probabilistic inverse depth on image edges per keyframe (docs/mapper.md, "Semi-dense
// depth per keyframe", after Mur-Artal & Tardós 2015 and Engel et al. 2013; details and defaults in
// docs/mapper.md): candidate edge pixels, a depth range from the sparse points, an epipolar search
// in each stereo neighbour, fusion of the hypotheses by the largest chi-square-compatible set,
// intra-keyframe regularisation, inter-keyframe consistency and a final Gauss-Newton refinement.
// The points are lifted into 3D with their gradients by maps/edge_lifting.h.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "maps/edge_lifting.h"

namespace evloc::mapper {

// An image prepared for the semi-dense stage: intensity and its gradient, camera and pose.
struct DepthFrame {
  // Intensity in [0, 1], CV_32F.
  cv::Mat intensity;
  // d intensity / dx, per pixel (Sobel / 8), CV_32F.
  cv::Mat gradient_x;
  // d intensity / dy, per pixel, CV_32F.
  cv::Mat gradient_y;
  // Canny edge mask of the image, CV_8U (255 on edges).
  cv::Mat edges;
  // Intrinsics.
  Camera camera;
  // Pose: p_cam = cam_from_world * p_world.
  Rigid3d cam_from_world;
};

// Options of the semi-dense stage.
struct SemiDenseOptions {
  // Canny hysteresis thresholds on the 8-bit image (L2 gradient, 3x3 Sobel).
  double canny_low_threshold = 40.0;
  // Upper Canny threshold.
  double canny_high_threshold = 100.0;
  // Candidate pixels need an intensity gradient modulus of at least this, per pixel (intensity
  // in [0, 1]).
  double min_gradient = 0.02;
  // Candidate pixels keep this distance to the image border, pixels.
  int border_margin = 4;
  // The depth range from the sparse points is widened by this factor: [min / f, max * f].
  double depth_range_margin = 1.25;
  // Reject a keyframe/neighbour pair for a pixel when the angle between the image gradient and
  // the epipolar line exceeds this (the edge then runs along the line), degrees.
  double max_gradient_epipolar_angle_deg = 70.0;
  // A match's gradient direction must be within this angle of the direction predicted by the
  // relative rotation, degrees.
  double max_gradient_orientation_difference_deg = 40.0;
  // A match's gradient modulus must be within this factor of the keyframe pixel's.
  double max_gradient_modulus_ratio = 2.5;
  // Epipolar search step, pixels along the line in the neighbour.
  double search_step_px = 1.0;
  // Longest searched epipolar segment, pixels (longer segments are skipped as uninformative).
  double max_search_length_px = 600.0;
  // Weight of the squared gradient-modulus difference in the matching cost, relative to the
  // five squared (mean-free) intensity differences.
  double gradient_cost_weight = 2.0;
  // Standard deviation of image noise, intensity units (photometric error).
  double intensity_sigma = 0.02;
  // Standard deviation of the epipolar line position from pose and calibration errors, pixels
  // (geometric error).
  double epipolar_sigma_px = 0.3;
  // Matching noise floor added to the disparity variance, pixels.
  double disparity_sigma_px = 0.3;
  // Largest accepted matching cost per sample (mean-free SSD / 5 + weighted gradient term).
  double max_match_cost = 0.004;
  // The second-best match away from the best must cost at least this factor more.
  double min_second_best_ratio = 1.5;
  // Chi-square threshold for compatibility of two inverse depths (1 degree of freedom, 95 %).
  double chi_square_threshold = 3.84;
  // Fusion keeps a pixel when its largest compatible hypothesis set has at least this many.
  int min_compatible_hypotheses = 2;
  // Intra-keyframe check: a pixel needs at least this many compatible 8-neighbours.
  int min_neighbour_support = 2;
  // Fill candidate pixels without depth from at least this many compatible 8-neighbours
  // (0 disables growing).
  int min_neighbours_to_grow = 2;
  // Inter-keyframe check: a point needs confirmation by at least this many other keyframes.
  int min_keyframe_confirmations = 2;
  // Gauss-Newton iterations of the final refinement.
  int refinement_iterations = 3;
  // Surface gradients of the lifted points (maps/edge_lifting.h, SurfaceGradients3d).
  SurfaceGradientOptions surface;
  // Worker threads.
  int num_threads = 2;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// One estimated edge pixel of a keyframe.
struct DepthPixel {
  // Pixel coordinates in the keyframe (integers, evloc convention).
  Eigen::Vector2i pixel = Eigen::Vector2i::Zero();
  // Inverse depth along the pixel's ray (ray with z = 1), 1/m.
  double inverse_depth = 0.0;
  // Variance of the inverse depth, 1/m^2.
  double inverse_depth_variance = 0.0;
  // Unit image gradient direction (increasing intensity).
  Eigen::Vector2d gradient_direction = Eigen::Vector2d::UnitX();
  // Image gradient modulus, intensity per pixel.
  double gradient_magnitude = 0.0;
  // Number of stereo hypotheses fused into the estimate.
  int num_hypotheses = 0;
  // Indices (into the keyframe list) of the other keyframes that confirmed the point.
  std::vector<uint32_t> confirming_keyframes;
};

// The semi-dense estimate of one keyframe.
struct KeyframeDepth {
  // Estimated pixels, in raster order.
  std::vector<DepthPixel> pixels;
  // Number of candidate edge pixels searched.
  size_t num_candidates = 0;
  // Pixels that survived fusion (before regularisation).
  size_t num_fused = 0;
};

// Prepares an image (8-bit grey or colour, or 16-bit grey) for the semi-dense stage. Throws
// InvalidArgumentError when the image is empty or its size differs from the camera's.
DepthFrame MakeDepthFrame(const cv::Mat& image, const Camera& camera, const Rigid3d& cam_from_world,
                          const SemiDenseOptions& options);

// Steps 1-5 of docs/mapper.md's semi-dense depth for one keyframe: candidates, epipolar search in
// each neighbour within [min_depth, max_depth] (already widened), fusion and intra-keyframe
// regularisation.
KeyframeDepth EstimateKeyframeDepth(const DepthFrame& keyframe,
                                    const std::vector<const DepthFrame*>& neighbours,
                                    double min_depth, double max_depth,
                                    const SemiDenseOptions& options);

// Step 6: keeps the pixels of each keyframe confirmed by at least min_keyframe_confirmations of
// its `consistency_neighbours` (indices into `keyframes`) and refines their inverse depth by
// Gauss-Newton on the inverse-depth differences to the confirming keyframes. Fills
// DepthPixel::confirming_keyframes.
void EnforceInterKeyframeConsistency(
    const std::vector<const DepthFrame*>& keyframes,
    const std::vector<std::vector<uint32_t>>& consistency_neighbours,
    const SemiDenseOptions& options, std::vector<KeyframeDepth>* depths);

// The pixels of `depth` (same order) as the input of edge lifting (maps/edge_lifting.h).
std::vector<EdgeDepthPixel> EdgeDepthPixels(const KeyframeDepth& depth);

// Depth range [min, max] of the sparse points in front of a camera, from the 2nd and 98th
// percentiles widened by `margin` (min / margin, max * margin). Returns false with fewer than 3
// points in front.
bool SparseDepthRange(const Rigid3d& cam_from_world, const std::vector<Eigen::Vector3d>& points,
                      double margin, double* min_depth, double* max_depth);

}  // namespace evloc::mapper
