#include "tools/sim/esim.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <thread>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

// Rejects a non-finite or non-positive value of the named option.
void CheckPositive(double value, const char* name) {
  if (!std::isfinite(value) || value <= 0) {
    throw InvalidArgumentError(std::string("ESIM option ") + name +
                               " must be positive and finite, got " + std::to_string(value) + ".");
  }
}

// Orders events by time, then row, column and polarity: a total order, so the result does not
// depend on how the work was split between threads.
bool EventBefore(const Event& a, const Event& b) {
  if (a.t_ns != b.t_ns) return a.t_ns < b.t_ns;
  if (a.y != b.y) return a.y < b.y;
  if (a.x != b.x) return a.x < b.x;
  return a.polarity < b.polarity;
}

}  // namespace

EsimOptions EsimOptions::Clean() const {
  EsimOptions clean = *this;
  clean.threshold_mismatch_sigma = 0;
  clean.refractory_period_ns = 0;
  clean.noise_rate_hz_per_pixel = 0;
  return clean;
}

void EsimOptions::Check() const {
  CheckPositive(contrast_threshold_on, "contrast_threshold_on");
  CheckPositive(contrast_threshold_off, "contrast_threshold_off");
  CheckPositive(min_contrast_threshold, "min_contrast_threshold");
  CheckPositive(log_epsilon, "log_epsilon");
  if (!std::isfinite(threshold_mismatch_sigma) || threshold_mismatch_sigma < 0) {
    throw InvalidArgumentError("ESIM option threshold_mismatch_sigma must be >= 0 and finite.");
  }
  if (!std::isfinite(noise_rate_hz_per_pixel) || noise_rate_hz_per_pixel < 0) {
    throw InvalidArgumentError("ESIM option noise_rate_hz_per_pixel must be >= 0 and finite.");
  }
  if (refractory_period_ns < 0) {
    throw InvalidArgumentError("ESIM option refractory_period_ns must be >= 0.");
  }
  if (num_threads < 1) {
    throw InvalidArgumentError("ESIM option num_threads must be at least 1.");
  }
}

EventSimulator::EventSimulator(int width, int height, const EsimOptions& options)
    : width_(width),
      height_(height),
      options_(options),
      noise_rng_(options.seed ^ 0x9e3779b97f4a7c15ULL) {
  options_.Check();
  if (width <= 0 || height <= 0 || width > 65535 || height > 65535) {
    throw InvalidArgumentError("EventSimulator: image size " + std::to_string(width) + "x" +
                               std::to_string(height) + " is not in (0, 65535].");
  }
  threshold_on_.create(height, width, CV_32FC1);
  threshold_off_.create(height, width, CV_32FC1);
  std::mt19937_64 mismatch_rng(options_.seed);
  std::normal_distribution<double> mismatch(0.0, 1.0);
  const double sigma = options_.threshold_mismatch_sigma;
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      double on = options_.contrast_threshold_on;
      double off = options_.contrast_threshold_off;
      if (sigma > 0) {
        on += sigma * mismatch(mismatch_rng);
        off += sigma * mismatch(mismatch_rng);
      }
      threshold_on_.at<float>(row, col) =
          static_cast<float>(std::max(on, options_.min_contrast_threshold));
      threshold_off_.at<float>(row, col) =
          static_cast<float>(std::max(off, options_.min_contrast_threshold));
    }
  }
  last_event_ns_.assign(static_cast<size_t>(width) * height, std::numeric_limits<int64_t>::min());
  thread_events_.resize(options_.num_threads);
}

void EventSimulator::LogImage(const cv::Mat& intensity, cv::Mat* log_image) const {
  if (intensity.type() != CV_32FC1 || intensity.cols != width_ || intensity.rows != height_) {
    throw InvalidArgumentError(
        "EventSimulator: expected a " + std::to_string(width_) + "x" + std::to_string(height_) +
        " CV_32FC1 image, got " + std::to_string(intensity.cols) + "x" +
        std::to_string(intensity.rows) + " of type " + std::to_string(intensity.type()) + ".");
  }
  cv::max(intensity, 0.0, *log_image);
  *log_image += options_.log_epsilon;
  cv::log(*log_image, *log_image);
}

void EventSimulator::Initialize(const cv::Mat& intensity, int64_t t_ns) {
  LogImage(intensity, &previous_log_);
  reference_ = previous_log_.clone();
  last_t_ns_ = t_ns;
  initialized_ = true;
}

void EventSimulator::SimulateRows(int row_begin, int row_end, const cv::Mat& new_log,
                                  int64_t t_new_ns, std::vector<Event>* out) {
  const int64_t t_old_ns = last_t_ns_;
  const double interval_ns = static_cast<double>(t_new_ns - t_old_ns);
  const int64_t refractory_ns = options_.refractory_period_ns;
  for (int row = row_begin; row < row_end; ++row) {
    const float* old_row = previous_log_.ptr<float>(row);
    const float* new_row = new_log.ptr<float>(row);
    float* reference_row = reference_.ptr<float>(row);
    const float* on_row = threshold_on_.ptr<float>(row);
    const float* off_row = threshold_off_.ptr<float>(row);
    int64_t* last_event_row = last_event_ns_.data() + static_cast<size_t>(row) * width_;
    for (int col = 0; col < width_; ++col) {
      const float difference = new_row[col] - reference_row[col];
      if (difference < on_row[col] && -difference < off_row[col]) continue;  // no crossing
      const double old_level = old_row[col];
      const double change = static_cast<double>(new_row[col]) - old_level;
      const int8_t polarity = difference > 0 ? 1 : -1;
      const double step = polarity > 0 ? on_row[col] : -static_cast<double>(off_row[col]);
      double reference = reference_row[col];
      // Each crossing of reference + step emits one event and moves the reference by one step.
      while (polarity > 0 ? new_row[col] - reference >= step : new_row[col] - reference <= step) {
        reference += step;
        double fraction = change != 0 ? (reference - old_level) / change : 1.0;
        fraction = std::clamp(fraction, 0.0, 1.0);
        int64_t t_ns = t_old_ns + std::llround(fraction * interval_ns);
        t_ns = std::clamp(t_ns, t_old_ns + 1, t_new_ns);
        if (refractory_ns > 0 && last_event_row[col] != std::numeric_limits<int64_t>::min() &&
            t_ns - last_event_row[col] < refractory_ns) {
          continue;  // suppressed; the reference has still moved
        }
        last_event_row[col] = t_ns;
        out->push_back({t_ns, static_cast<uint16_t>(col), static_cast<uint16_t>(row), polarity});
      }
      reference_row[col] = static_cast<float>(reference);
    }
  }
}

void EventSimulator::AddNoise(int64_t t_new_ns, std::vector<Event>* out) {
  const double rate = options_.noise_rate_hz_per_pixel;
  if (rate <= 0) return;
  const double expected = rate * static_cast<double>(width_) * height_ *
                          static_cast<double>(t_new_ns - last_t_ns_) * 1e-9;
  std::poisson_distribution<int64_t> count_distribution(expected);
  const int64_t count = count_distribution(noise_rng_);
  std::uniform_int_distribution<int64_t> time_distribution(last_t_ns_ + 1, t_new_ns);
  std::uniform_int_distribution<int> col_distribution(0, width_ - 1);
  std::uniform_int_distribution<int> row_distribution(0, height_ - 1);
  std::bernoulli_distribution polarity_distribution(0.5);
  for (int64_t i = 0; i < count; ++i) {
    const int64_t t_ns = time_distribution(noise_rng_);
    const int col = col_distribution(noise_rng_);
    const int row = row_distribution(noise_rng_);
    const int8_t polarity = polarity_distribution(noise_rng_) ? 1 : -1;
    out->push_back({t_ns, static_cast<uint16_t>(col), static_cast<uint16_t>(row), polarity});
  }
}

void EventSimulator::AddImage(const cv::Mat& intensity, int64_t t_ns, EventBuffer* events) {
  if (!initialized_) {
    throw InvalidArgumentError("EventSimulator::AddImage called before Initialize().");
  }
  if (t_ns <= last_t_ns_) {
    throw InvalidArgumentError("EventSimulator::AddImage: time " + std::to_string(t_ns) +
                               " ns is not after the previous image at " +
                               std::to_string(last_t_ns_) + " ns.");
  }
  cv::Mat new_log;
  LogImage(intensity, &new_log);

  const int num_threads = std::min(options_.num_threads, height_);
  for (auto& batch : thread_events_) batch.clear();
  if (num_threads == 1) {
    SimulateRows(0, height_, new_log, t_ns, &thread_events_[0]);
  } else {
    std::vector<std::thread> workers;
    for (int i = 1; i < num_threads; ++i) {
      const int begin = height_ * i / num_threads;
      const int end = height_ * (i + 1) / num_threads;
      workers.emplace_back([this, begin, end, &new_log, t_ns, i] {
        SimulateRows(begin, end, new_log, t_ns, &thread_events_[i]);
      });
    }
    SimulateRows(0, height_ / num_threads, new_log, t_ns, &thread_events_[0]);
    for (auto& worker : workers) worker.join();
  }
  std::vector<Event>& batch = thread_events_[0];
  for (int i = 1; i < num_threads; ++i) {
    batch.insert(batch.end(), thread_events_[i].begin(), thread_events_[i].end());
  }
  AddNoise(t_ns, &batch);
  std::sort(batch.begin(), batch.end(), EventBefore);

  for (const Event& event : batch) events->push_back(event);

  previous_log_ = new_log;
  last_t_ns_ = t_ns;
}

}  // namespace evloc::sim
