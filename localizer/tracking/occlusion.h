// Occlusion culling with an approximate nearest-neighbour field (ANNF, method.md §4.4): every
// pixel knows its nearest active edge pixel; map points claiming the same edge pixel are resolved
// by a z-buffer keyed by that edge pixel (the nearest point wins), and points with no edge pixel
// within a radius drop out.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace evloc::tracking {

// For every pixel, the nearest edge pixel of a binary edge image (cv::distanceTransform with
// DIST_LABEL_PIXEL, 5x5 mask: approximate Euclidean distances).
class NearestEdgeField {
 public:
  // Builds the field of `edge_mask` (CV_8UC1, non-zero = edge). Throws InvalidArgumentError for
  // another type or an empty image.
  void Build(const cv::Mat& edge_mask);

  // Image width, pixels.
  int width() const { return distance_.cols; }
  // Image height, pixels.
  int height() const { return distance_.rows; }
  // True when the last built image had no edge pixel (or nothing was built).
  bool empty() const { return num_edge_pixels_ == 0; }
  // Number of edge pixels.
  int num_edge_pixels() const { return num_edge_pixels_; }

  // The nearest edge pixel of pixel (x, y), as the row-major index y * width + x, and its
  // (approximate) distance in pixels. False when (x, y) is outside the image or there is no edge.
  bool Nearest(int x, int y, int* edge_pixel_index, float* distance_px) const;

 private:
  cv::Mat distance_;
  cv::Mat labels_;
  // Label (1-based, from distanceTransform) to the row-major index of its edge pixel.
  std::vector<int32_t> label_to_pixel_;
  int num_edge_pixels_ = 0;
};

// The z-buffer keyed by edge pixel. Reuses its storage across steps.
class EdgeZBuffer {
 public:
  // For each point (projected pixel, depth in metres), keep[i] = 1 when its nearest edge pixel
  // (of the rounded pixel) lies within `radius_px` and no other point claiming the same edge
  // pixel is nearer (ties: the lower index wins); 0 otherwise. `pixels` and `depths` have the
  // same size (else InvalidArgumentError).
  void Cull(const std::vector<Eigen::Vector2d>& pixels, const std::vector<double>& depths,
            const NearestEdgeField& annf, double radius_px, std::vector<uint8_t>* keep);

 private:
  // Per edge pixel, the index of the point that owns it, or -1.
  std::vector<int32_t> owner_;
  // Per point, the edge pixel it claims, or -1.
  std::vector<int32_t> claimed_;
};

}  // namespace evloc::tracking
