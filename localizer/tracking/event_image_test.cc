// The image of the events (the search's image hypotheses): the leaky integrator's values, its
// rendering, and its bad input.
#include "localizer/tracking/event_image.h"

#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "core/common/error.h"

namespace evloc::tracking {
namespace {

constexpr int64_t kTau = 50'000'000;

EventBuffer Events(std::initializer_list<Event> events) {
  EventBuffer buffer;
  for (const Event& event : events) buffer.push_back(event);
  return buffer;
}

TEST(EventImage, IntegratesPolaritiesWithAnExponentialLeak) {
  EventImage image(4, 3, 0.05);
  EXPECT_EQ(image.covered_ns(), 0);
  const EventBuffer events = Events({{1'000, 1, 2, 1}, {1'000 + kTau, 1, 2, 1}, {2'000, 3, 0, -1}});
  // Time-ordered: the OFF event of (3, 0) comes before the second ON event of (1, 2).
  EventBuffer ordered;
  ordered.push_back(events[0]);
  ordered.push_back(events[2]);
  ordered.push_back(events[1]);
  image.Insert(ordered, 0, ordered.size());
  EXPECT_EQ(image.covered_ns(), kTau);
  const int64_t t = 1'000 + kTau;
  EXPECT_NEAR(image.Value(1, 2, t), std::exp(-1.0) + 1.0, 1e-6);
  EXPECT_NEAR(image.Value(1, 2, t + kTau), (std::exp(-1.0) + 1.0) * std::exp(-1.0), 1e-6);
  EXPECT_NEAR(image.Value(3, 0, 2'000 + 2 * kTau), -std::exp(-2.0), 1e-6);
  EXPECT_EQ(image.Value(0, 0, t), 0.0);
  image.Clear();
  EXPECT_EQ(image.covered_ns(), 0);
  EXPECT_EQ(image.Value(1, 2, t), 0.0);
}

TEST(EventImage, SkipsEventsOutsideTheImage) {
  EventImage image(4, 3, 0.05);
  const EventBuffer events = Events({{10, 4, 0, 1}, {20, 0, 3, 1}, {30, 2, 1, 1}});
  image.Insert(events, 0, events.size());
  // 1 from the one event inside (float rounding of its weight and decay: 1e-6, as above); the
  // two outside would make it 2 or 3 wherever they landed.
  EXPECT_NEAR(image.Value(2, 1, 30), 1.0, 1e-6);
}

// Over many time constants (the values are brought to a later anchor every 20 of them) the value
// stays the leaky sum of the polarities, sum p_i exp(-(t - t_i) / tau).
TEST(EventImage, StaysTheLeakySumOverManyTimeConstants) {
  EventImage image(4, 3, 0.05);
  EventBuffer events;
  for (int64_t t_ns = 0; t_ns < 3'000'000'000; t_ns += 7'000'000) {
    events.push_back({t_ns, 1, 1, static_cast<int8_t>((t_ns / 7'000'000) % 3 == 0 ? -1 : 1)});
    events.push_back({t_ns, 2, 2, 1});  // two events of one timestamp share a weight
  }
  for (size_t begin = 0; begin < events.size(); begin += 100) {
    image.Insert(events, begin, std::min(events.size(), begin + 100));
  }
  const int64_t t = events.t_ns.back() + 3'000'000;
  double expected_1 = 0;
  double expected_2 = 0;
  for (size_t i = 0; i < events.size(); ++i) {
    const double decay = std::exp(-static_cast<double>(t - events.t_ns[i]) / kTau);
    (events.x[i] == 1 ? expected_1 : expected_2) += events.polarity[i] * decay;
  }
  EXPECT_NEAR(image.Value(1, 1, t), expected_1, 1e-5 * std::abs(expected_1));
  EXPECT_NEAR(image.Value(2, 2, t), expected_2, 1e-5 * expected_2);
  EXPECT_GT(expected_2, 5.0);  // about 1 / (1 - exp(-7 / 50)) events' worth
}

TEST(EventImage, RendersOnPixelsBrightOffPixelsDarkAndTheRestBetween) {
  EventImage image(20, 10, 0.05);
  const cv::Mat before = image.Render(0);
  EXPECT_EQ(cv::countNonZero(before != 128), 0);  // All grey before any event.
  // Columns 0-8 fire ON three times, columns 11-19 OFF, columns 9 and 10 never.
  EventBuffer events;
  for (int k = 0; k < 3; ++k) {
    for (uint16_t y = 0; y < 10; ++y) {
      for (uint16_t x = 0; x < 20; ++x) {
        if (x < 9) events.push_back({100 + k, x, y, 1});
        if (x > 10) events.push_back({100 + k, x, y, -1});
      }
    }
  }
  image.Insert(events, 0, events.size());
  const cv::Mat rendered = image.Render(200);
  ASSERT_EQ(rendered.type(), CV_8UC1);
  ASSERT_EQ(rendered.cols, 20);
  ASSERT_EQ(rendered.rows, 10);
  const int on = rendered.at<uint8_t>(3, 2);
  const int off = rendered.at<uint8_t>(5, 17);
  const int rest = rendered.at<uint8_t>(4, 9);
  // Stretched from the 1st to the 99th percentile: the ON value to white, the OFF one to black,
  // the integrator's rest value (0) half way.
  EXPECT_EQ(on, 255);
  EXPECT_EQ(off, 0);
  EXPECT_NEAR(rest, 128, 1);
}

TEST(EventImage, RejectsABadSizeOrTimeConstant) {
  EXPECT_THROW(EventImage(0, 10, 0.05), InvalidArgumentError);
  EXPECT_THROW(EventImage(10, -1, 0.05), InvalidArgumentError);
  EXPECT_THROW(EventImage(10, 10, 0.0), InvalidArgumentError);
  EXPECT_THROW(EventImage(10, 10, std::nan("")), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::tracking
