#include "tools/sim/esim.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

constexpr double kEpsilon = 1e-3;

// Options with no mismatch, refractory period or noise, and the given threshold.
EsimOptions CleanOptions(double threshold) {
  EsimOptions options;
  options.contrast_threshold_on = threshold;
  options.contrast_threshold_off = threshold;
  options.log_epsilon = kEpsilon;
  return options.Clean();
}

cv::Mat Uniform(int width, int height, double intensity) {
  return cv::Mat(height, width, CV_32FC1, cv::Scalar(intensity));
}

// The linear intensity whose log level is `log_level`.
double IntensityForLog(double log_level) { return std::exp(log_level) - kEpsilon; }

TEST(EventSimulator, StepEmitsFloorOfLogChangeOverThresholdWithItsPolarity) {
  const double threshold = 0.2;
  for (double log_change : {0.05, 0.25, 0.61, 0.85, 1.39, -0.3, -0.79, -1.21}) {
    EventSimulator simulator(3, 2, CleanOptions(threshold));
    const double base = std::log(0.3 + kEpsilon);
    simulator.Initialize(Uniform(3, 2, IntensityForLog(base)), 0);
    EventBuffer events;
    simulator.AddImage(Uniform(3, 2, IntensityForLog(base + log_change)), 1'000'000, &events);
    const int expected_per_pixel = static_cast<int>(std::floor(std::abs(log_change) / threshold));
    ASSERT_EQ(events.size(), static_cast<size_t>(6 * expected_per_pixel)) << log_change;
    for (size_t i = 0; i < events.size(); ++i) {
      EXPECT_EQ(events.polarity[i], log_change > 0 ? 1 : -1);
    }
  }
}

TEST(EventSimulator, ReferenceCarriesOverBetweenImages) {
  // Two steps of 0.15 each: no event after the first, one after the second (0.3 >= 0.2).
  EventSimulator simulator(1, 1, CleanOptions(0.2));
  const double base = std::log(0.2 + kEpsilon);
  simulator.Initialize(Uniform(1, 1, IntensityForLog(base)), 0);
  EventBuffer events;
  simulator.AddImage(Uniform(1, 1, IntensityForLog(base + 0.15)), 1000, &events);
  EXPECT_EQ(events.size(), 0u);
  simulator.AddImage(Uniform(1, 1, IntensityForLog(base + 0.30)), 2000, &events);
  ASSERT_EQ(events.size(), 1u);
  // The crossing of base + 0.2 happens a third of the way through the second interval.
  EXPECT_NEAR(events.t_ns[0], 1000 + 1000.0 / 3.0, 1.0);
}

TEST(EventSimulator, LinearRampGivesInterpolatedCrossingTimes) {
  const double threshold = 0.1;
  EventSimulator simulator(2, 1, CleanOptions(threshold));
  const double base = std::log(0.05 + kEpsilon);
  const double change = 0.75;  // crossings at 0.1 .. 0.7
  const int64_t t0 = 5'000'000;
  const int64_t t1 = 6'000'000;
  simulator.Initialize(Uniform(2, 1, IntensityForLog(base)), t0);
  EventBuffer events;
  simulator.AddImage(Uniform(2, 1, IntensityForLog(base + change)), t1, &events);
  ASSERT_EQ(events.size(), 14u);
  for (size_t i = 0; i < events.size(); ++i) {
    const int k = static_cast<int>(i / 2) + 1;
    const double expected = t0 + (k * threshold / change) * (t1 - t0);
    EXPECT_NEAR(static_cast<double>(events.t_ns[i]), expected, 2.0) << i;
    EXPECT_EQ(events.x[i], i % 2);  // same time: sorted by column
  }
}

TEST(EventSimulator, RefractoryPeriodSuppressesEventsButMovesTheReference) {
  EsimOptions options = CleanOptions(0.2);
  options.refractory_period_ns = 500'000;
  EventSimulator simulator(1, 1, options);
  const double base = std::log(0.1 + kEpsilon);
  simulator.Initialize(Uniform(1, 1, IntensityForLog(base)), 0);
  EventBuffer events;
  // Five crossings within 1 ms (change 1.05 over 1 ms): at k * 0.2 / 1.05 ms, k = 1..5, i.e.
  // 0.190, 0.381, 0.571, 0.762, 0.952 ms.
  simulator.AddImage(Uniform(1, 1, IntensityForLog(base + 1.05)), 1'000'000, &events);
  // Kept: 0.190 ms, then 0.762 ms (the others are within 0.5 ms of the last kept event).
  ASSERT_EQ(events.size(), 2u);
  EXPECT_NEAR(events.t_ns[0], 1e6 * 0.2 / 1.05, 2);
  EXPECT_NEAR(events.t_ns[1], 1e6 * 0.8 / 1.05, 2);
  // The reference followed all five crossings.
  EXPECT_NEAR(simulator.reference_log_intensity().at<float>(0, 0), base + 1.0, 1e-5);
  // So a further small change does not release the suppressed events.
  simulator.AddImage(Uniform(1, 1, IntensityForLog(base + 1.1)), 3'000'000, &events);
  EXPECT_EQ(events.size(), 2u);
}

TEST(EventSimulator, NoiseRateWithinStatisticalBounds) {
  EsimOptions options = CleanOptions(0.2);
  options.noise_rate_hz_per_pixel = 5.0;
  options.seed = 7;
  const int width = 80;
  const int height = 60;
  EventSimulator simulator(width, height, options);
  const cv::Mat still = Uniform(width, height, 0.4);
  simulator.Initialize(still, 0);
  EventBuffer events;
  const int64_t step = 10'000'000;
  const int64_t duration = 2'000'000'000;
  for (int64_t t = step; t <= duration; t += step) simulator.AddImage(still, t, &events);
  const double expected = options.noise_rate_hz_per_pixel * width * height * duration * 1e-9;
  EXPECT_NEAR(static_cast<double>(events.size()), expected, 5 * std::sqrt(expected));
  size_t on = 0;
  for (int8_t polarity : events.polarity) on += polarity > 0;
  const double n = static_cast<double>(events.size());
  EXPECT_NEAR(static_cast<double>(on), n / 2, 5 * std::sqrt(n / 4));
}

// A moving sinusoidal grating, linear intensity in [0.05, 0.95].
cv::Mat Grating(int width, int height, double shift_px) {
  cv::Mat image(height, width, CV_32FC1);
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      const double phase = 2 * M_PI * (col + 0.3 * row - shift_px) / 17.0;
      image.at<float>(row, col) = static_cast<float>(0.5 + 0.45 * std::sin(phase));
    }
  }
  return image;
}

EventBuffer SimulateGrating(const EsimOptions& options) {
  EventSimulator simulator(64, 48, options);
  simulator.Initialize(Grating(64, 48, 0), 0);
  EventBuffer events;
  for (int i = 1; i <= 40; ++i)
    simulator.AddImage(Grating(64, 48, 0.5 * i), i * 1'000'000, &events);
  return events;
}

TEST(EventSimulator, EventTimesNonDecreasingAndInsideTheSequence) {
  EsimOptions options;
  options.noise_rate_hz_per_pixel = 20;
  const EventBuffer events = SimulateGrating(options);
  ASSERT_GT(events.size(), 1000u);
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_GT(events.t_ns[i], 0);
    EXPECT_LE(events.t_ns[i], 40'000'000);
    if (i > 0) {
      ASSERT_LE(events.t_ns[i - 1], events.t_ns[i]) << i;
    }
    EXPECT_LT(events.x[i], 64);
    EXPECT_LT(events.y[i], 48);
  }
}

TEST(EventSimulator, SameSeedSameEventsAndThreadCountDoesNotMatter) {
  EsimOptions options;
  options.seed = 11;
  options.noise_rate_hz_per_pixel = 20;
  options.num_threads = 2;
  const EventBuffer first = SimulateGrating(options);
  const EventBuffer second = SimulateGrating(options);
  EXPECT_TRUE(first == second);
  options.num_threads = 1;
  EXPECT_TRUE(SimulateGrating(options) == first);
  options.seed = 12;
  EXPECT_FALSE(SimulateGrating(options) == first);
}

// FNV-1a digest of every event field, to compare whole streams with a recorded one.
uint64_t Digest(const EventBuffer& events) {
  uint64_t hash = 1469598103934665603ULL;
  const auto mix = [&hash](uint64_t value) {
    for (int byte = 0; byte < 8; ++byte) {
      hash ^= (value >> (8 * byte)) & 0xff;
      hash *= 1099511628211ULL;
    }
  };
  for (size_t i = 0; i < events.size(); ++i) {
    mix(static_cast<uint64_t>(events.t_ns[i]));
    mix(events.x[i]);
    mix(events.y[i]);
    mix(static_cast<uint64_t>(static_cast<int64_t>(events.polarity[i])));
  }
  return hash;
}

TEST(EventSimulator, IdealPixelReproducesTheRecordedStream) {
  // Recorded with the ESIM of commit 9366bbe (before the pixel model): the `ideal` sensor must
  // give the same events, bit for bit (docs/simulator.md).
  EsimOptions options;
  options.seed = 5;
  options.noise_rate_hz_per_pixel = 20;
  const EventBuffer events = SimulateGrating(options);
  EXPECT_EQ(events.size(), 95945u);
  EXPECT_EQ(Digest(events), 3803912034387287589ULL);
}

TEST(EventSimulator, ThresholdMismatchHasTheRequestedSpread) {
  EsimOptions options;
  options.threshold_mismatch_sigma = 0.03;
  EventSimulator simulator(100, 100, options);
  cv::Scalar mean;
  cv::Scalar deviation;
  cv::meanStdDev(simulator.on_thresholds(), mean, deviation);
  EXPECT_NEAR(mean[0], 0.2, 0.002);
  EXPECT_NEAR(deviation[0], 0.03, 0.002);
}

TEST(EventSimulator, RejectsBadInput) {
  EsimOptions options;
  options.contrast_threshold_on = 0;
  EXPECT_THROW(EventSimulator(4, 4, options), InvalidArgumentError);
  EventSimulator simulator(4, 4, EsimOptions());
  EventBuffer events;
  EXPECT_THROW(simulator.AddImage(Uniform(4, 4, 0.5), 1, &events), InvalidArgumentError);
  simulator.Initialize(Uniform(4, 4, 0.5), 10);
  EXPECT_THROW(simulator.AddImage(Uniform(4, 4, 0.5), 10, &events), InvalidArgumentError);
  EXPECT_THROW(simulator.AddImage(Uniform(5, 4, 0.5), 20, &events), InvalidArgumentError);
}

// The realistic pixel with only the named parts on: no mismatch, refractory period, noise,
// leak, hot pixels, low-pass or read-out limit unless a test sets them.
EsimOptions BarePixel(double threshold) {
  EsimOptions options = CleanOptions(threshold);
  options.seed = 21;
  return options;
}

// Runs a still image of `intensity` for `duration_ns` in steps of `step_ns`; returns the events
// and their origins.
struct PixelRun {
  EventBuffer events;
  std::vector<EventOrigin> origins;
  EsimCounts counts;
};
PixelRun RunStill(const EsimOptions& options, int width, int height, double intensity,
                  int64_t duration_ns, int64_t step_ns) {
  EventSimulator simulator(width, height, options);
  const cv::Mat still = Uniform(width, height, intensity);
  simulator.Initialize(still, 0);
  PixelRun run;
  for (int64_t t = step_ns; t <= duration_ns; t += step_ns) {
    simulator.AddImage(still, t, &run.events, &run.origins);
  }
  run.counts = simulator.counts();
  return run;
}

size_t CountOrigin(const PixelRun& run, EventOrigin origin) {
  return static_cast<size_t>(std::count(run.origins.begin(), run.origins.end(), origin));
}

TEST(PixelModel, ShotNoiseRateFollowsTheLight) {
  // Rate at intensity I: R / (1 + I / I_half). A Poisson count N has sd sqrt(N): 5 sd bounds.
  EsimOptions options = BarePixel(0.2);
  options.noise_rate_hz_per_pixel = 4.0;
  options.noise_half_intensity = 0.03;
  const int width = 60;
  const int height = 40;
  const int64_t duration = 5'000'000'000;
  for (double intensity : {0.0, 0.003, 0.03, 0.3, 0.9}) {
    const PixelRun run = RunStill(options, width, height, intensity, duration, 20'000'000);
    const double expected =
        options.noise_rate_hz_per_pixel / (1 + intensity / 0.03) * width * height * duration * 1e-9;
    EXPECT_NEAR(static_cast<double>(run.events.size()), expected, 5 * std::sqrt(expected))
        << "I = " << intensity;
    EXPECT_EQ(CountOrigin(run, EventOrigin::kNoise), run.events.size());
    EXPECT_EQ(run.counts.noise, static_cast<int64_t>(run.events.size()));
  }
}

TEST(PixelModel, HotPixelsFireAtTheirRateThroughTheRefractoryPeriod) {
  EsimOptions options = BarePixel(0.2);
  options.hot_pixel_fraction = 0.01;
  options.hot_pixel_rate_hz = 2000;
  options.refractory_period_ns = 200'000;
  const int width = 50;
  const int height = 40;
  const int64_t duration = 2'000'000'000;
  EventSimulator probe(width, height, options);
  ASSERT_EQ(probe.hot_pixels().size(), 20u);  // 1 % of 2000 pixels
  const PixelRun run = RunStill(options, width, height, 0.5, duration, 10'000'000);
  // A Poisson stream with a non-paralysable dead time R: rate r / (1 + r R) = 1428.6 Hz.
  const double expected = 2000 / (1 + 2000 * 200e-6) * duration * 1e-9;
  std::map<int, std::pair<size_t, std::set<int>>> per_pixel;  // count, polarities
  for (size_t i = 0; i < run.events.size(); ++i) {
    auto& [count, polarities] = per_pixel[run.events.y[i] * width + run.events.x[i]];
    ++count;
    polarities.insert(run.events.polarity[i]);
    ASSERT_EQ(run.origins[i], EventOrigin::kHotPixel);
  }
  ASSERT_EQ(per_pixel.size(), 20u);
  for (const auto& [pixel, entry] : per_pixel) {
    EXPECT_TRUE(std::binary_search(probe.hot_pixels().begin(), probe.hot_pixels().end(), pixel));
    // The dead time makes the count less variable than Poisson: sqrt(expected) bounds it.
    EXPECT_NEAR(static_cast<double>(entry.first), expected, 5 * std::sqrt(expected)) << pixel;
    EXPECT_EQ(entry.second.size(), 1u) << "a hot pixel keeps its polarity";
  }
  EXPECT_GT(run.counts.refractory_suppressed, 0);
}

TEST(PixelModel, RefractoryGapsAreNeverShorterThanThePeriod) {
  EsimOptions options = SensorPreset("davis240");
  options.noise_rate_hz_per_pixel = 50;
  options.hot_pixel_fraction = 0.02;
  options.refractory_period_ns = 700'000;
  const EventBuffer events = SimulateGrating(options);
  ASSERT_GT(events.size(), 2000u);
  std::map<int, int64_t> last;
  for (size_t i = 0; i < events.size(); ++i) {
    const int pixel = events.y[i] * 64 + events.x[i];
    const auto found = last.find(pixel);
    if (found != last.end()) {
      ASSERT_GE(events.t_ns[i] - found->second, options.refractory_period_ns) << i;
    }
    last[pixel] = events.t_ns[i];
    if (i > 0) {
      ASSERT_LE(events.t_ns[i - 1], events.t_ns[i]);
    }
  }
}

TEST(PixelModel, PresetThresholdsHaveTheirMismatchSpread) {
  // n = 40000 samples: the mean's sd is sigma / 200, the sample sd's about sigma / 283.
  for (const std::string& name : SensorPresetNames()) {
    const EsimOptions options = SensorPreset(name);
    EventSimulator simulator(200, 200, options);
    for (const auto& [thresholds, nominal] :
         {std::pair{simulator.on_thresholds(), options.contrast_threshold_on},
          std::pair{simulator.off_thresholds(), options.contrast_threshold_off}}) {
      cv::Scalar mean;
      cv::Scalar deviation;
      cv::meanStdDev(thresholds, mean, deviation);
      const double sigma = options.threshold_mismatch_sigma;
      EXPECT_NEAR(mean[0], nominal, 5 * sigma / 200 + 1e-6) << name;
      EXPECT_NEAR(deviation[0], sigma, 5 * sigma / 283 + 1e-6) << name;
    }
  }
  EXPECT_THROW(SensorPreset("davis"), InvalidArgumentError);
}

// Time of the first event after the log intensity steps up by `log_step` at 10 ms (a 1 us ramp),
// from `intensity`; images every 50 us.
double FirstEventDelayMs(const EsimOptions& options, double intensity, double log_step,
                         int* num_events) {
  EventSimulator simulator(1, 1, options);
  const double base = std::log(intensity + options.log_epsilon);
  simulator.Initialize(Uniform(1, 1, intensity), 0);
  EventBuffer events;
  const int64_t step_ns = 50'000;
  for (int64_t t = step_ns; t <= 10'000'000; t += step_ns) {
    simulator.AddImage(Uniform(1, 1, intensity), t, &events);
  }
  const cv::Mat bright = Uniform(1, 1, std::exp(base + log_step) - options.log_epsilon);
  simulator.AddImage(bright, 10'001'000, &events);
  for (int64_t t = 10'001'000 + step_ns; t <= 400'000'000; t += step_ns) {
    simulator.AddImage(bright, t, &events);
  }
  *num_events = static_cast<int>(events.size());
  return events.empty() ? -1 : (events.t_ns[0] - 10'000'000) * 1e-6;
}

TEST(PixelModel, PhotoreceptorLagGrowsInTheDarkAndKeepsTheEventCount) {
  // First order: y(t) = step (1 - exp(-t / tau)), tau = 1 / (2 pi f_c (I + eps)), so the first
  // threshold C is crossed after -tau ln(1 - C / step).
  EsimOptions options = BarePixel(0.2);
  options.photoreceptor_cutoff_hz = 500;
  const double log_step = 0.5;
  double previous_delay = 0;
  for (double intensity : {0.8, 0.1, 0.01, 0.002}) {
    int num_events = 0;
    const double delay_ms = FirstEventDelayMs(options, intensity, log_step, &num_events);
    const double light = (intensity + options.log_epsilon) * std::exp(log_step);  // I + eps
    const double tau_ms = 1e3 / (2 * M_PI * 500 * light);
    const double expected_ms = -tau_ms * std::log(1 - 0.2 / log_step);
    // Bounds: the 50 us image spacing, and 3 % for the linear interpolation between images.
    EXPECT_NEAR(delay_ms, expected_ms, 0.05 + 0.03 * expected_ms) << "I = " << intensity;
    EXPECT_GT(delay_ms, previous_delay) << "I = " << intensity;
    previous_delay = delay_ms;
    EXPECT_EQ(num_events, 2) << "a low-pass delays events, it does not remove them";
  }
  EXPECT_GT(previous_delay, 30.0);  // 0.002: tau = 64 ms
}

TEST(PixelModel, LeakEventsComeAtTheLeakRate) {
  EsimOptions options = BarePixel(0.2);
  options.leak_rate_hz = 2.0;
  options.leak_rate_spread_decades = 0;
  const PixelRun run = RunStill(options, 10, 10, 0.4, 10'250'000'000, 10'000'000);
  // The reference drifts down one threshold per 0.5 s: 20 ON events per pixel in 10.25 s.
  EXPECT_EQ(run.events.size(), 100u * 20);
  EXPECT_EQ(CountOrigin(run, EventOrigin::kLeak), run.events.size());
  for (int8_t polarity : run.events.polarity) ASSERT_EQ(polarity, 1);

  options.leak_rate_spread_decades = 0.2;
  EventSimulator spread(100, 100, options);
  double sum = 0;
  double sum_squares = 0;
  for (float rate : spread.leak_rates_hz()) {
    const double decades = std::log10(rate / 2.0);
    sum += decades;
    sum_squares += decades * decades;
  }
  const double n = static_cast<double>(spread.leak_rates_hz().size());
  EXPECT_NEAR(sum / n, 0.0, 5 * 0.2 / 100);
  EXPECT_NEAR(std::sqrt(sum_squares / n - (sum / n) * (sum / n)), 0.2, 5 * 0.2 / 141);
}

TEST(PixelModel, ReadOutLimitDelaysThenDropsAndIsNeverExceeded) {
  // Every pixel of 64 x 48 crosses 2 thresholds in the same microsecond: 6144 events at once.
  EsimOptions options = BarePixel(0.2);
  options.readout_rate_eps = 1e6;  // 1 event per us
  options.readout_max_delay_ns = 2'000'000;
  EventSimulator simulator(64, 48, options);
  const double base = 0.2;
  simulator.Initialize(Uniform(64, 48, base), 0);
  EventBuffer events;
  std::vector<EventOrigin> origins;
  simulator.AddImage(Uniform(64, 48, (base + 1e-3) * std::exp(0.45) - 1e-3), 1000, &events,
                     &origins);
  for (int64_t t = 1'000'000; t <= 10'000'000; t += 1'000'000) {
    simulator.AddImage(Uniform(64, 48, (base + 1e-3) * std::exp(0.45) - 1e-3), t, &events);
  }
  const EsimCounts& counts = simulator.counts();
  // The queue serves 1 event per us for at most 2 ms: 2001 events, the rest dropped.
  EXPECT_EQ(counts.events, static_cast<int64_t>(events.size()));
  EXPECT_EQ(counts.events + counts.readout_dropped, 6144);
  EXPECT_NEAR(static_cast<double>(counts.events), 2001, 2);
  EXPECT_LE(counts.readout_max_delay_ns, options.readout_max_delay_ns);
  for (size_t i = 1; i < events.size(); ++i) {
    ASSERT_GE(events.t_ns[i] - events.t_ns[i - 1], 1000) << i;  // 1 / rate
  }
}

TEST(PixelModel, SameSeedSameEventsWhateverTheThreadsAndTheLightMatters) {
  EsimOptions options = SensorPreset("davis240");
  options.hot_pixel_fraction = 0.01;
  options.noise_rate_hz_per_pixel = 20;
  options.seed = 4;
  const EventBuffer first = SimulateGrating(options);
  EXPECT_TRUE(SimulateGrating(options) == first);
  options.num_threads = 1;
  EXPECT_TRUE(SimulateGrating(options) == first);
  options.seed = 5;
  EXPECT_FALSE(SimulateGrating(options) == first);
}

TEST(PixelModel, OptionsAreChecked) {
  EsimOptions options;
  EXPECT_FALSE(options.UsesPixelModel());
  EXPECT_FALSE(SensorPreset("ideal").UsesPixelModel());
  EXPECT_TRUE(SensorPreset("gen4").UsesPixelModel());
  EXPECT_FALSE(SensorPreset("gen4").Clean().UsesPixelModel());
  options.hot_pixel_fraction = 1.0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = EsimOptions();
  options.photoreceptor_cutoff_hz = -1;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = EsimOptions();
  options.readout_max_delay_ns = -1;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::sim
