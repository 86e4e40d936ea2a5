#include "localizer/tracking/oriented_chamfer.h"

#include <cmath>
#include <numbers>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"

namespace evloc::tracking {
namespace {

// The bin of an orientation angle (radians, any value; modulo pi), bins centred on k * pi / bins.
int AngleBin(double angle, int bins) {
  double wrapped = std::fmod(angle, std::numbers::pi);
  if (wrapped < 0) wrapped += std::numbers::pi;
  const int bin = static_cast<int>(std::floor(wrapped * bins / std::numbers::pi + 0.5));
  return bin % bins;
}

}  // namespace

void OrientedChamferOptions::Check() const {
  if (bins < 2 || bins > 64) {
    throw InvalidArgumentError("OrientedChamferOptions: bins must be in [2, 64].");
  }
  if (tolerance_bins < 0 || 2 * tolerance_bins + 1 > bins) {
    throw InvalidArgumentError(
        "OrientedChamferOptions: tolerance_bins must be >= 0 and 2 * tolerance_bins + 1 <= bins.");
  }
  if (!std::isfinite(tensor_sigma_px) || tensor_sigma_px <= 0 || tensor_sigma_px > 20) {
    throw InvalidArgumentError("OrientedChamferOptions: tensor_sigma_px must be in (0, 20].");
  }
  if (!std::isfinite(min_coherence) || min_coherence < 0 || min_coherence >= 1) {
    throw InvalidArgumentError("OrientedChamferOptions: min_coherence must be in [0, 1).");
  }
  if (!std::isfinite(truncation_px) || truncation_px <= 0 || truncation_px > 1000) {
    throw InvalidArgumentError("OrientedChamferOptions: truncation_px must be in (0, 1000].");
  }
  if (mean_window_px < 0 || mean_window_px > 1000) {
    throw InvalidArgumentError("OrientedChamferOptions: mean_window_px must be in [0, 1000].");
  }
}

void OrientedChamferField::Build(const cv::Mat& edges, const OrientedChamferOptions& options) {
  options.Check();
  if (edges.empty() || edges.type() != CV_8UC1) {
    throw InvalidArgumentError("OrientedChamferField::Build: the edge image must be CV_8UC1.");
  }
  const int width = edges.cols;
  const int height = edges.rows;
  // Structure tensor of the smoothed edge image.
  cv::Mat image;
  edges.convertTo(image, CV_32F, 1.0 / 255.0);
  cv::threshold(image, image, 0, 1, cv::THRESH_BINARY);
  cv::GaussianBlur(image, image, cv::Size(0, 0), 1.0);
  cv::Mat gx;
  cv::Mat gy;
  cv::Sobel(image, gx, CV_32F, 1, 0, 3);
  cv::Sobel(image, gy, CV_32F, 0, 1, 3);
  cv::Mat jxx = gx.mul(gx);
  cv::Mat jxy = gx.mul(gy);
  cv::Mat jyy = gy.mul(gy);
  const cv::Size kernel(0, 0);
  cv::GaussianBlur(jxx, jxx, kernel, options.tensor_sigma_px);
  cv::GaussianBlur(jxy, jxy, kernel, options.tensor_sigma_px);
  cv::GaussianBlur(jyy, jyy, kernel, options.tensor_sigma_px);

  const int bins = options.bins;
  std::vector<cv::Mat> masks(bins);
  for (cv::Mat& mask : masks) mask = cv::Mat(height, width, CV_8UC1, cv::Scalar(255));
  oriented_pixels_ = 0;
  for (int y = 0; y < height; ++y) {
    const uint8_t* edge_row = edges.ptr<uint8_t>(y);
    const float* xx = jxx.ptr<float>(y);
    const float* xy = jxy.ptr<float>(y);
    const float* yy = jyy.ptr<float>(y);
    for (int x = 0; x < width; ++x) {
      if (edge_row[x] == 0) continue;
      const double trace = static_cast<double>(xx[x]) + yy[x];
      if (trace <= 1e-12) continue;
      const double difference = static_cast<double>(xx[x]) - yy[x];
      const double twice_cross = 2.0 * xy[x];
      const double coherence = std::hypot(difference, twice_cross) / trace;
      if (coherence < options.min_coherence) continue;
      ++oriented_pixels_;
      // The dominant eigenvector's angle: the edge normal.
      const int bin = AngleBin(0.5 * std::atan2(twice_cross, difference), bins);
      for (int k = -options.tolerance_bins; k <= options.tolerance_bins; ++k) {
        masks[(bin + k + bins) % bins].ptr<uint8_t>(y)[x] = 0;
      }
    }
  }
  distances_.assign(bins, cv::Mat());
  const float truncation = static_cast<float>(options.truncation_px);
  for (int b = 0; b < bins; ++b) {
    if (cv::countNonZero(masks[b]) == width * height) {
      distances_[b] = cv::Mat(height, width, CV_32FC1, cv::Scalar(truncation));
      continue;
    }
    cv::distanceTransform(masks[b], distances_[b], cv::DIST_L2, cv::DIST_MASK_5);
    cv::min(distances_[b], truncation, distances_[b]);
  }
  means_.clear();
  if (options.mean_window_px > 0) {
    means_.assign(bins, cv::Mat());
    const cv::Size window(options.mean_window_px, options.mean_window_px);
    for (int b = 0; b < bins; ++b) {
      cv::blur(distances_[b], means_[b], window, cv::Point(-1, -1), cv::BORDER_REFLECT);
    }
  }
}

int OrientedChamferField::Bin(double dx, double dy) const {
  return AngleBin(std::atan2(dy, dx), bins());
}

}  // namespace evloc::tracking
