#include "localizer/tracking/occlusion.h"

#include <cmath>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"

namespace evloc::tracking {

void NearestEdgeField::Build(const cv::Mat& edge_mask) {
  if (edge_mask.type() != CV_8UC1 || edge_mask.empty()) {
    throw InvalidArgumentError("NearestEdgeField needs a non-empty CV_8UC1 edge mask.");
  }
  // distanceTransform measures distances to zero pixels: zero on the edges.
  const cv::Mat not_edges = (edge_mask == 0);
  num_edge_pixels_ = edge_mask.rows * edge_mask.cols - cv::countNonZero(not_edges);
  if (num_edge_pixels_ == 0) {
    distance_.create(edge_mask.size(), CV_32F);
    labels_.release();
    return;
  }
  cv::distanceTransform(not_edges, distance_, labels_, cv::DIST_L2, cv::DIST_MASK_5,
                        cv::DIST_LABEL_PIXEL);
  // Every zero pixel of the input carries its own label; map labels back to pixels.
  label_to_pixel_.assign(static_cast<size_t>(num_edge_pixels_) + 1, -1);
  for (int y = 0; y < edge_mask.rows; ++y) {
    const uint8_t* mask_row = edge_mask.ptr<uint8_t>(y);
    const int32_t* label_row = labels_.ptr<int32_t>(y);
    for (int x = 0; x < edge_mask.cols; ++x) {
      if (mask_row[x] == 0) continue;
      const int32_t label = label_row[x];
      if (label >= 0 && label < static_cast<int32_t>(label_to_pixel_.size())) {
        label_to_pixel_[label] = y * edge_mask.cols + x;
      }
    }
  }
}

bool NearestEdgeField::Nearest(int x, int y, int* edge_pixel_index, float* distance_px) const {
  if (num_edge_pixels_ == 0 || x < 0 || y < 0 || x >= distance_.cols || y >= distance_.rows) {
    return false;
  }
  const int32_t label = labels_.ptr<int32_t>(y)[x];
  if (label < 0 || label >= static_cast<int32_t>(label_to_pixel_.size())) return false;
  const int32_t index = label_to_pixel_[label];
  if (index < 0) return false;
  *edge_pixel_index = index;
  *distance_px = distance_.ptr<float>(y)[x];
  return true;
}

void EdgeZBuffer::Cull(const std::vector<Eigen::Vector2d>& pixels,
                       const std::vector<double>& depths, const NearestEdgeField& annf,
                       double radius_px, std::vector<uint8_t>* keep) {
  if (pixels.size() != depths.size()) {
    throw InvalidArgumentError("EdgeZBuffer::Cull: pixels and depths differ in size.");
  }
  const size_t num_pixels = static_cast<size_t>(annf.width()) * annf.height();
  if (owner_.size() != num_pixels) owner_.assign(num_pixels, -1);
  keep->assign(pixels.size(), 0);
  claimed_.assign(pixels.size(), -1);
  for (size_t i = 0; i < pixels.size(); ++i) {
    const int x = static_cast<int>(std::lround(pixels[i].x()));
    const int y = static_cast<int>(std::lround(pixels[i].y()));
    int edge_pixel;
    float distance;
    if (!std::isfinite(pixels[i].x()) || !std::isfinite(pixels[i].y()) ||
        !annf.Nearest(x, y, &edge_pixel, &distance) || distance > radius_px) {
      continue;
    }
    claimed_[i] = edge_pixel;
    int32_t& owner = owner_[edge_pixel];
    // The comparison the reference implementation never made: the nearer point wins.
    if (owner < 0 || depths[i] < depths[owner]) owner = static_cast<int32_t>(i);
  }
  for (size_t i = 0; i < pixels.size(); ++i) {
    if (claimed_[i] >= 0 && owner_[claimed_[i]] == static_cast<int32_t>(i)) (*keep)[i] = 1;
  }
  // Reset only the entries this call touched.
  for (const int32_t edge_pixel : claimed_) {
    if (edge_pixel >= 0) owner_[edge_pixel] = -1;
  }
}

}  // namespace evloc::tracking
