#include "tools/sim/esim.h"

#include <algorithm>
#include <cmath>
#include <functional>
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

// Rejects a negative or non-finite value of the named option.
void CheckNonNegative(double value, const char* name) {
  if (!std::isfinite(value) || value < 0) {
    throw InvalidArgumentError(std::string("ESIM option ") + name +
                               " must be >= 0 and finite, got " + std::to_string(value) + ".");
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

// Runs `simulate(row_begin, row_end, batch)` over the rows split between min(batches, height)
// threads, one batch each (cleared first), and returns the first batch with the others appended
// in row order.
template <typename Item, typename Function>
std::vector<Item>& SplitRows(int height, std::vector<std::vector<Item>>* batches,
                             const Function& simulate) {
  const int num_threads = std::min(static_cast<int>(batches->size()), height);
  for (auto& batch : *batches) batch.clear();
  std::vector<std::thread> workers;
  for (int i = 1; i < num_threads; ++i) {
    workers.emplace_back([&, i] {
      simulate(height * i / num_threads, height * (i + 1) / num_threads, &(*batches)[i]);
    });
  }
  simulate(0, height / num_threads, &(*batches)[0]);
  for (auto& worker : workers) worker.join();
  std::vector<Item>& first = (*batches)[0];
  for (int i = 1; i < num_threads; ++i) {
    first.insert(first.end(), (*batches)[i].begin(), (*batches)[i].end());
  }
  return first;
}

}  // namespace

EsimOptions EsimOptions::Clean() const {
  EsimOptions clean = *this;
  clean.threshold_mismatch_sigma = 0;
  clean.refractory_period_ns = 0;
  clean.noise_rate_hz_per_pixel = 0;
  clean.noise_half_intensity = 0;
  clean.photoreceptor_cutoff_hz = 0;
  clean.leak_rate_hz = 0;
  clean.hot_pixel_fraction = 0;
  clean.readout_rate_eps = 0;
  return clean;
}

bool EsimOptions::UsesPixelModel() const {
  return noise_half_intensity > 0 || photoreceptor_cutoff_hz > 0 || leak_rate_hz > 0 ||
         hot_pixel_fraction > 0 || readout_rate_eps > 0;
}

void EsimCounts::Add(const EsimCounts& other) {
  events += other.events;
  signal += other.signal;
  noise += other.noise;
  leak += other.leak;
  hot_pixel += other.hot_pixel;
  refractory_suppressed += other.refractory_suppressed;
  readout_dropped += other.readout_dropped;
  readout_delayed += other.readout_delayed;
  readout_max_delay_ns = std::max(readout_max_delay_ns, other.readout_max_delay_ns);
}

const std::vector<std::string>& SensorPresetNames() {
  static const std::vector<std::string> names = {"ideal", "davis240", "davis346", "gen3", "gen4"};
  return names;
}

EsimOptions SensorPreset(const std::string& name) {
  // Sources and derivations: docs/simulator.md, "Sensor presets". Thresholds are the published
  // minimum contrast sensitivities c as log thresholds ln(1 + c); the cutoff at intensity 1 is
  // the published latency at 1 klux scaled to the ~50 lux on the chip of the bright preset:
  // f = (50 / 1000) / (2 pi latency).
  struct Sheet {
    const char* name;
    double contrast_on;       // minimum contrast sensitivity, ON, fraction
    double contrast_off;      // the same, OFF
    double latency_s;         // latency at 1 klux
    double dark_noise_hz;     // shot-noise rate at the darkest level
    double readout_rate_eps;  // read-out bandwidth, events per second
  };
  static constexpr Sheet kSheets[] = {{"davis240", 0.11, 0.11, 12e-6, 5.0, 12e6},
                                      {"davis346", 0.143, 0.225, 20e-6, 5.0, 12e6},
                                      {"gen3", 0.12, 0.12, 40e-6, 1.0, 66e6},
                                      {"gen4", 0.11, 0.11, 20e-6, 1.0, 1066e6}};
  EsimOptions options;
  if (name == "ideal") return options;
  for (const Sheet& sheet : kSheets) {
    if (name != sheet.name) continue;
    options.contrast_threshold_on = std::log1p(sheet.contrast_on);
    options.contrast_threshold_off = std::log1p(sheet.contrast_off);
    options.threshold_mismatch_sigma = 0.021;
    options.refractory_period_ns = 500'000;
    options.photoreceptor_cutoff_hz = (50.0 / 1000.0) / (2 * M_PI * sheet.latency_s);
    options.noise_rate_hz_per_pixel = sheet.dark_noise_hz;
    options.noise_half_intensity = 0.03;
    options.leak_rate_hz = 0.1;
    options.leak_rate_spread_decades = 0.1;
    options.hot_pixel_fraction = 0;
    options.hot_pixel_rate_hz = 1000;
    options.readout_rate_eps = sheet.readout_rate_eps;
    options.readout_max_delay_ns = 1'000'000;
    return options;
  }
  throw InvalidArgumentError("Unknown sensor preset '" + name +
                             "'; expected ideal, davis240, davis346, gen3 or gen4.");
}

void EsimOptions::Check() const {
  CheckPositive(contrast_threshold_on, "contrast_threshold_on");
  CheckPositive(contrast_threshold_off, "contrast_threshold_off");
  CheckPositive(min_contrast_threshold, "min_contrast_threshold");
  CheckPositive(log_epsilon, "log_epsilon");
  CheckNonNegative(threshold_mismatch_sigma, "threshold_mismatch_sigma");
  CheckNonNegative(noise_rate_hz_per_pixel, "noise_rate_hz_per_pixel");
  CheckNonNegative(noise_half_intensity, "noise_half_intensity");
  CheckNonNegative(photoreceptor_cutoff_hz, "photoreceptor_cutoff_hz");
  CheckNonNegative(leak_rate_hz, "leak_rate_hz");
  CheckNonNegative(leak_rate_spread_decades, "leak_rate_spread_decades");
  CheckNonNegative(hot_pixel_rate_hz, "hot_pixel_rate_hz");
  CheckNonNegative(readout_rate_eps, "readout_rate_eps");
  if (!std::isfinite(hot_pixel_fraction) || hot_pixel_fraction < 0 || hot_pixel_fraction >= 1) {
    throw InvalidArgumentError("ESIM option hot_pixel_fraction must be in [0, 1), got " +
                               std::to_string(hot_pixel_fraction) + ".");
  }
  if (refractory_period_ns < 0) {
    throw InvalidArgumentError("ESIM option refractory_period_ns must be >= 0.");
  }
  if (readout_max_delay_ns < 0) {
    throw InvalidArgumentError("ESIM option readout_max_delay_ns must be >= 0.");
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
  if (!options_.UsesPixelModel()) return;

  // The realistic pixel's fixed pattern, each from its own stream so that the ideal pixel's
  // streams (mismatch, noise) are those of the original ESIM.
  const size_t num_pixels = static_cast<size_t>(width) * height;
  thread_candidates_.resize(options_.num_threads);
  if (options_.leak_rate_hz > 0) {
    std::mt19937_64 leak_rng(options_.seed ^ 0x6a09e667f3bcc909ULL);
    std::normal_distribution<double> spread(0.0, 1.0);
    leak_rate_hz_.resize(num_pixels);
    for (float& rate : leak_rate_hz_) {
      rate =
          static_cast<float>(options_.leak_rate_hz *
                             std::pow(10.0, options_.leak_rate_spread_decades * spread(leak_rng)));
    }
  }
  if (options_.hot_pixel_fraction > 0) {
    std::mt19937_64 choice_rng(options_.seed ^ 0xbb67ae8584caa73bULL);
    const auto count = static_cast<size_t>(
        std::llround(options_.hot_pixel_fraction * static_cast<double>(num_pixels)));
    // A partial Fisher-Yates shuffle picks `count` distinct pixels.
    std::vector<int32_t> order(num_pixels);
    for (size_t i = 0; i < num_pixels; ++i) order[i] = static_cast<int32_t>(i);
    for (size_t i = 0; i < count; ++i) {
      std::uniform_int_distribution<size_t> pick(i, num_pixels - 1);
      std::swap(order[i], order[pick(choice_rng)]);
    }
    hot_pixels_.assign(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(count));
    std::sort(hot_pixels_.begin(), hot_pixels_.end());
    std::bernoulli_distribution on(0.5);
    for (size_t i = 0; i < count; ++i) hot_polarity_.push_back(on(choice_rng) ? 1 : -1);
  }
  hot_rng_.seed(options_.seed ^ 0x3c6ef372fe94f82bULL);
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
  if (options_.UsesPixelModel()) {
    filtered_ = previous_log_.clone();
    leak_debt_ = cv::Mat::zeros(height_, width_, CV_32FC1);
  }
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

void EventSimulator::AddNoise(int64_t t_new_ns, const cv::Mat* new_log,
                              const std::function<void(const Event&)>& emit) {
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
  std::uniform_real_distribution<double> accept_distribution(0.0, 1.0);
  const double half = options_.noise_half_intensity;
  const bool thinned = new_log != nullptr && half > 0;
  for (int64_t i = 0; i < count; ++i) {
    const int64_t t_ns = time_distribution(noise_rng_);
    const int col = col_distribution(noise_rng_);
    const int row = row_distribution(noise_rng_);
    const int8_t polarity = polarity_distribution(noise_rng_) ? 1 : -1;
    if (thinned) {
      // Candidates come at the dark rate and are kept with probability 1 / (1 + I / I_half),
      // I the pixel's mean linear intensity over the interval.
      const double light = 0.5 * (std::exp(previous_log_.at<float>(row, col)) +
                                  std::exp(new_log->at<float>(row, col))) -
                           options_.log_epsilon;
      if (accept_distribution(noise_rng_) >= 1.0 / (1.0 + std::max(light, 0.0) / half)) continue;
    }
    emit({t_ns, static_cast<uint16_t>(col), static_cast<uint16_t>(row), polarity});
  }
}

void EventSimulator::AddImage(const cv::Mat& intensity, int64_t t_ns, EventBuffer* events,
                              std::vector<EventOrigin>* origins) {
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
  if (options_.UsesPixelModel()) {
    AddImageWithPixelModel(new_log, t_ns, events, origins);
    previous_log_ = new_log;
    last_t_ns_ = t_ns;
    return;
  }

  std::vector<Event>& batch =
      SplitRows(height_, &thread_events_, [&](int begin, int end, std::vector<Event>* out) {
        SimulateRows(begin, end, new_log, t_ns, out);
      });
  const size_t num_signal = batch.size();
  AddNoise(t_ns, nullptr, [&batch](const Event& event) { batch.push_back(event); });
  if (origins == nullptr) {
    std::sort(batch.begin(), batch.end(), EventBefore);
    for (const Event& event : batch) events->push_back(event);
  } else {
    // The same order through an index, to carry each event's origin along (equal events are
    // interchangeable, so the events are those of the plain sort).
    std::vector<uint32_t> order(batch.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<uint32_t>(i);
    std::sort(order.begin(), order.end(), [&batch](uint32_t a, uint32_t b) {
      if (EventBefore(batch[a], batch[b])) return true;
      if (EventBefore(batch[b], batch[a])) return false;
      return a < b;
    });
    for (uint32_t i : order) {
      events->push_back(batch[i]);
      origins->push_back(i < num_signal ? EventOrigin::kSignal : EventOrigin::kNoise);
    }
  }
  counts_.events += static_cast<int64_t>(batch.size());
  counts_.signal += static_cast<int64_t>(num_signal);
  counts_.noise += static_cast<int64_t>(batch.size() - num_signal);

  previous_log_ = new_log;
  last_t_ns_ = t_ns;
}

void EventSimulator::SimulatePixelModelRows(int row_begin, int row_end, const cv::Mat& new_log,
                                            int64_t t_new_ns, std::vector<Candidate>* out) {
  const int64_t t_old_ns = last_t_ns_;
  const double interval_ns = static_cast<double>(t_new_ns - t_old_ns);
  const double interval_s = interval_ns * 1e-9;
  const double cutoff_hz = options_.photoreceptor_cutoff_hz;
  const bool leak = !leak_rate_hz_.empty();
  for (int row = row_begin; row < row_end; ++row) {
    const float* old_row = previous_log_.ptr<float>(row);
    const float* new_row = new_log.ptr<float>(row);
    float* filtered_row = filtered_.ptr<float>(row);
    float* reference_row = reference_.ptr<float>(row);
    float* debt_row = leak_debt_.ptr<float>(row);
    const float* on_row = threshold_on_.ptr<float>(row);
    const float* off_row = threshold_off_.ptr<float>(row);
    const size_t row_offset = static_cast<size_t>(row) * width_;
    for (int col = 0; col < width_; ++col) {
      const double old_input = old_row[col];
      const double new_input = new_row[col];
      // Photoreceptor: a first-order low-pass of the log intensity whose cutoff is proportional
      // to the light (I + epsilon = exp(L)), solved exactly for the input's linear ramp over the
      // interval with the cutoff of the interval's mean light.
      const double start = filtered_row[col];
      double end = new_input;
      if (cutoff_hz > 0) {
        const double light = 0.5 * (std::exp(old_input) + std::exp(new_input));
        const double x = 2 * M_PI * cutoff_hz * light * interval_s;  // interval / time constant
        if (x < 1e-6) {
          end = start + x * (0.5 * (old_input + new_input) - start);
        } else {
          const double ramp = (new_input - old_input) / x;  // slope x time constant
          end = new_input - ramp + (start - old_input + ramp) * std::exp(-x);
        }
      }
      filtered_row[col] = static_cast<float>(end);
      // Leak: the reference drifts down by rate x ON threshold per second. Crossings are found on
      // level = output + drift so far against the effective reference (reference - debt).
      const double drift = leak ? leak_rate_hz_[row_offset + col] * on_row[col] * interval_s : 0.0;
      double reference = reference_row[col];
      double debt = debt_row[col];
      double effective = reference - debt;
      const double level_end = end + drift;
      const double difference = level_end - effective;
      if (difference >= on_row[col] || -difference >= off_row[col]) {
        const double change = level_end - start;
        const int8_t polarity = difference > 0 ? 1 : -1;
        const double step = polarity > 0 ? on_row[col] : -static_cast<double>(off_row[col]);
        while (polarity > 0 ? level_end - effective >= step : level_end - effective <= step) {
          effective += step;
          double fraction = change != 0 ? (effective - start) / change : 1.0;
          fraction = std::clamp(fraction, 0.0, 1.0);
          int64_t t_ns = t_old_ns + std::llround(fraction * interval_ns);
          t_ns = std::clamp(t_ns, t_old_ns + 1, t_new_ns);
          EventOrigin origin = EventOrigin::kSignal;
          // An ON crossing while at least half a threshold of leak drift is owed is a leak event
          // and pays one threshold of it; otherwise the reference itself moves. So the leak
          // events of a pixel number its drift over the threshold, rounded (docs/simulator.md).
          if (polarity > 0 && leak && debt + drift * fraction >= 0.5 * step) {
            origin = EventOrigin::kLeak;
            debt -= step;
          } else {
            reference += step;
          }
          out->push_back(
              {{t_ns, static_cast<uint16_t>(col), static_cast<uint16_t>(row), polarity}, origin});
        }
      }
      reference_row[col] = static_cast<float>(reference);
      debt_row[col] = static_cast<float>(debt + drift);
    }
  }
}

void EventSimulator::AddPixelModelNoise(const cv::Mat& new_log, int64_t t_new_ns,
                                        std::vector<Candidate>* out) {
  const double interval_s = static_cast<double>(t_new_ns - last_t_ns_) * 1e-9;
  AddNoise(t_new_ns, &new_log, [out](const Event& event) {
    out->push_back({event, EventOrigin::kNoise});
  });
  if (!hot_pixels_.empty()) {
    std::poisson_distribution<int64_t> count_distribution(options_.hot_pixel_rate_hz * interval_s);
    std::uniform_int_distribution<int64_t> time_distribution(last_t_ns_ + 1, t_new_ns);
    for (size_t k = 0; k < hot_pixels_.size(); ++k) {
      const int64_t count = count_distribution(hot_rng_);
      const auto col = static_cast<uint16_t>(hot_pixels_[k] % width_);
      const auto row = static_cast<uint16_t>(hot_pixels_[k] / width_);
      for (int64_t i = 0; i < count; ++i) {
        out->push_back(
            {{time_distribution(hot_rng_), col, row, hot_polarity_[k]}, EventOrigin::kHotPixel});
      }
    }
  }
}

void EventSimulator::AddImageWithPixelModel(const cv::Mat& new_log, int64_t t_new_ns,
                                            EventBuffer* events,
                                            std::vector<EventOrigin>* origins) {
  std::vector<Candidate>& batch =
      SplitRows(height_, &thread_candidates_, [&](int begin, int end, std::vector<Candidate>* out) {
        SimulatePixelModelRows(begin, end, new_log, t_new_ns, out);
      });
  AddPixelModelNoise(new_log, t_new_ns, &batch);
  std::sort(batch.begin(), batch.end(), [](const Candidate& a, const Candidate& b) {
    if (EventBefore(a.event, b.event)) return true;
    if (EventBefore(b.event, a.event)) return false;
    return a.origin < b.origin;
  });

  // Refractory period (from the pixel's last read-out event), then the read-out arbiter: one
  // event every 1 / rate seconds in time order, later ones wait, too long a wait drops them.
  const int64_t refractory_ns = options_.refractory_period_ns;
  const double service_ns = options_.readout_rate_eps > 0 ? 1e9 / options_.readout_rate_eps : 0;
  for (const Candidate& candidate : batch) {
    const Event& event = candidate.event;
    int64_t& last = last_event_ns_[static_cast<size_t>(event.y) * width_ + event.x];
    if (refractory_ns > 0 && last != std::numeric_limits<int64_t>::min() &&
        event.t_ns - last < refractory_ns) {
      ++counts_.refractory_suppressed;
      continue;
    }
    int64_t t_out = event.t_ns;
    if (service_ns > 0) {
      t_out = std::max(t_out, static_cast<int64_t>(std::ceil(readout_next_free_ns_)));
      if (t_out - event.t_ns > options_.readout_max_delay_ns) {
        ++counts_.readout_dropped;
        last = event.t_ns;  // the pixel was reset; its event was lost in the queue
        continue;
      }
      readout_next_free_ns_ = static_cast<double>(t_out) + service_ns;
      if (t_out > event.t_ns) {
        ++counts_.readout_delayed;
        counts_.readout_max_delay_ns = std::max(counts_.readout_max_delay_ns, t_out - event.t_ns);
      }
    }
    last = t_out;
    events->push_back({t_out, event.x, event.y, event.polarity});
    if (origins != nullptr) origins->push_back(candidate.origin);
    ++counts_.events;
    switch (candidate.origin) {
      case EventOrigin::kSignal:
        ++counts_.signal;
        break;
      case EventOrigin::kNoise:
        ++counts_.noise;
        break;
      case EventOrigin::kLeak:
        ++counts_.leak;
        break;
      case EventOrigin::kHotPixel:
        ++counts_.hot_pixel;
        break;
    }
  }
}

}  // namespace evloc::sim
