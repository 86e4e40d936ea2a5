// Potential fields sampled by the registration: small values on the current edges, 1 far from
// them. Pixel centres at integer coordinates; values between pixels by bilinear interpolation.
#pragma once

#include <cmath>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace evloc::tracking {

// A scalar field on the image of the ideal pinhole camera, sampled with bilinear interpolation.
class PotentialField {
 public:
  virtual ~PotentialField() = default;

  // Field width, pixels.
  virtual int width() const = 0;
  // Field height, pixels.
  virtual int height() const = 0;

  // The bilinearly interpolated value at (u, v) and, when `gradient` is not null, its exact
  // derivative (d/du, d/dv) inside the pixel cell. Returns false (outputs untouched) when the
  // 2x2 cell around (u, v) is not inside the image. Not const: lazy fields memoise.
  virtual bool Sample(double u, double v, double* value, Eigen::Vector2d* gradient) = 0;
};

// The bilinear cell of (u, v): its top-left pixel (x0, y0) and the fractions a = u - x0,
// b = v - y0. False when (u, v) is not inside the image (outputs untouched). On the last row or
// column the cell to the left (or above) is used.
inline bool LocateCell(int width, int height, double u, double v, int* x0, int* y0, double* a,
                       double* b) {
  if (!(u >= 0 && v >= 0 && u <= width - 1 && v <= height - 1)) return false;
  int x = static_cast<int>(u);
  int y = static_cast<int>(v);
  if (x >= width - 1) x = width - 2;
  if (y >= height - 1) y = height - 2;
  if (x < 0 || y < 0) return false;
  *x0 = x;
  *y0 = y;
  *a = u - x;
  *b = v - y;
  return true;
}

// The bilinear interpolant of a cell with corner values f00 at (x0, y0), f10 at (x0 + 1, y0), f01
// at (x0, y0 + 1) and f11, at fractions (a, b), and when `gradient` is not null its exact
// derivative (d/du, d/dv).
inline void InterpolateCell(double a, double b, double f00, double f10, double f01, double f11,
                            double* value, Eigen::Vector2d* gradient) {
  *value = (1 - b) * ((1 - a) * f00 + a * f10) + b * ((1 - a) * f01 + a * f11);
  if (gradient != nullptr) {
    (*gradient)(0) = (1 - b) * (f10 - f00) + b * (f11 - f01);
    (*gradient)(1) = (1 - a) * (f01 - f00) + a * (f11 - f10);
  }
}

// Bilinear interpolation of a field given by a value function of integer pixels; the derivative
// is the exact derivative of the interpolant. `value_at(x, y)` returns float.
template <typename ValueAt>
inline bool SampleBilinear(int width, int height, double u, double v, ValueAt&& value_at,
                           double* value, Eigen::Vector2d* gradient) {
  int x0;
  int y0;
  double a;
  double b;
  if (!LocateCell(width, height, u, v, &x0, &y0, &a, &b)) return false;
  const double f00 = value_at(x0, y0);
  const double f10 = value_at(x0 + 1, y0);
  const double f01 = value_at(x0, y0 + 1);
  const double f11 = value_at(x0 + 1, y0 + 1);
  InterpolateCell(a, b, f00, f10, f01, f11, value, gradient);
  return true;
}

// A field stored as a full float image (CV_32FC1).
class DenseField final : public PotentialField {
 public:
  DenseField() = default;
  // Wraps `values` (CV_32FC1, shared, not copied). Throws InvalidArgumentError for another type
  // or an image smaller than 2x2.
  explicit DenseField(cv::Mat values);

  // The stored image.
  const cv::Mat& values() const { return values_; }
  int width() const override { return values_.cols; }
  int height() const override { return values_.rows; }
  bool Sample(double u, double v, double* value, Eigen::Vector2d* gradient) override {
    if (values_.empty()) return false;
    return SampleBilinear(
        values_.cols, values_.rows, u, v, [this](int x, int y) { return values_.ptr<float>(y)[x]; },
        value, gradient);
  }

  // Hints the values of the bilinear cell at (u, v) into the cache ahead of Sample. (u, v) must
  // lie inside the image. No effect on values.
  void Prefetch(double u, double v) const {
    const float* value = values_.ptr<float>(static_cast<int>(v)) + static_cast<int>(u);
    __builtin_prefetch(value);
    __builtin_prefetch(value + 1);
    __builtin_prefetch(value + values_.step1());
    __builtin_prefetch(value + values_.step1() + 1);
  }

 private:
  cv::Mat values_;
};

// The 5x5 binomial kernel [1 4 6 4 1] / 16 per axis (OpenCV's Gaussian for ksize 5, sigma 0),
// used both by the dense and by the lazy smoothing so that they agree.
inline constexpr float kSmoothingKernel[5] = {1.f / 16, 4.f / 16, 6.f / 16, 4.f / 16, 1.f / 16};

// Smooths a CV_32FC1 image with kSmoothingKernel per axis, replicating the border.
cv::Mat SmoothField(const cv::Mat& values);

// The Canny-VT field of a binary edge image (CV_8UC1, non-zero = edge): the Euclidean distance to
// the nearest edge pixel, truncated at `truncation_px` and divided by it (0 on edges, 1 far
// away), optionally smoothed. An image without edges gives 1 everywhere.
cv::Mat TruncatedDistanceField(const cv::Mat& edges, double truncation_px, bool smooth);

}  // namespace evloc::tracking
