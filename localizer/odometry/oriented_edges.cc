#include "localizer/odometry/oriented_edges.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"

namespace evloc::odometry {
namespace {

// The Sobel gradient magnitude (L2) at (x, y).
double Magnitude(const cv::Mat& gradient_x, const cv::Mat& gradient_y, int x, int y) {
  return std::hypot(static_cast<double>(gradient_x.at<int16_t>(y, x)),
                    static_cast<double>(gradient_y.at<int16_t>(y, x)));
}

}  // namespace

void OrientedEdgeOptions::Check() const {
  if (!(canny_low_threshold >= 0) || !(canny_high_threshold >= canny_low_threshold)) {
    throw InvalidArgumentError("OrientedEdgeOptions: Canny thresholds need 0 <= low <= high");
  }
  if (orientation_bins < 4 || orientation_bins > 64) {
    throw InvalidArgumentError("OrientedEdgeOptions: orientation_bins must be in 4..64, got " +
                               std::to_string(orientation_bins));
  }
  if (!(max_distance_px > 0) || !std::isfinite(max_distance_px)) {
    throw InvalidArgumentError("OrientedEdgeOptions: max_distance_px must be positive");
  }
}

int OrientationBin(const Eigen::Vector2d& direction, int bins) {
  double angle = std::atan2(direction.y(), direction.x());
  if (angle < 0) angle += 2 * M_PI;
  int bin = static_cast<int>(angle / (2 * M_PI) * bins);
  if (bin >= bins) bin = bins - 1;
  if (bin < 0) bin = 0;
  return bin;
}

std::vector<EdgePixel> DetectOrientedEdges(const cv::Mat& gray, const UndistortionTable& table,
                                           const OrientedEdgeOptions& options) {
  options.Check();
  if (gray.type() != CV_8UC1 || gray.cols != table.width() || gray.rows != table.height()) {
    throw InvalidArgumentError(
        "DetectOrientedEdges: expected an 8-bit grey image of " + std::to_string(table.width()) +
        "x" + std::to_string(table.height()) + ", got " + std::to_string(gray.cols) + "x" +
        std::to_string(gray.rows) + " of type " + std::to_string(gray.type()));
  }
  cv::Mat gradient_x;
  cv::Mat gradient_y;
  cv::Sobel(gray, gradient_x, CV_16S, 1, 0, 3);
  cv::Sobel(gray, gradient_y, CV_16S, 0, 1, 3);
  cv::Mat edges;
  cv::Canny(gradient_x, gradient_y, edges, options.canny_low_threshold,
            options.canny_high_threshold);
  const int width = table.width();
  const int height = table.height();
  std::vector<EdgePixel> result;
  for (int y = 0; y < height; ++y) {
    const uint8_t* edge_row = edges.ptr<uint8_t>(y);
    const int16_t* gx_row = gradient_x.ptr<int16_t>(y);
    const int16_t* gy_row = gradient_y.ptr<int16_t>(y);
    for (int x = 0; x < width; ++x) {
      if (edge_row[x] == 0) continue;
      const Eigen::Vector2d gradient(gx_row[x], gy_row[x]);
      const double norm = gradient.norm();
      if (!(norm > 0)) continue;
      const UndistortionTable::Entry* entry = table.Find(x, y);
      if (entry == nullptr) continue;
      // Sub-pixel refinement across the edge, along the gradient's dominant axis.
      const bool along_x = std::abs(gradient.x()) >= std::abs(gradient.y());
      const int step_x = along_x ? 1 : 0;
      const int step_y = along_x ? 0 : 1;
      double offset = 0;
      if (x - step_x >= 0 && y - step_y >= 0 && x + step_x < width && y + step_y < height) {
        const double before = Magnitude(gradient_x, gradient_y, x - step_x, y - step_y);
        const double after = Magnitude(gradient_x, gradient_y, x + step_x, y + step_y);
        const double curvature = before - 2 * norm + after;
        if (curvature < 0) offset = std::clamp(0.5 * (before - after) / curvature, -0.5, 0.5);
      }
      const Eigen::Vector2d shift(step_x * offset, step_y * offset);
      const Eigen::Vector2d ideal = entry->ideal_pixel.cast<double>() + shift;
      if (!(ideal.x() >= 0 && ideal.y() >= 0 && ideal.x() <= width - 1 &&
            ideal.y() <= height - 1)) {
        continue;
      }
      EdgePixel pixel;
      pixel.sensor_pixel = Eigen::Vector2i(x, y);
      pixel.sensor_subpixel = Eigen::Vector2d(x, y) + shift;
      pixel.ideal_pixel = ideal;
      pixel.gradient_direction = gradient / norm;
      pixel.bin = OrientationBin(gradient, options.orientation_bins);
      result.push_back(pixel);
    }
  }
  return result;
}

OrientedEdgeFields::OrientedEdgeFields(std::vector<EdgePixel> edges, int width, int height,
                                       const OrientedEdgeOptions& options)
    : edges_(std::move(edges)),
      width_(width),
      height_(height),
      max_distance_px_(options.max_distance_px) {
  options.Check();
  if (width < 2 || height < 2) {
    throw InvalidArgumentError("OrientedEdgeFields: the image must be at least 2x2");
  }
  const int bins = options.orientation_bins;
  const size_t pixels = static_cast<size_t>(width) * height;
  distances_.resize(bins);
  nearest_.assign(bins, std::vector<int32_t>());
  // The edge claiming each pixel per own bin (first one wins).
  std::vector<std::vector<int32_t>> owner(bins, std::vector<int32_t>());
  for (int bin = 0; bin < bins; ++bin) owner[bin].assign(pixels, -1);
  for (size_t i = 0; i < edges_.size(); ++i) {
    const EdgePixel& edge = edges_[i];
    if (edge.bin < 0 || edge.bin >= bins) {
      throw InvalidArgumentError("OrientedEdgeFields: edge bin " + std::to_string(edge.bin) +
                                 " outside 0.." + std::to_string(bins - 1));
    }
    const int x = static_cast<int>(std::lround(edge.ideal_pixel.x()));
    const int y = static_cast<int>(std::lround(edge.ideal_pixel.y()));
    if (x < 0 || y < 0 || x >= width || y >= height) continue;
    int32_t& slot = owner[edge.bin][static_cast<size_t>(y) * width + x];
    if (slot < 0) slot = static_cast<int32_t>(i);
  }
  cv::Mat sources(height, width, CV_8UC1);
  cv::Mat labels;
  std::vector<int32_t> edge_of_label;
  for (int bin = 0; bin < bins; ++bin) {
    // Edges of this bin and its two neighbours (a bin's field spans 3 * 360 / bins degrees).
    const int neighbours[3] = {(bin + bins - 1) % bins, bin, (bin + 1) % bins};
    sources.setTo(255);
    std::vector<int32_t> source_edge(pixels, -1);
    for (const int other : neighbours) {
      const std::vector<int32_t>& claims = owner[other];
      for (size_t p = 0; p < pixels; ++p) {
        if (claims[p] >= 0 && (source_edge[p] < 0 || other == bin)) source_edge[p] = claims[p];
      }
    }
    bool any = false;
    for (size_t p = 0; p < pixels; ++p) {
      if (source_edge[p] >= 0) {
        sources.data[p] = 0;
        any = true;
      }
    }
    std::vector<int32_t>& nearest = nearest_[bin];
    nearest.assign(pixels, -1);
    if (!any) {
      distances_[bin] = cv::Mat(height, width, CV_32FC1, cv::Scalar(max_distance_px_ + 1));
      continue;
    }
    cv::distanceTransform(sources, distances_[bin], labels, cv::DIST_L2, cv::DIST_MASK_5,
                          cv::DIST_LABEL_PIXEL);
    // Labels number the zero pixels 1..n in row-major order.
    edge_of_label.assign(1, -1);
    for (size_t p = 0; p < pixels; ++p) {
      if (source_edge[p] >= 0) edge_of_label.push_back(source_edge[p]);
    }
    for (int y = 0; y < height; ++y) {
      const int32_t* label_row = labels.ptr<int32_t>(y);
      const float* distance_row = distances_[bin].ptr<float>(y);
      for (int x = 0; x < width; ++x) {
        const int32_t label = label_row[x];
        if (distance_row[x] > max_distance_px_ || label <= 0 ||
            label >= static_cast<int32_t>(edge_of_label.size())) {
          continue;
        }
        nearest[static_cast<size_t>(y) * width + x] = edge_of_label[label];
      }
    }
  }
}

int OrientedEdgeFields::NearestEdge(int bin, int x, int y) const {
  if (bin < 0 || bin >= bins() || x < 0 || y < 0 || x >= width_ || y >= height_) return -1;
  return nearest_[bin][static_cast<size_t>(y) * width_ + x];
}

}  // namespace evloc::odometry
