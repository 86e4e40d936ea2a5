// libFuzzer target for the noise filters before the time surfaces (EventFilter,
// docs/tracking.md "Noise filters"; docs/reliability.md). Input: 10 bytes of options and sensor
// size, then events of 6 bytes (time step in microseconds, 16 bits; x; y; polarity and packet
// flags). Every filter setting is reachable, with every filter on in a quarter of the inputs.
//
// Checked on every input, whatever the options:
// - the events that pass are the same when the stream is given in one packet and when it is
//   split where the input says (the filters never depend on the packet split);
// - they are a subsequence of the input, in time order;
// - the counts add up: input = passed + held + hot_pixel + refractory + background_activity;
// - an event outside the sensor is refused with InvalidArgumentError and changes nothing;
// - with every filter off the output is the input, uncounted and unchecked (the tracker's path
//   when no filter is on: EventFilter::Process returns its argument).
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "core/common/error.h"
#include "localizer/tracking/event_filter.h"

namespace {

using evloc::EventBuffer;
using evloc::SensorSize;
using evloc::tracking::EventFilter;
using evloc::tracking::EventFilterCounts;
using evloc::tracking::EventFilterOptions;

void Require(bool condition) {
  if (!condition) std::abort();
}

bool SameEvents(const EventBuffer& a, const EventBuffer& b) {
  return a.t_ns == b.t_ns && a.x == b.x && a.y == b.y && a.polarity == b.polarity;
}

void CheckCounts(const EventFilterCounts& counts) {
  Require(counts.input == counts.passed + counts.held + counts.hot_pixel + counts.refractory +
                              counts.background_activity);
  Require(counts.masked_pixels >= 0);
}

// Runs `packets` through a fresh filter and then AdvanceTo past the last event.
EventBuffer FilterPackets(SensorSize size, const EventFilterOptions& options,
                          const std::vector<EventBuffer>& packets, int64_t end_ns,
                          EventFilterCounts* counts) {
  EventFilter filter(size, options);
  EventBuffer passed;
  for (const EventBuffer& packet : packets) {
    passed.Append(filter.Process(packet));
    CheckCounts(filter.counts());
  }
  passed.Append(filter.AdvanceTo(end_ns));
  CheckCounts(filter.counts());
  *counts = filter.counts();
  return passed;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 10) return 0;
  EventFilterOptions options;
  const uint8_t flags = data[0];
  const bool all_on = (flags & 0xc0) == 0xc0;
  options.hot_pixels = all_on || (flags & 1) != 0;
  options.background_activity_include_self = (flags & 2) != 0;
  options.refractory_period_s = (all_on || (flags & 4)) ? (1 + data[1]) * 1e-4 : 0.0;
  options.background_activity_window_s = (all_on || (flags & 8)) ? (1 + data[2]) * 1e-4 : 0.0;
  options.hot_pixel_window_s = (1 + data[3]) * 1e-3;
  options.hot_pixel_rate_factor = 1.0 + data[4] * 0.25;
  options.hot_pixel_min_rate_hz = data[5] * 10.0;
  options.hot_pixel_learning_max_events = 1 + data[6];
  const SensorSize sensor{1 + data[7] % 64, 1 + data[8] % 64};
  const uint8_t outside_at = data[9];  // the index of an event moved outside the sensor, 255: none
  try {
    options.Check();
  } catch (const evloc::InvalidArgumentError&) {
    return 0;
  }

  EventBuffer all;
  std::vector<EventBuffer> packets(1);
  int64_t t_ns = 1'000'000'000;
  for (size_t offset = 10; offset + 6 <= size && all.size() < 4096; offset += 6) {
    const uint16_t dt_us = static_cast<uint16_t>(data[offset] | (data[offset + 1] << 8));
    t_ns += int64_t{dt_us} * 1000;
    const uint16_t x = static_cast<uint16_t>(data[offset + 2] % sensor.width);
    const uint16_t y = static_cast<uint16_t>(data[offset + 3] % sensor.height);
    const int8_t polarity = (data[offset + 4] & 1) ? 1 : -1;
    all.push_back({t_ns, x, y, polarity});
    packets.back().push_back({t_ns, x, y, polarity});
    if (data[offset + 5] & 1) packets.emplace_back();
  }
  const int64_t end_ns = t_ns + 10'000'000'000;

  EventFilterCounts split_counts;
  const EventBuffer split = FilterPackets(sensor, options, packets, end_ns, &split_counts);
  EventFilterCounts whole_counts;
  const EventBuffer whole = FilterPackets(sensor, options, {all}, end_ns, &whole_counts);
  Require(SameEvents(split, whole));
  Require(split_counts.passed == whole_counts.passed);
  if (!options.Enabled()) {
    Require(SameEvents(whole, all));
    Require(whole_counts.input == 0);
    return 0;
  }
  Require(whole_counts.input == static_cast<int64_t>(all.size()));
  Require(whole_counts.held == 0);  // AdvanceTo far past the end releases every held event.
  Require(whole_counts.passed == static_cast<int64_t>(whole.size()));

  // A subsequence of the input, in time order.
  size_t j = 0;
  for (size_t i = 0; i < whole.size(); ++i) {
    if (i > 0) Require(whole.t_ns[i] >= whole.t_ns[i - 1]);
    while (j < all.size() && !(all.t_ns[j] == whole.t_ns[i] && all.x[j] == whole.x[i] &&
                               all.y[j] == whole.y[i] && all.polarity[j] == whole.polarity[i])) {
      ++j;
    }
    Require(j < all.size());
    ++j;
  }

  // An event outside the sensor is refused before anything changes.
  if (outside_at < all.size()) {
    EventFilter filter(sensor, options);
    EventBuffer bad = all;
    bad.x[outside_at] = static_cast<uint16_t>(sensor.width);
    bool refused = false;
    try {
      filter.Process(bad);
    } catch (const evloc::InvalidArgumentError&) {
      refused = true;
    }
    Require(refused);
    Require(filter.counts().input == 0);
    EventFilterCounts after;
    Require(SameEvents(FilterPackets(sensor, options, {all}, end_ns, &after), whole));
  }
  return 0;
}
