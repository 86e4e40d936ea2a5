// Oriented (directional) chamfer field of an edge image, for the global search's pre-score
// (docs/relocalization.md, "Events"): the distance from a pixel to the nearest edge pixel whose
// edge normal has about a given orientation. On a dense, textured event image every pixel is near
// some edge, so the plain chamfer distance ranks almost any pose well; near an edge of the
// *right orientation* it does not.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

namespace evloc::tracking {

// Options of OrientedChamferField::Build.
struct OrientedChamferOptions {
  // Orientation bins over 180 degrees (an edge normal and its opposite are one orientation).
  int bins = 8;
  // An edge pixel counts in its own bin and in this many bins on either side (the tolerance of
  // the orientation estimates, of the image's and of the projected map gradient's).
  int tolerance_bins = 1;
  // Standard deviation of the Gaussian that integrates the structure tensor, pixels.
  double tensor_sigma_px = 1.5;
  // Edge pixels whose structure tensor has a lower coherence ((l1 - l2) / (l1 + l2), 0 for a
  // blob or a corner, 1 for a straight edge) have no orientation and count in no bin.
  double min_coherence = 0.3;
  // Distances are truncated at this many pixels.
  double truncation_px = 24.0;
  // When > 0, also the local mean of each bin's truncated distance over a square window of this
  // side (pixels): what a point placed at random near that pixel scores (MeanDistance).
  int mean_window_px = 0;

  // Throws InvalidArgumentError naming the first field out of range.
  void Check() const;
};

// Per orientation bin, the truncated distance transform of the edge pixels of that orientation.
class OrientedChamferField {
 public:
  // Builds the field of `edges` (CV_8UC1, non-zero = edge pixel). The orientation of an edge
  // pixel is that of the dominant eigenvector of the structure tensor of the Gaussian-smoothed
  // edge image (the edge normal; on either side of a thin line both gradients give it). Throws
  // InvalidArgumentError for an empty image, another type, or invalid options.
  void Build(const cv::Mat& edges, const OrientedChamferOptions& options);

  // True once built.
  bool empty() const { return distances_.empty(); }
  // Number of orientation bins.
  int bins() const { return static_cast<int>(distances_.size()); }
  // The bin of an edge normal (dx, dy) in pixels (any length but zero, either sign).
  int Bin(double dx, double dy) const;
  // Truncated distance in pixels from pixel (x, y) (inside the image) to the nearest edge pixel
  // of orientation bin `bin` (or a neighbour within the tolerance).
  float Distance(int x, int y, int bin) const { return distances_[bin].ptr<float>(y)[x]; }
  // The local mean of Distance(., ., bin) around (x, y) (built with mean_window_px > 0).
  float MeanDistance(int x, int y, int bin) const { return means_[bin].ptr<float>(y)[x]; }
  // The truncated distance image of a bin (CV_32FC1), and its local mean (mean_window_px > 0).
  const cv::Mat& distances(int bin) const { return distances_[bin]; }
  const cv::Mat& means(int bin) const { return means_[bin]; }
  // Edge pixels that got an orientation (coherent enough), for inspection and tests.
  int oriented_pixels() const { return oriented_pixels_; }

 private:
  std::vector<cv::Mat> distances_;
  std::vector<cv::Mat> means_;
  int oriented_pixels_ = 0;
};

}  // namespace evloc::tracking
