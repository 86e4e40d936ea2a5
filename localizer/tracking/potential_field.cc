#include "localizer/tracking/potential_field.h"

#include <opencv2/imgproc.hpp>
#include <utility>

#include "core/common/error.h"

namespace evloc::tracking {

DenseField::DenseField(cv::Mat values) : values_(std::move(values)) {
  if (values_.type() != CV_32FC1 || values_.cols < 2 || values_.rows < 2) {
    throw InvalidArgumentError("DenseField needs a CV_32FC1 image of at least 2x2 pixels.");
  }
}

cv::Mat SmoothField(const cv::Mat& values) {
  const cv::Mat kernel(1, 5, CV_32F, const_cast<float*>(kSmoothingKernel));
  cv::Mat smoothed;
  cv::sepFilter2D(values, smoothed, CV_32F, kernel, kernel, cv::Point(-1, -1), 0,
                  cv::BORDER_REPLICATE);
  return smoothed;
}

cv::Mat TruncatedDistanceField(const cv::Mat& edges, double truncation_px, bool smooth) {
  if (edges.type() != CV_8UC1 || edges.empty()) {
    throw InvalidArgumentError("TruncatedDistanceField needs a non-empty CV_8UC1 edge image.");
  }
  if (!(truncation_px > 0)) {
    throw InvalidArgumentError("TruncatedDistanceField needs a positive truncation.");
  }
  cv::Mat field(edges.size(), CV_32F, cv::Scalar(1.0f));
  if (cv::countNonZero(edges) > 0) {
    // distanceTransform measures the distance to the nearest zero pixel: zero on the edges.
    cv::Mat not_edges = (edges == 0);
    cv::Mat distance;
    cv::distanceTransform(not_edges, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
    cv::min(distance, truncation_px, distance);
    field = distance * (1.0 / truncation_px);
  }
  return smooth ? SmoothField(field) : field;
}

}  // namespace evloc::tracking
