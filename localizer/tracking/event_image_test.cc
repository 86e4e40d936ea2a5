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
  EXPECT_NEAR(image.Value(2, 1, 30), 1.0, 1e-9);
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
