// Canny edges split by gradient orientation and their distance and nearest-edge fields (Canny-VO,
// Zhou, Li and Kneip 2018; docs/tracking.md, "Mapless odometry"): every edge pixel falls into
// one of N orientation bins of its image gradient (over 360 degrees, so the two sides of a thin
// line never attract each other's points); the field of bin b holds, for every pixel, the
// distance to and the index of the nearest edge whose bin is b or one of its two neighbours.
// A model point registers only against edges of an orientation near its predicted one.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/camera/undistortion_table.h"

namespace evloc::odometry {

// Options of edge detection and the oriented fields.
struct OrientedEdgeOptions {
  // Canny's lower hysteresis threshold on the 8-bit image (Sobel 3x3, L1 gradient).
  double canny_low_threshold = 50.0;
  // Canny's upper hysteresis threshold.
  double canny_high_threshold = 150.0;
  // Number of orientation bins over 360 degrees (>= 4).
  int orientation_bins = 8;
  // Pixels farther than this from every edge of a field have no nearest edge there, pixels.
  double max_distance_px = 20.0;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// One Canny edge pixel.
struct EdgePixel {
  // The sensor pixel it was detected at.
  Eigen::Vector2i sensor_pixel = Eigen::Vector2i::Zero();
  // The edge's sub-pixel position on the sensor: the peak of a parabola through the gradient
  // magnitudes of the pixel and its two neighbours along the gradient's dominant axis.
  Eigen::Vector2d sensor_subpixel = Eigen::Vector2d::Zero();
  // The sub-pixel position in the ideal pinhole camera of the undistortion table.
  Eigen::Vector2d ideal_pixel = Eigen::Vector2d::Zero();
  // Unit image gradient (direction of increasing intensity), sensor image.
  Eigen::Vector2d gradient_direction = Eigen::Vector2d::UnitX();
  // Its orientation bin.
  int bin = 0;
};

// The orientation bin of a direction (not necessarily unit): bin k covers the angles
// [k, k + 1) * 360 / bins degrees, angle 0 along +x, 90 along +y (image down).
int OrientationBin(const Eigen::Vector2d& direction, int bins);

// The Canny edges of an 8-bit grey image of table's camera, with Sobel gradients, their
// orientation bins and ideal pixels (pixels whose undistortion fails, or whose ideal pixel falls
// outside the image, are dropped). Throws InvalidArgumentError when the image is not CV_8UC1 of
// the table's size or the options are bad.
std::vector<EdgePixel> DetectOrientedEdges(const cv::Mat& gray, const UndistortionTable& table,
                                           const OrientedEdgeOptions& options);

// The distance and nearest-edge fields of every orientation bin, on the ideal image.
class OrientedEdgeFields {
 public:
  // Builds one field per bin from `edges` (ideal pixels rounded; the first edge wins a pixel two
  // edges round to) on a width x height image. Throws InvalidArgumentError for bad options or
  // sizes.
  OrientedEdgeFields(std::vector<EdgePixel> edges, int width, int height,
                     const OrientedEdgeOptions& options);

  // The edges the fields were built from.
  const std::vector<EdgePixel>& edges() const { return edges_; }
  // Number of bins.
  int bins() const { return static_cast<int>(distances_.size()); }
  // Image width, pixels.
  int width() const { return width_; }
  // Image height, pixels.
  int height() const { return height_; }
  // The distance field of `bin` (CV_32FC1, pixels; approximate Euclidean, 5x5 mask).
  const cv::Mat& distance(int bin) const { return distances_[bin]; }
  // Index into edges() of the edge nearest to pixel (x, y) in `bin`'s field, or -1 when (x, y)
  // is outside the image or no edge lies within max_distance_px.
  int NearestEdge(int bin, int x, int y) const;

 private:
  std::vector<EdgePixel> edges_;
  int width_ = 0;
  int height_ = 0;
  double max_distance_px_ = 0;
  std::vector<cv::Mat> distances_;
  // Per bin, per pixel (row-major): the index into edges_ of the nearest edge, -1 for none.
  std::vector<std::vector<int32_t>> nearest_;
};

}  // namespace evloc::odometry
