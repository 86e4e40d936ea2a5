#include "localizer/tracking/event_filter.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/events/ecd_text.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "localizer/tracking/tracker.h"

namespace evloc::tracking {
namespace {

constexpr SensorSize kSensor{64, 48};
constexpr int64_t kMs = 1'000'000;

int64_t Nanoseconds(double seconds) { return std::llround(seconds * 1e9); }

// A vertical edge sweeping right one column per millisecond from t0 (every row fires once per
// column), then leaving the sensor.
void AddSweep(int64_t t0_ns, EventBuffer* events) {
  for (int x = 0; x < kSensor.width; ++x) {
    for (int y = 0; y < kSensor.height; ++y) {
      events->push_back(
          {t0_ns + x * kMs + y, static_cast<uint16_t>(x), static_cast<uint16_t>(y), 1});
    }
  }
}

EventBuffer Sorted(EventBuffer events) {
  std::vector<size_t> order(events.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return events.t_ns[a] < events.t_ns[b]; });
  EventBuffer sorted;
  for (const size_t i : order) sorted.push_back(events[i]);
  return sorted;
}

// Runs `events` through `filter` in packets of `packet` events and collects what passes.
EventBuffer FilterAll(EventFilter& filter, const EventBuffer& events, size_t packet) {
  EventBuffer passed;
  for (size_t begin = 0; begin < events.size(); begin += packet) {
    EventBuffer chunk;
    chunk.Append(events, begin, std::min(packet, events.size() - begin));
    passed.Append(filter.Process(chunk));
  }
  return passed;
}

size_t CountAt(const EventBuffer& events, int x, int y) {
  size_t count = 0;
  for (size_t i = 0; i < events.size(); ++i) count += events.x[i] == x && events.y[i] == y;
  return count;
}

TEST(EventFilter, WithEveryFilterOffReturnsItsInputItself) {
  EventFilter filter(kSensor, EventFilterOptions{});
  EXPECT_FALSE(filter.enabled());
  EventBuffer events;
  AddSweep(0, &events);
  EXPECT_EQ(&filter.Process(events), &events);
}

TEST(EventFilter, MasksAPixelHotFromTheFirstEventWithinItsLearningPeriod) {
  EventFilterOptions options;
  options.hot_pixels = true;  // 0.1 s windows, 10 x median, >= 100 Hz.
  EventFilter filter(kSensor, options);
  // A pixel firing at 2 kHz for 0.5 s, and an edge sweeping the sensor three times.
  EventBuffer events;
  for (int64_t t = 0; t < 500 * kMs; t += kMs / 2) events.push_back({t, 20, 30, -1});
  AddSweep(1 * kMs, &events);
  AddSweep(150 * kMs, &events);
  AddSweep(400 * kMs, &events);
  events = Sorted(events);
  const EventBuffer passed = FilterAll(filter, events, 997);
  // Not one of its events passes: the learning period (the first window) is held back and
  // filtered with the mask learned from it.
  EXPECT_EQ(CountAt(passed, 20, 30), 0u);
  EXPECT_TRUE(filter.IsMasked(20, 30));
  EXPECT_EQ(filter.counts().masked_pixels, 1);
  EXPECT_EQ(filter.counts().hot_pixel, 1000 + 3);
  // Every edge event passes, the pixel's own sweep events excepted (it is masked).
  EXPECT_EQ(passed.size(), 3u * kSensor.width * kSensor.height - 3);
  EXPECT_EQ(filter.counts().input, static_cast<int64_t>(events.size()));
  EXPECT_EQ(filter.counts().passed + filter.counts().held + filter.counts().hot_pixel,
            filter.counts().input);
}

TEST(EventFilter, HotPixelEventsNeverReachTheTrackersSurfaces) {
  const Camera camera = Camera::Pinhole(240, 180, 200.0, 200.0, 119.5, 89.5);
  const Map map = testing::MakeRectangleMap(testing::DefaultRectangles(), 0.004);
  EventBuffer events = testing::SimulateEdgeEvents(
      map, camera, [](int64_t t_ns) { return testing::SmoothMotion(t_ns); }, 0, 300 * kMs);
  for (int64_t t = 3; t < 300 * kMs; t += kMs) events.push_back({t, 7, 11, 1});
  events = Sorted(events);
  TrackerOptions options;
  options.event_filter.hot_pixels = true;
  Tracker tracker(map, nullptr, camera, options);
  tracker.Reset(testing::SmoothMotion(50 * kMs), 50 * kMs);
  for (size_t begin = 0; begin < events.size(); begin += 5000) {
    EventBuffer chunk;
    chunk.Append(events, begin, std::min<size_t>(5000, events.size() - begin));
    tracker.AddEvents(chunk);
    // The hot pixel's events are the only ones at 3 ns past a millisecond.
    const int64_t last = tracker.time_surface().LastTimestamp(SurfaceChannel::kAll, 7, 11);
    EXPECT_TRUE(last == kNeverFired || last % kMs != 3) << "after event " << begin;
  }
  EXPECT_GE(tracker.event_filter().counts().hot_pixel, 300);
  // The scene's events do reach them.
  EXPECT_GT(tracker.time_surface().num_stored(), static_cast<int64_t>(events.size()) * 9 / 10);
}

TEST(EventFilter, UnmasksAPixelThatCalmsDown) {
  EventFilterOptions options;
  options.hot_pixels = true;
  EventFilter filter(kSensor, options);
  EventBuffer events;
  // Hot (1 kHz) for 0.25 s, then one event every 50 ms.
  for (int64_t t = 0; t < 250 * kMs; t += kMs) events.push_back({t, 5, 5, 1});
  for (int64_t t = 300 * kMs; t < 800 * kMs; t += 50 * kMs) events.push_back({t, 5, 5, 1});
  for (int64_t t = 0; t < 800 * kMs; t += 20 * kMs) AddSweep(t, &events);
  events = Sorted(events);
  EventBuffer passed;
  bool masked_while_hot = false;
  for (size_t begin = 0; begin < events.size(); begin += 1000) {
    EventBuffer chunk;
    chunk.Append(events, begin, std::min<size_t>(1000, events.size() - begin));
    passed.Append(filter.Process(chunk));
    if (chunk.t_ns.back() > 120 * kMs && chunk.t_ns.back() < 250 * kMs) {
      masked_while_hot |= filter.IsMasked(5, 5);
    }
  }
  EXPECT_TRUE(masked_while_hot);
  EXPECT_FALSE(filter.IsMasked(5, 5));
  // Its calm events from the window after the one it calmed down in pass again.
  size_t late = 0;
  for (size_t i = 0; i < passed.size(); ++i) {
    late += passed.x[i] == 5 && passed.y[i] == 5 && passed.t_ns[i] >= 400 * kMs;
  }
  EXPECT_GT(late, 0u);
}

TEST(EventFilter, LearningPeriodEndsEarlyAtItsEventCap) {
  EventFilterOptions options;
  options.hot_pixels = true;
  options.hot_pixel_learning_max_events = 100;
  EventFilter filter(kSensor, options);
  EventBuffer events;
  AddSweep(0, &events);
  const EventBuffer& passed = filter.Process(events);
  EXPECT_FALSE(filter.holding());
  EXPECT_EQ(passed.size(), events.size());
}

TEST(EventFilter, AdvanceToReleasesACompleteLearningPeriod) {
  EventFilterOptions options;
  options.hot_pixels = true;
  EventFilter filter(kSensor, options);
  EventBuffer events;
  events.push_back({10, 1, 1, 1});
  events.push_back({20, 2, 1, 1});
  EXPECT_TRUE(filter.Process(events).empty());
  EXPECT_TRUE(filter.holding());
  EXPECT_TRUE(filter.AdvanceTo(100 * kMs + 8).empty());  // The window ends at 100 ms + 10 ns.
  EXPECT_EQ(filter.AdvanceTo(100 * kMs + 9).size(), 2u);
  EXPECT_FALSE(filter.holding());
}

TEST(EventFilter, BackgroundActivityRemovesIsolatedEventsAndPassesEdges) {
  EventFilterOptions options;
  options.background_activity_window_s = 0.002;
  EventFilter filter(kSensor, options);
  EventBuffer events;
  AddSweep(0, &events);  // Neighbours one column apart fire 1 ms apart.
  // Isolated noise events, each far in space or time from any other.
  for (int i = 0; i < 20; ++i) {
    events.push_back({100 * kMs + i * 10 * kMs, static_cast<uint16_t>(3 * i), 40, 1});
  }
  events = Sorted(events);
  const EventBuffer passed = FilterAll(filter, events, 333);
  // The sweep's first column has no earlier neighbour; rows of a column fire 1 ns apart, so
  // every row but the first of column 0 finds its upper neighbour.
  EXPECT_EQ(filter.counts().background_activity, 20 + 1);
  EXPECT_EQ(passed.size(), static_cast<size_t>(kSensor.width * kSensor.height - 1));
  for (size_t i = 0; i < passed.size(); ++i) EXPECT_LT(passed.t_ns[i], 100 * kMs);
}

TEST(EventFilter, BackgroundActivityCountsThePixelItselfOnlyWhenAsked) {
  EventBuffer events;
  events.push_back({0, 10, 10, 1});
  events.push_back({kMs, 10, 10, 1});
  EventFilterOptions options;
  options.background_activity_window_s = 0.002;
  EventFilter without_self(kSensor, options);
  EXPECT_TRUE(without_self.Process(events).empty());
  options.background_activity_include_self = true;
  EventFilter with_self(kSensor, options);
  const EventBuffer& passed = with_self.Process(events);
  ASSERT_EQ(passed.size(), 1u);
  EXPECT_EQ(passed.t_ns[0], kMs);
}

TEST(EventFilter, RefractoryPeriodDropsEventsTooSoonAfterTheLastPassedOne) {
  EventFilterOptions options;
  options.refractory_period_s = 0.001;
  EventFilter filter(kSensor, options);
  EventBuffer events;
  for (const int64_t t : {0L, 300'000L, 999'999L, 1'000'000L, 1'500'000L, 2'100'000L}) {
    events.push_back({t, 3, 4, 1});
  }
  events.push_back({400'000, 4, 4, -1});  // Another pixel is independent.
  events = Sorted(events);
  const EventBuffer& passed = filter.Process(events);
  std::vector<int64_t> times(passed.t_ns.begin(), passed.t_ns.end());
  EXPECT_EQ(times, (std::vector<int64_t>{0, 400'000, 1'000'000, 2'100'000}));
  EXPECT_EQ(filter.counts().refractory, 3);
}

TEST(EventFilter, TheSameEventsGiveTheSameResultForAnyPacketSplit) {
  EventFilterOptions options;
  options.hot_pixels = true;
  options.refractory_period_s = 0.0005;
  options.background_activity_window_s = 0.003;
  EventBuffer events;
  std::mt19937 random(7);
  std::uniform_int_distribution<int> x(0, kSensor.width - 1);
  std::uniform_int_distribution<int> y(0, kSensor.height - 1);
  for (int64_t t = 0; t < 600 * kMs; t += 37'000) {
    events.push_back({t, static_cast<uint16_t>(x(random)), static_cast<uint16_t>(y(random)), 1});
  }
  for (int64_t t = 0; t < 600 * kMs; t += kMs / 3) events.push_back({t, 9, 9, 1});
  for (int64_t t = 0; t < 600 * kMs; t += 45 * kMs) AddSweep(t, &events);
  events = Sorted(events);
  EventFilter whole(kSensor, options);
  const EventBuffer reference = whole.Process(events);
  for (const size_t packet : {1u, 7u, 1000u}) {
    EventFilter split(kSensor, options);
    EventBuffer passed;
    for (size_t begin = 0; begin < events.size(); begin += packet) {
      EventBuffer chunk;
      chunk.Append(events, begin, std::min(packet, events.size() - begin));
      passed.Append(split.Process(chunk));
      passed.Append(split.AdvanceTo(chunk.t_ns.back() - 1));
    }
    EXPECT_EQ(passed.t_ns, reference.t_ns) << packet;
    EXPECT_EQ(passed.x, reference.x) << packet;
    EXPECT_EQ(split.counts().hot_pixel, whole.counts().hot_pixel);
    EXPECT_EQ(split.counts().refractory, whole.counts().refractory);
    EXPECT_EQ(split.counts().background_activity, whole.counts().background_activity);
  }
  EXPECT_GT(whole.counts().hot_pixel, 0);
  EXPECT_GT(whole.counts().refractory, 0);
  EXPECT_GT(whole.counts().background_activity, 0);
}

TEST(EventFilter, AnEventOutsideTheSensorThrowsAndChangesNothing) {
  EventFilterOptions options;
  options.refractory_period_s = 0.001;
  EventFilter filter(kSensor, options);
  EventBuffer events;
  events.push_back({0, 1, 1, 1});
  events.push_back({1, 64, 1, 1});
  EXPECT_THROW(filter.Process(events), InvalidArgumentError);
  EXPECT_EQ(filter.counts().input, 0);
  EventBuffer good;
  good.push_back({0, 1, 1, 1});
  EXPECT_EQ(filter.Process(good).size(), 1u);
}

// The real recordings of the Event Camera Dataset (DAVIS240C, 30,000 events each, 5-106 ms):
// what each filter removes at the values docs/accuracy.md reports ("Noise filters"), printed for
// that table. Busy recordings of real edges: hot-pixel masking removes (almost) nothing, the
// background-activity filter removes the isolated events (4-12 % at 5 ms, measured), a filter
// that removed edge events wholesale would fail.
TEST(EventFilter, RealEcdSnippetsKeepTheirEdgeEvents) {
  for (const char* name :
       {"boxes_rotation", "boxes_translation", "dynamic_rotation", "dynamic_translation",
        "poster_rotation", "poster_translation", "shapes_rotation", "shapes_translation"}) {
    EVLOC_REQUIRE_SHARED_DATA(path, std::string("ecd/snippets/") + name + "/events.txt");
    EventBuffer events;
    EcdTextReader reader(path, SensorSize{240, 180});
    while (reader.Read(1 << 16, &events) > 0) {
    }
    ASSERT_EQ(events.size(), 30000u) << name;
    const auto removed = [&](const EventFilterOptions& options) {
      EventFilter filter(SensorSize{240, 180}, options);
      size_t passed = filter.Process(events).size();
      // The snippets are shorter than the learning period: the recording ends, and with it the
      // period.
      passed +=
          filter.AdvanceTo(events.t_ns.front() + Nanoseconds(options.hot_pixel_window_s)).size();
      EXPECT_EQ(filter.counts().held, 0);
      return 1.0 - static_cast<double>(passed) / static_cast<double>(events.size());
    };
    EventFilterOptions hot;
    hot.hot_pixels = true;
    EventFilterOptions refractory;
    refractory.refractory_period_s = 0.001;
    EventFilterOptions background;
    background.background_activity_window_s = 0.005;
    const double hot_removed = removed(hot);
    const double refractory_removed = removed(refractory);
    const double background_removed = removed(background);
    std::printf(
        "%-20s span %6.1f ms: removed hot pixels %5.2f %%, refractory 1 ms %5.2f %%, "
        "background activity 5 ms %5.2f %%\n",
        name, static_cast<double>(events.t_ns.back() - events.t_ns.front()) * 1e-6,
        100 * hot_removed, 100 * refractory_removed, 100 * background_removed);
    EXPECT_LT(hot_removed, 0.01) << name;
    EXPECT_LT(background_removed, 0.2) << name;
  }
}

TEST(EventFilterOptions, CheckRejectsValuesOutOfRange) {
  const auto rejects = [](auto change) {
    TrackerOptions options;
    change(options.event_filter);
    EXPECT_THROW(options.Check(), InvalidArgumentError);
  };
  rejects([](EventFilterOptions& o) { o.hot_pixel_window_s = 0; });
  rejects([](EventFilterOptions& o) { o.hot_pixel_rate_factor = 1; });
  rejects([](EventFilterOptions& o) { o.hot_pixel_min_rate_hz = -1; });
  rejects([](EventFilterOptions& o) { o.hot_pixel_learning_max_events = 0; });
  rejects([](EventFilterOptions& o) { o.refractory_period_s = -0.001; });
  rejects([](EventFilterOptions& o) { o.refractory_period_s = std::nan(""); });
  rejects([](EventFilterOptions& o) { o.background_activity_window_s = 2; });
  TrackerOptions fine;
  fine.event_filter.hot_pixels = true;
  fine.event_filter.refractory_period_s = 0.001;
  fine.event_filter.background_activity_window_s = 0.01;
  EXPECT_NO_THROW(fine.Check());
}

}  // namespace
}  // namespace evloc::tracking
