#include "tools/sim/esim.h"

#include <cmath>

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

}  // namespace
}  // namespace evloc::sim
