#include "localizer/tracking/time_surface.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/common/error.h"

namespace evloc::tracking {

double SurfaceDecay::Value(int64_t last_t_ns, int64_t t_ns) const {
  if (last_t_ns == kNeverFired) return 0.0;
  const int64_t age_ns = std::max<int64_t>(0, t_ns - last_t_ns);
  if (age_ns > MaxActiveAgeNs()) return 0.0;
  const double value = std::exp(-static_cast<double>(age_ns) / decay_time_ns);
  return value > empty_threshold ? value : 0.0;
}

int64_t SurfaceDecay::MaxActiveAgeNs() const {
  // T > delta  <=>  age < tau * ln(1 / delta); one nanosecond of slack for rounding.
  return static_cast<int64_t>(std::ceil(decay_time_ns * std::log(1.0 / empty_threshold))) + 1;
}

int64_t SurfaceDecay::MaxActiveAgeExactNs() const {
  // Start from the analytic bound and settle the rounding with Value itself, so that the two
  // agree exactly. Age 0 is always active (empty_threshold < 1).
  auto active = [this](int64_t age_ns) {
    return std::exp(-static_cast<double>(age_ns) / decay_time_ns) > empty_threshold;
  };
  int64_t age_ns = std::min<int64_t>(
      MaxActiveAgeNs(),
      static_cast<int64_t>(std::floor(decay_time_ns * std::log(1.0 / empty_threshold))));
  age_ns = std::max<int64_t>(age_ns, 0);
  while (age_ns > 0 && !active(age_ns)) --age_ns;
  while (age_ns + 1 <= MaxActiveAgeNs() && active(age_ns + 1)) ++age_ns;
  return age_ns;
}

TimeSurface::TimeSurface(const UndistortionTable& table) {
  StartLookup(table.camera(), table.ideal_camera());
  for (int y = 0; y < sensor_height_; ++y) {
    for (int x = 0; x < sensor_width_; ++x) {
      const UndistortionTable::Entry* entry = table.Find(x, y);
      if (entry != nullptr) SetIdealPixel(x, y, entry->ideal_pixel);
    }
  }
  FillHoles(table.camera(), table.ideal_camera());
  Clear();
}

TimeSurface::TimeSurface(const Camera& camera, int binning) {
  camera.Check();
  const Camera ideal = UndistortionTable::BinnedIdealCamera(camera, binning);
  StartLookup(camera, ideal);
  UndistortionTable::ForEachPixel(
      camera, ideal,
      [this](int x, int y, const Eigen::Vector2f&, const Eigen::Vector2f& ideal_pixel) {
        SetIdealPixel(x, y, ideal_pixel);
      });
  FillHoles(camera, ideal);
  Clear();
}

void TimeSurface::StartLookup(const Camera& sensor, const Camera& ideal) {
  width_ = ideal.width;
  height_ = ideal.height;
  sensor_width_ = sensor.width;
  sensor_height_ = sensor.height;
  sensor_to_pixel_.assign(static_cast<size_t>(sensor_width_) * sensor_height_, -1);
}

void TimeSurface::SetIdealPixel(int x, int y, const Eigen::Vector2f& ideal_pixel) {
  const int ideal_x = static_cast<int>(std::lround(ideal_pixel.x()));
  const int ideal_y = static_cast<int>(std::lround(ideal_pixel.y()));
  if (ideal_x < 0 || ideal_y < 0 || ideal_x >= width_ || ideal_y >= height_) return;
  sensor_to_pixel_[static_cast<size_t>(y) * sensor_width_ + x] = ideal_y * width_ + ideal_x;
}

void TimeSurface::FillHoles(const Camera& sensor, const Camera& ideal) {
  const size_t num_sensor = static_cast<size_t>(sensor_width_) * sensor_height_;
  std::vector<uint8_t> mapped(static_cast<size_t>(width_) * height_, 0);
  for (const int32_t pixel : sensor_to_pixel_) {
    if (pixel >= 0) mapped[pixel] = 1;
  }
  // (sensor pixel, hole) pairs, in hole order; then grouped by sensor pixel.
  std::vector<std::pair<uint32_t, int32_t>> fills;
  for (int v = 0; v < height_; ++v) {
    for (int u = 0; u < width_; ++u) {
      const int32_t index = v * width_ + u;
      if (mapped[index]) continue;
      const Eigen::Vector3d ray((u - ideal.cx) / ideal.fx, (v - ideal.cy) / ideal.fy, 1.0);
      Eigen::Vector2d sensor_pixel;
      if (!sensor.Project(ray, &sensor_pixel)) continue;
      const long x = std::lround(sensor_pixel.x());
      const long y = std::lround(sensor_pixel.y());
      if (x < 0 || y < 0 || x >= sensor_width_ || y >= sensor_height_) continue;
      fills.emplace_back(static_cast<uint32_t>(y * sensor_width_ + x), index);
    }
  }
  hole_begin_.clear();
  holes_.clear();
  if (fills.empty()) return;
  std::stable_sort(fills.begin(), fills.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  hole_begin_.assign(num_sensor + 1, 0);
  for (const auto& [sensor_index, hole] : fills) ++hole_begin_[sensor_index + 1];
  for (size_t s = 0; s < num_sensor; ++s) hole_begin_[s + 1] += hole_begin_[s];
  holes_.reserve(fills.size());
  for (const auto& [sensor_index, hole] : fills) holes_.push_back(hole);
}

void TimeSurface::Clear() {
  for (std::vector<int64_t>& channel : last_t_ns_) {
    channel.assign(static_cast<size_t>(width_) * height_, kNeverFired);
  }
  num_dropped_ = 0;
  num_stored_ = 0;
}

void TimeSurface::Insert(const EventBuffer& events, size_t begin, size_t end) {
  const int64_t* t_ns = events.t_ns.data();
  const uint16_t* xs = events.x.data();
  const uint16_t* ys = events.y.data();
  const int8_t* polarity = events.polarity.data();
  const int32_t* lookup = sensor_to_pixel_.data();
  const bool has_holes = !holes_.empty();
  const uint32_t* hole_begin = hole_begin_.data();
  const int32_t* holes = holes_.data();
  int64_t* all = last_t_ns_[0].data();
  int64_t* on = last_t_ns_[1].data();
  int64_t* off = last_t_ns_[2].data();
  const uint32_t sensor_width = sensor_width_;
  const uint32_t sensor_height = sensor_height_;
  int64_t dropped = 0;
  for (size_t i = begin; i < end; ++i) {
    const uint32_t x = xs[i];
    const uint32_t y = ys[i];
    if (x >= sensor_width || y >= sensor_height) [[unlikely]] {
      num_dropped_ += dropped;
      num_stored_ += static_cast<int64_t>(i - begin) - dropped;
      throw InvalidArgumentError("Event " + std::to_string(i) + " at pixel (" + std::to_string(x) +
                                 ", " + std::to_string(y) + ") lies outside the " +
                                 std::to_string(sensor_width) + "x" +
                                 std::to_string(sensor_height) + " sensor.");
    }
    const uint32_t sensor = y * sensor_width + x;
    const int32_t pixel = lookup[sensor];
    int64_t* signed_channel = polarity[i] > 0 ? on : off;
    bool stored = false;
    if (pixel >= 0) [[likely]] {
      all[pixel] = t_ns[i];
      signed_channel[pixel] = t_ns[i];
      stored = true;
    }
    if (has_holes) {
      const uint32_t first = hole_begin[sensor];
      const uint32_t last = hole_begin[sensor + 1];
      for (uint32_t k = first; k < last; ++k) {
        all[holes[k]] = t_ns[i];
        signed_channel[holes[k]] = t_ns[i];
      }
      stored |= first != last;
    }
    if (!stored) [[unlikely]]
      ++dropped;
  }
  num_dropped_ += dropped;
  num_stored_ += static_cast<int64_t>(end - begin) - dropped;
}

cv::Mat TimeSurface::Values(SurfaceChannel channel, int64_t t_ns, const SurfaceDecay& decay) const {
  cv::Mat values;
  Values(channel, t_ns, decay, &values);
  return values;
}

void TimeSurface::Values(SurfaceChannel channel, int64_t t_ns, const SurfaceDecay& decay,
                         cv::Mat* values_out) const {
  values_out->create(height_, width_, CV_32FC1);
  values_out->setTo(cv::Scalar(0));
  cv::Mat& values = *values_out;
  const int64_t* last = last_t_ns_[static_cast<int>(channel)].data();
  // The age test rejects most pixels without a logarithm and an exp each (Value's own bound).
  const int64_t max_age_ns = decay.MaxActiveAgeNs();
  for (int y = 0; y < height_; ++y) {
    float* row = values.ptr<float>(y);
    const int64_t* last_row = last + static_cast<size_t>(y) * width_;
    for (int x = 0; x < width_; ++x) {
      const int64_t last_t = last_row[x];
      if (last_t == kNeverFired || t_ns - last_t > max_age_ns) continue;
      row[x] = static_cast<float>(decay.Value(last_t, t_ns));
    }
  }
}

cv::Mat TimeSurface::ActiveMask(SurfaceChannel channel, int64_t t_ns,
                                const SurfaceDecay& decay) const {
  // Value is 0 or above the threshold (> 0), so a stored value is positive exactly when active.
  cv::Mat mask;
  cv::compare(Values(channel, t_ns, decay), 0.0, mask, cv::CMP_GT);
  return mask;
}

TimeSurfaceField::TimeSurfaceField(const TimeSurface& surface, SurfaceChannel channel,
                                   const SurfaceDecay& decay, bool smooth)
    : surface_(surface), channel_(channel), decay_(decay), exponential_(decay), smooth_(smooth) {
  const size_t num_pixels = static_cast<size_t>(surface.width()) * surface.height();
  raw_.assign(num_pixels, Memo{});
  if (smooth_) smoothed_.assign(num_pixels, Memo{});
}

void TimeSurfaceField::SetDecay(const SurfaceDecay& decay) {
  if (decay.decay_time_ns == decay_.decay_time_ns &&
      decay.empty_threshold == decay_.empty_threshold) {
    return;
  }
  decay_ = decay;
  exponential_ = DecayExponential(decay);
}

void TimeSurfaceField::SetTime(int64_t t_ns) {
  t_ns_ = t_ns;
  num_evaluated_ = 0;
  ++stamp_;
  if (stamp_ == 0) {  // Wrapped after 2^32 steps: invalidate explicitly.
    std::fill(raw_.begin(), raw_.end(), Memo{});
    std::fill(smoothed_.begin(), smoothed_.end(), Memo{});
    stamp_ = 1;
  }
}

float TimeSurfaceField::SmoothedValue(int x, int y) {
  const int width = surface_.width();
  Memo& memo = smoothed_[static_cast<size_t>(y) * width + x];
  if (memo.stamp == stamp_) return memo.value;
  // Separable 5x5 binomial kernel with replicated borders, rows first (as cv::sepFilter2D).
  const int max_x = width - 1;
  const int max_y = surface_.height() - 1;
  int columns[5];
  for (int i = 0; i < 5; ++i) columns[i] = std::clamp(x + i - 2, 0, max_x);
  float sum = 0.0f;
  for (int j = 0; j < 5; ++j) {
    const int row = std::clamp(y + j - 2, 0, max_y);
    float row_sum = 0.0f;
    for (int i = 0; i < 5; ++i) row_sum += kSmoothingKernel[i] * RawValue(columns[i], row);
    sum += kSmoothingKernel[j] * row_sum;
  }
  memo.value = sum;
  memo.stamp = stamp_;
  ++num_evaluated_;
  return sum;
}

cv::Mat TimeSurfaceField::RenderDense() const {
  cv::Mat raw(surface_.height(), surface_.width(), CV_32FC1);
  const size_t num_pixels = static_cast<size_t>(surface_.width()) * surface_.height();
  float* values = raw.ptr<float>(0);
  for (size_t index = 0; index < num_pixels; ++index) values[index] = ComputeRaw(index);
  return smooth_ ? SmoothField(raw) : raw;
}

DecayExponential::DecayExponential(const SurfaceDecay& decay)
    : inverse_tau_ns_(1.0 / decay.decay_time_ns), max_active_age_ns_(decay.MaxActiveAgeExactNs()) {
  const double largest = static_cast<double>(max_active_age_ns_) * inverse_tau_ns_;
  const int steps = static_cast<int>(largest * kStepsPerUnit) + 2;
  table_.resize(steps);
  for (int k = 0; k < steps; ++k) table_[k] = std::exp(-static_cast<double>(k) / kStepsPerUnit);
}

}  // namespace evloc::tracking
