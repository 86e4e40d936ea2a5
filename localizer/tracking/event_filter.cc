#include "localizer/tracking/event_filter.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/common/cli.h"
#include "core/common/error.h"

namespace evloc::tracking {
namespace {

// The time of a pixel that never had an event. The tests compare t - period (no overflow for any
// session time, |t| <= 2^62 ns) with the stored times, never t - stored.
constexpr int64_t kLongAgoNs = std::numeric_limits<int64_t>::min();

int64_t Nanoseconds(double seconds) { return std::llround(seconds * 1e9); }

}  // namespace

EventFilter::EventFilter(SensorSize sensor_size, const EventFilterOptions& options)
    : options_((options.Check(), options)),
      enabled_(options.Enabled()),
      width_(sensor_size.width),
      height_(sensor_size.height),
      window_ns_(std::max<int64_t>(1, Nanoseconds(options.hot_pixel_window_s))),
      refractory_ns_(Nanoseconds(options.refractory_period_s)),
      background_window_ns_(Nanoseconds(options.background_activity_window_s)) {
  sensor_size.Check();
  const size_t pixels = static_cast<size_t>(width_) * height_;
  if (options_.hot_pixels) {
    pixel_state_.assign(pixels, 0);
  }
  if (refractory_ns_ > 0) last_passed_ns_.assign(pixels, kLongAgoNs);
  if (background_window_ns_ > 0) {
    last_event_ns_.assign(static_cast<size_t>(width_ + 2) * (height_ + 2), kLongAgoNs);
  }
}

const EventBuffer& EventFilter::Process(const EventBuffer& events) {
  if (!enabled_) return events;
  const size_t count = events.size();
  const int64_t* t_ns = events.t_ns.data();
  const uint16_t* xs = events.x.data();
  const uint16_t* ys = events.y.data();
  const int8_t* polarity = events.polarity.data();
  // Validate first: a bad event changes nothing.
  bool inside = true;
  for (size_t i = 0; i < count; ++i) inside &= xs[i] < width_ && ys[i] < height_;
  if (!inside) {
    for (size_t i = 0; i < count; ++i) {
      if (xs[i] >= width_ || ys[i] >= height_) {
        throw InvalidArgumentError("Event " + std::to_string(i) + " at pixel (" +
                                   std::to_string(xs[i]) + ", " + std::to_string(ys[i]) +
                                   ") lies outside the " + std::to_string(width_) + "x" +
                                   std::to_string(height_) + " sensor.");
      }
    }
  }
  out_count_ = 0;
  // At most the held events and this packet's come out of this call.
  ReserveOutput(count + held_.size());
  counts_.input += static_cast<int64_t>(count);
  const size_t learning_cap = static_cast<size_t>(options_.hot_pixel_learning_max_events);
  for (size_t i = 0; i < count; ++i) {
    const size_t index = static_cast<size_t>(ys[i]) * width_ + xs[i];
    if (options_.hot_pixels) {
      if (t_ns[i] >= window_end_ns_ || !started_) [[unlikely]] {
        CloseWindowsUntil(t_ns[i]);
      }
      if ((pixel_state_[index]++ & ~kMaskedBit) == 0) {
        touched_.push_back(static_cast<uint32_t>(index));
      }
      if (learning_) [[unlikely]] {
        held_.push_back({t_ns[i], xs[i], ys[i], polarity[i]});
        ++counts_.held;
        // A learning period that holds too many events ends early, judged on what it saw.
        if (held_.size() >= learning_cap) {
          EndLearning(t_ns[i] - window_start_ns_ + 1, t_ns[i] + 1);
        }
        continue;
      }
    }
    Pass(index, t_ns[i], xs[i], ys[i], polarity[i]);
  }
  return FinishOutput();
}

const EventBuffer& EventFilter::AdvanceTo(int64_t t_ns) {
  out_count_ = 0;
  // The learning window [start, end) is complete once no event before `end` can follow.
  if (learning_ && t_ns >= window_end_ns_ - 1) EndLearning(window_ns_, window_end_ns_);
  return FinishOutput();
}

void EventFilter::ReserveOutput(size_t count) {
  const size_t size = out_count_ + count;
  if (out_.t_ns.size() < size) {
    out_.t_ns.resize(size);
    out_.x.resize(size);
    out_.y.resize(size);
    out_.polarity.resize(size);
  }
}

const EventBuffer& EventFilter::FinishOutput() {
  out_.t_ns.resize(out_count_);
  out_.x.resize(out_count_);
  out_.y.resize(out_count_);
  out_.polarity.resize(out_count_);
  return out_;
}

void EventFilter::CloseWindowsUntil(int64_t t_ns) {
  if (!started_) {
    started_ = true;
    learning_ = true;
    window_start_ns_ = t_ns;
    window_end_ns_ = t_ns + window_ns_;
  }
  while (t_ns >= window_end_ns_) {
    if (learning_) {
      EndLearning(window_ns_, window_end_ns_);
    } else {
      CloseWindow(window_ns_, window_end_ns_);
    }
    // Skip whole windows without events at once (they would only unmask, and nothing is masked).
    if (t_ns >= window_end_ns_ && masked_list_.empty()) {
      window_start_ns_ += (t_ns - window_start_ns_) / window_ns_ * window_ns_;
      window_end_ns_ = window_start_ns_ + window_ns_;
    }
  }
}

uint32_t EventFilter::NeighbourMedianCount(uint32_t pixel) const {
  const int x = static_cast<int>(pixel % static_cast<uint32_t>(width_));
  const int y = static_cast<int>(pixel / static_cast<uint32_t>(width_));
  uint32_t counts[8];
  int n = 0;
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) {
      const int nx = x + dx;
      const int ny = y + dy;
      if ((dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= width_ || ny >= height_) continue;
      counts[n++] = pixel_state_[static_cast<size_t>(ny) * width_ + nx] & ~kMaskedBit;
    }
  }
  std::nth_element(counts, counts + n / 2, counts + n);
  return counts[n / 2];
}

void EventFilter::CloseWindow(int64_t duration_ns, int64_t next_start_ns) {
  // The population's level: the median count of the unmasked pixels that fired.
  scratch_counts_.clear();
  for (const uint32_t pixel : touched_) {
    if ((pixel_state_[pixel] & kMaskedBit) == 0) scratch_counts_.push_back(pixel_state_[pixel]);
  }
  double median = 0;
  if (!scratch_counts_.empty()) {
    const auto middle = scratch_counts_.begin() + scratch_counts_.size() / 2;
    std::nth_element(scratch_counts_.begin(), middle, scratch_counts_.end());
    median = *middle;
  }
  const double factor = options_.hot_pixel_rate_factor;
  const double population_threshold =
      std::max(std::ceil(options_.hot_pixel_min_rate_hz * static_cast<double>(duration_ns) * 1e-9),
               factor * median);
  // A pixel's own threshold also compares it with its 8 neighbours (their median count, so that
  // a hot neighbour does not hide it): a moving edge fires neighbouring pixels alike, however
  // textured the scene, while a hot pixel fires alone.
  const auto threshold = [&](uint32_t pixel) {
    return std::max(population_threshold,
                    factor * std::max<double>(1.0, NeighbourMedianCount(pixel)));
  };
  // Decide from this window's counts before any is reset: unmask the pixels that calmed down
  // (below half their threshold: hysteresis), mask the new hot ones.
  scratch_unmask_.clear();
  for (const uint32_t pixel : masked_list_) {
    if ((pixel_state_[pixel] & ~kMaskedBit) < 0.5 * threshold(pixel)) {
      scratch_unmask_.push_back(pixel);
    }
  }
  scratch_mask_.clear();
  for (const uint32_t pixel : touched_) {
    const uint32_t state = pixel_state_[pixel];
    if ((state & kMaskedBit) == 0 && state >= population_threshold && state >= threshold(pixel)) {
      scratch_mask_.push_back(pixel);
    }
  }
  for (const uint32_t pixel : scratch_unmask_) pixel_state_[pixel] &= ~kMaskedBit;
  size_t kept = 0;
  for (const uint32_t pixel : masked_list_) {
    if ((pixel_state_[pixel] & kMaskedBit) != 0) masked_list_[kept++] = pixel;
  }
  masked_list_.resize(kept);
  for (const uint32_t pixel : scratch_mask_) {
    pixel_state_[pixel] |= kMaskedBit;
    masked_list_.push_back(pixel);
  }
  for (const uint32_t pixel : touched_) pixel_state_[pixel] &= kMaskedBit;  // The counts restart.
  touched_.clear();
  counts_.masked_pixels = static_cast<int64_t>(masked_list_.size());
  window_start_ns_ = next_start_ns;
  window_end_ns_ = next_start_ns + window_ns_;
}

void EventFilter::EndLearning(int64_t duration_ns, int64_t next_start_ns) {
  learning_ = false;
  CloseWindow(duration_ns, next_start_ns);
  const size_t count = held_.size();
  ReserveOutput(count);
  for (size_t i = 0; i < count; ++i) {
    Pass(static_cast<size_t>(held_.y[i]) * width_ + held_.x[i], held_.t_ns[i], held_.x[i],
         held_.y[i], held_.polarity[i]);
  }
  counts_.held = 0;
  held_ = EventBuffer();
}

void EventFilter::Pass(size_t index, int64_t t_ns, uint16_t x, uint16_t y, int8_t polarity) {
  if (options_.hot_pixels && (pixel_state_[index] & kMaskedBit) != 0) {
    ++counts_.hot_pixel;
    return;
  }
  if (refractory_ns_ > 0) {
    if (t_ns - refractory_ns_ < last_passed_ns_[index]) {
      ++counts_.refractory;
      return;
    }
    last_passed_ns_[index] = t_ns;
  }
  if (background_window_ns_ > 0) {
    const ptrdiff_t stride = width_ + 2;
    int64_t* cell = last_event_ns_.data() + (static_cast<ptrdiff_t>(y) + 1) * stride + x + 1;
    const int64_t above = std::max({cell[-stride - 1], cell[-stride], cell[-stride + 1]});
    const int64_t beside = std::max(cell[-1], cell[1]);
    const int64_t below = std::max({cell[stride - 1], cell[stride], cell[stride + 1]});
    int64_t support = std::max({above, beside, below});
    if (options_.background_activity_include_self) support = std::max(support, cell[0]);
    cell[0] = t_ns;
    if (support < t_ns - background_window_ns_) {
      ++counts_.background_activity;
      return;
    }
  }
  ++counts_.passed;
  out_.t_ns[out_count_] = t_ns;
  out_.x[out_count_] = x;
  out_.y[out_count_] = y;
  out_.polarity[out_count_] = polarity;
  ++out_count_;
}

bool ApplyEventFilterFlag(std::string_view flag, std::string_view value,
                          EventFilterOptions* options) {
  if (flag == "--hot-pixels") {
    options->hot_pixels = ParseSwitchFlag(flag, value);
  } else if (flag == "--hot-pixel-window") {
    options->hot_pixel_window_s = ParseDoubleFlag(flag, value);
  } else if (flag == "--hot-pixel-factor") {
    options->hot_pixel_rate_factor = ParseDoubleFlag(flag, value);
  } else if (flag == "--hot-pixel-min-rate") {
    options->hot_pixel_min_rate_hz = ParseDoubleFlag(flag, value);
  } else if (flag == "--refractory") {
    options->refractory_period_s = ParseDoubleFlag(flag, value);
  } else if (flag == "--background-activity") {
    options->background_activity_window_s = ParseDoubleFlag(flag, value);
  } else if (flag == "--background-activity-self") {
    options->background_activity_include_self = ParseSwitchFlag(flag, value);
  } else {
    return false;
  }
  return true;
}

const char kEventFilterFlagsUsage[] =
    "  --hot-pixels on|off     mask hot pixels (docs/tracking.md, \"Noise filters\"; default off)\n"
    "  --hot-pixel-window S    hot-pixel counting window and learning period, seconds (default\n"
    "                          0.1)\n"
    "  --hot-pixel-factor F    a pixel is hot at F times the median count of the pixels that\n"
    "                          fired in the window (default 10)...\n"
    "  --hot-pixel-min-rate HZ ...and at least HZ events per second (default 100)\n"
    "  --refractory S          drop a pixel's events within S seconds of its last passed one\n"
    "                          (default 0: off)\n"
    "  --background-activity S keep an event only when a neighbour fired within S seconds\n"
    "                          before it (default 0: off)\n"
    "  --background-activity-self on|off\n"
    "                          the pixel's own previous event counts as support (default off)\n";

}  // namespace evloc::tracking
