// Semi-dense probabilistic inverse depth on image edges per keyframe (docs/method.md §3.2, after
// Mur-Artal & Tardós 2015 and Engel et al. 2013; details and defaults in docs/mapper.md):
// candidate edge pixels, a depth range from the sparse points, an epipolar search in each stereo
// neighbour, fusion of the hypotheses by the largest chi-square-compatible set, intra-keyframe
// regularisation, inter-keyframe consistency and a final Gauss-Newton refinement, and the 3D
// gradient vectors of §3.4.
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
  // Surface gradients (SurfaceGradients3d): half-size of the pixel window whose estimated points
  // give the local surface plane, pixels; 0 keeps the §3.4 gradients.
  int surface_window_px = 20;
  // Surface gradients: when the window's points are too few, or lie on one line (a single edge:
  // under a sideways motion only the edges across it get depth), the window is doubled up to
  // this many times (20 -> 40 -> 80 px).
  int surface_window_doublings = 2;
  // Surface gradients: the window needs at least this many points within
  // surface_max_depth_difference of the pixel's depth.
  int min_surface_points = 15;
  // Surface gradients: points of the window whose depth differs from the pixel's by more than
  // this fraction of it, and by more than surface_max_slope times the window's half-width at the
  // pixel's depth, belong to another surface and are left out (the second bound keeps floors and
  // walls seen at a grazing angle, whose depth changes fast across the window).
  double surface_max_depth_difference = 0.05;
  double surface_max_slope = 3.0;
  // Surface gradients: only the points on the brighter side of the edge (and on the edge line,
  // within this many pixels of it) are fitted. The gradient points into the brighter side, so on
  // a crease it lies in the brighter face, as defined by the ground-truth map of
  // docs/sim-scene.md; on a texture edge both sides are the same plane.
  double surface_edge_band_px = 1.0;
  // Surface gradients: the points are planar when their smallest principal standard deviation is
  // below this fraction of the middle one...
  double max_surface_thickness_ratio = 0.1;
  // ... and not on one line when the middle one is above this fraction of the largest.
  double min_surface_width_ratio = 0.15;
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

// Steps 1-5 of method.md §3.2 for one keyframe: candidates, epipolar search in each neighbour
// within [min_depth, max_depth] (already widened), fusion and intra-keyframe regularisation.
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

// The 3D gradient direction of method.md §3.4, in the camera frame: the ray through
// pixel + gradient_direction meets the plane through point_in_cam whose normal is the viewing
// direction; the result is the unit vector from the point to that intersection. Returns false
// when the ray cannot be formed or is parallel to the plane.
bool ComputeGradient3d(const Camera& camera, const Eigen::Vector2d& pixel,
                       const Eigen::Vector2d& gradient_direction,
                       const Eigen::Vector3d& point_in_cam, Eigen::Vector3d* gradient_in_cam);

// Per pixel of `depth` (same order), in the camera frame: the 3D gradient in the surface, the
// in-surface direction perpendicular to the 3D edge, where the surface is the plane fitted to the
// keyframe's points within options.surface_window_px of the pixel (same surface: similar depth)
// and the 3D edge is its intersection with the plane through the camera centre and the image
// edge; signed like the §3.4 gradient (ComputeGradient3d). Unlike the §3.4 gradient, which lies
// in the plane facing this keyframe, it is the scene's own gradient (docs/sim-scene.md), the same
// from every view. std::nullopt where the points are too few, not planar, on one line, or the
// surface is seen edge-on; every entry is std::nullopt when surface_window_px is 0.
std::vector<std::optional<Eigen::Vector3d>> SurfaceGradients3d(const Camera& camera,
                                                               const KeyframeDepth& depth,
                                                               const SemiDenseOptions& options);

// Depth range [min, max] of the sparse points in front of a camera, from the 2nd and 98th
// percentiles widened by `margin` (min / margin, max * margin). Returns false with fewer than 3
// points in front.
bool SparseDepthRange(const Rigid3d& cam_from_world, const std::vector<Eigen::Vector3d>& points,
                      double margin, double* min_depth, double* max_depth);

}  // namespace evloc::mapper
