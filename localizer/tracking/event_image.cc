#include "localizer/tracking/event_image.h"

#include <algorithm>
#include <cmath>

#include "core/common/error.h"

namespace evloc::tracking {
EventImage::EventImage(int width, int height, double tau_s)
    : width_(width), height_(height), tau_ns_(tau_s * 1e9) {
  if (width <= 0 || height <= 0 || !(tau_s > 0) || !std::isfinite(tau_s)) {
    throw InvalidArgumentError("EventImage: the size must be positive and tau positive, got " +
                               std::to_string(width) + "x" + std::to_string(height) + ", tau " +
                               std::to_string(tau_s) + " s.");
  }
  Clear();
}

void EventImage::Clear() {
  const size_t pixels = static_cast<size_t>(width_) * height_;
  value_.assign(pixels, 0.0f);
  any_ = false;
  first_t_ns_ = 0;
  last_t_ns_ = 0;
  anchor_t_ns_ = 0;
}

void EventImage::Reanchor(int64_t t_ns) {
  const float factor =
      static_cast<float>(std::exp(-static_cast<double>(t_ns - anchor_t_ns_) / tau_ns_));
  for (float& value : value_) value *= factor;
  anchor_t_ns_ = t_ns;
}

void EventImage::Insert(const EventBuffer& events, size_t begin, size_t end) {
  if (begin >= end) return;
  if (!any_) {
    any_ = true;
    first_t_ns_ = events.t_ns[begin];
    anchor_t_ns_ = first_t_ns_;
  }
  const double inverse_tau = 1.0 / tau_ns_;
  // Weights up to exp(kAnchorSpan) before the values are brought to a later anchor: e^20, far
  // from a float's range, once every 20 time constants (1 s at 50 ms).
  constexpr double kAnchorSpan = 20.0;
  int64_t weight_t_ns = events.t_ns[begin] - 1;
  float weight = 0;
  for (size_t i = begin; i < end; ++i) {
    if (events.x[i] >= width_ || events.y[i] >= height_) continue;
    const int64_t t = events.t_ns[i];
    if (t != weight_t_ns) {
      if (static_cast<double>(t - anchor_t_ns_) * inverse_tau > kAnchorSpan) Reanchor(t);
      // Events come in runs of one timestamp at high rates: one exp per run.
      weight = static_cast<float>(std::exp(static_cast<double>(t - anchor_t_ns_) * inverse_tau));
      weight_t_ns = t;
    }
    value_[static_cast<size_t>(events.y[i]) * width_ + events.x[i]] +=
        weight * static_cast<float>(events.polarity[i]);
  }
  last_t_ns_ = events.t_ns[end - 1];
}

float EventImage::Decayed(size_t pixel, int64_t t_ns) const {
  return value_[pixel] *
         static_cast<float>(std::exp(-static_cast<double>(t_ns - anchor_t_ns_) / tau_ns_));
}

double EventImage::Value(int x, int y, int64_t t_ns) const {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return 0.0;
  return Decayed(static_cast<size_t>(y) * width_ + x, t_ns);
}

cv::Mat EventImage::Render(int64_t t_ns) const {
  cv::Mat image(height_, width_, CV_8UC1, cv::Scalar(128));
  if (!any_) return image;
  const size_t pixels = value_.size();
  std::vector<float> decayed(pixels);
  const float factor =
      static_cast<float>(std::exp(-static_cast<double>(t_ns - anchor_t_ns_) / tau_ns_));
  for (size_t i = 0; i < pixels; ++i) decayed[i] = value_[i] * factor;
  // The percentiles are over every pixel (those that never fired are at the integrator's rest
  // value, 0), as measured in docs/relocalization.md.
  std::vector<float> seen = decayed;
  const auto quantile = [&seen](double q) {
    const size_t k =
        std::min(seen.size() - 1, static_cast<size_t>(q * static_cast<double>(seen.size())));
    std::nth_element(seen.begin(), seen.begin() + static_cast<std::ptrdiff_t>(k), seen.end());
    return seen[k];
  };
  const float low = quantile(0.01);
  const float high = quantile(0.99);
  const float scale = high > low ? 255.0f / (high - low) : 0.0f;
  for (int y = 0; y < height_; ++y) {
    uint8_t* row = image.ptr<uint8_t>(y);
    for (int x = 0; x < width_; ++x) {
      const size_t i = static_cast<size_t>(y) * width_ + x;
      const float v = scale > 0 ? (decayed[i] - low) * scale : 128.0f;
      row[x] = static_cast<uint8_t>(std::clamp(v, 0.0f, 255.0f) + 0.5f);
    }
  }
  return image;
}

}  // namespace evloc::tracking
