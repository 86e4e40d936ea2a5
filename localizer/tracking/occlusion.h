// Occlusion culling with an approximate nearest-neighbour field (ANNF, docs/tracking.md, "Occlusion
// culling"): each projected map point looks for its nearest active edge pixel within a radius in
// its own window; map points claiming the same edge pixel are resolved by a z-buffer keyed by that
// edge pixel (the nearest point wins), and points with no edge pixel within the radius drop out.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "localizer/tracking/time_surface.h"

namespace evloc::tracking {

// The nearest edge pixel of any pixel, searched on demand in a window around it (O(r^2) per query
// at worst, O(1) for a pixel on an edge) instead of a whole-image distance transform per step.
// Distances are exact Euclidean distances between integer pixels; among edge pixels at the same
// distance the one with the lowest row-major index wins. Not thread-safe (the search order is
// cached per radius).
class NearestEdgeField {
 public:
  // Uses the non-zero pixels of `edge_mask` (CV_8UC1, shared, not copied) as edges. Throws
  // InvalidArgumentError for another type or an empty image.
  void Build(const cv::Mat& edge_mask);
  // Uses the pixels of `channel` of `surface` active at `t_ns` (T > delta, as the field's empty
  // test) as edges; reads the surface live, so `surface` must outlive the queries.
  void Build(const TimeSurface& surface, SurfaceChannel channel, int64_t t_ns,
             const SurfaceDecay& decay);

  // Image width, pixels.
  int width() const { return width_; }
  // Image height, pixels.
  int height() const { return height_; }

  // True when pixel (x, y) is an edge pixel. Unchecked.
  bool IsEdge(int x, int y) const {
    const size_t index = static_cast<size_t>(y) * width_ + x;
    return mask_ != nullptr ? mask_[index] != 0 : last_t_ns_[index] >= min_active_t_ns_;
  }

  // The nearest edge pixel of pixel (x, y) within `radius_px`, as the row-major index
  // y * width + x, and its distance in pixels. False when (x, y) is outside the image or no edge
  // pixel lies within the radius.
  bool Nearest(int x, int y, double radius_px, int* edge_pixel_index, float* distance_px) const;
  // Nearest for the pixel nearest to `pixel` (rounded half away from zero, as std::lround);
  // false for non-finite or far-off coordinates too.
  bool Nearest(const Eigen::Vector2d& pixel, double radius_px, int* edge_pixel_index,
               float* distance_px) const {
    int x;
    int y;
    return RoundToPixel(pixel, &x, &y) && Nearest(x, y, radius_px, edge_pixel_index, distance_px);
  }

  // Rounds `pixel` half away from zero (as std::lround, without its library call); false when a
  // coordinate is not finite or beyond 1e8 in magnitude (outputs untouched).
  static bool RoundToPixel(const Eigen::Vector2d& pixel, int* x, int* y) {
    if (!(std::abs(pixel.x()) <= 1e8 && std::abs(pixel.y()) <= 1e8)) return false;
    *x = RoundHalfAwayFromZero(pixel.x());
    *y = RoundHalfAwayFromZero(pixel.y());
    return true;
  }

 private:
  struct Offset {
    int dx;
    int dy;
    float distance;
  };
  // The window of one radius: offsets by increasing distance then row-major order, and the same
  // offsets as row-major index differences for the image width they were made for.
  struct Window {
    double radius_px = -1;
    int width = 0;
    std::vector<Offset> offsets;
    std::vector<std::ptrdiff_t> index_offsets;
  };
  const Window& WindowFor(double radius_px) const {
    if (last_window_ < windows_.size()) {
      const Window& last = windows_[last_window_];
      if (last.radius_px == radius_px && last.width == width_) return last;
    }
    return FindOrMakeWindow(radius_px);
  }
  const Window& FindOrMakeWindow(double radius_px) const;
  // |value| <= 1e8: the exact difference value - trunc(value) decides, as std::lround.
  static int RoundHalfAwayFromZero(double value) {
    const int truncated = static_cast<int>(value);
    const double fraction = value - truncated;
    return truncated + (fraction >= 0.5 ? 1 : 0) - (fraction <= -0.5 ? 1 : 0);
  }
  // The first edge pixel among `window` around row-major index `centre` (the window lies inside
  // the image), or -1, with its position in the window.
  template <typename IsEdgeAt>
  static int FirstEdge(const Window& window, size_t centre, IsEdgeAt&& is_edge, size_t* position);

  int width_ = 0;
  int height_ = 0;
  // Either a mask (non-zero = edge) ...
  cv::Mat mask_image_;
  const uint8_t* mask_ = nullptr;
  // ... or per-pixel last time stamps with the earliest time stamp that is still active.
  const int64_t* last_t_ns_ = nullptr;
  int64_t min_active_t_ns_ = 0;
  // Per radius asked for, its window (a tracker asks for two radii: occlusion and on-edge); the
  // last one used is tried first.
  mutable std::vector<Window> windows_;
  mutable size_t last_window_ = 0;
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
