#include "localizer/wire/packed_events.h"

#include <gtest/gtest.h>

#include <limits>

#include "core/common/error.h"

namespace evloc::wire {
namespace {

// Events at the extremes of the layout: 16-bit coordinates, both polarities, equal times.
EventBuffer EdgeEvents() {
  EventBuffer events;
  events.push_back({1'000, 65535, 0, 1});
  events.push_back({2'000, 0, 65535, -1});
  events.push_back({2'000, 640, 480, 1});
  return events;
}

TEST(PackedEvents, LayoutIsAsDocumented) {
  EventBuffer events;
  events.push_back({500 + 0x01020304, 0x0506, 0x0708, 1});
  events.push_back({500, 1, 2, -1});
  const std::string data = EncodePackedEvents(events, 0, events.size(), 500);
  ASSERT_EQ(data.size(), 2 * kPackedEventBytes);
  EXPECT_EQ(data.substr(0, 8), std::string("\x04\x03\x02\x81\x06\x05\x08\x07", 8));
  EXPECT_EQ(data.substr(8, 8), std::string("\x00\x00\x00\x00\x01\x00\x02\x00", 8));
}

TEST(PackedEvents, RoundTripAppendsAndEncodesARange) {
  const EventBuffer events = EdgeEvents();
  const std::string data = EncodePackedEvents(events, 0, events.size(), 500);
  EXPECT_EQ(data.size(), 24u);
  EventBuffer decoded;
  DecodePackedEvents(data, 500, &decoded);
  EXPECT_EQ(decoded, events);
  // Appends: a second decode of the last two events only.
  DecodePackedEvents(EncodePackedEvents(events, 1, 3, 1'999), 1'999, &decoded);
  ASSERT_EQ(decoded.size(), 5u);
  EXPECT_EQ(decoded[3], events[1]);
  EXPECT_EQ(decoded[4], events[2]);
  // The largest offset round-trips; a negative base works too.
  EventBuffer far;
  far.push_back({-10 + kMaxPackedOffsetNs, 7, 8, -1});
  EventBuffer far_decoded;
  DecodePackedEvents(EncodePackedEvents(far, 0, 1, -10), -10, &far_decoded);
  EXPECT_EQ(far_decoded, far);
}

TEST(PackedEvents, RejectsWhatPackedCannotCarry) {
  const EventBuffer events = EdgeEvents();
  EXPECT_THROW(EncodePackedEvents(events, 0, 3, 1'001), InvalidArgumentError) << "before base";
  EXPECT_THROW(EncodePackedEvents(events, 0, 3, 2'000 - kMaxPackedOffsetNs - 1),
               InvalidArgumentError)
      << "2^31 ns after the base";
  EXPECT_NO_THROW(EncodePackedEvents(events, 1, 3, 2'000 - kMaxPackedOffsetNs));
  EventBuffer decoded;
  const std::string data = EncodePackedEvents(events, 0, 3, 0);
  EXPECT_THROW(DecodePackedEvents(data.substr(0, 23), 0, &decoded), InvalidArgumentError);
  EXPECT_THROW(DecodePackedEvents(
                   data, std::numeric_limits<int64_t>::max() - kMaxPackedOffsetNs + 1, &decoded),
               InvalidArgumentError);
  EXPECT_TRUE(decoded.empty()) << "nothing appended on an error";
}

TEST(PackEventWindows, WindowsCoverEveryEventAndKeepEmptyOnes) {
  EventBuffer events;
  events.push_back({101, 1, 1, 1});
  events.push_back({200, 2, 2, -1});  // at the first window's end: still in it
  events.push_back({450, 3, 3, 1});   // third window; the second is empty
  const std::vector<api::EventPacket> packets = PackEventWindows(events, 100, 100);
  ASSERT_EQ(packets.size(), 4u);
  const int64_t expected_counts[] = {2, 0, 0, 1};
  EventBuffer all;
  for (size_t k = 0; k < packets.size(); ++k) {
    EXPECT_EQ(packets[k].encoding(), api::EVENT_ENCODING_PACKED);
    EXPECT_EQ(packets[k].time_base_ns(), 100 + 100 * static_cast<int64_t>(k));
    EXPECT_EQ(packets[k].end_t_ns(), 200 + 100 * static_cast<int64_t>(k));
    EXPECT_EQ(static_cast<int64_t>(packets[k].data().size() / kPackedEventBytes),
              expected_counts[k])
        << "window " << k;
    DecodePackedEvents(packets[k].data(), packets[k].time_base_ns(), &all);
  }
  EXPECT_EQ(all, events);
  EXPECT_TRUE(PackEventWindows(EventBuffer(), 0, 10).empty());
}

TEST(PackEventWindows, RejectsBadWindowsAndOrigins) {
  const EventBuffer events = EdgeEvents();
  EXPECT_THROW(PackEventWindows(events, 0, 0), InvalidArgumentError);
  EXPECT_THROW(PackEventWindows(events, 0, kMaxPackedOffsetNs + 1), InvalidArgumentError);
  EXPECT_THROW(PackEventWindows(events, 1'000, 100), InvalidArgumentError)
      << "first event at the origin";
  EXPECT_EQ(PackEventWindows(events, 999, kMaxPackedOffsetNs).size(), 1u);
}

TEST(ThinningStride, KeepsAPacketWithinTheRate) {
  EXPECT_EQ(ThinningStride(1000, 1'000'000, 0), 1u);          // no advice
  EXPECT_EQ(ThinningStride(1000, 1'000'000, 1'000'000), 1u);  // 1000 in 1 ms: within
  EXPECT_EQ(ThinningStride(1001, 1'000'000, 1'000'000), 2u);
  EXPECT_EQ(ThinningStride(11'700, 1'000'000, 6'144'000), 2u);  // 640x480 at 20 per pixel
  EXPECT_EQ(ThinningStride(11'700, 1'000'000, 2'900'000), 5u);
  EXPECT_EQ(ThinningStride(50, 1'000, 1'000'000), 50u);  // under one event allowed: one kept
  EXPECT_EQ(ThinningStride(0, 1'000'000, 1), 1u);
  EXPECT_EQ(ThinningStride(10, 0, 1), 1u);
}

TEST(ThinEvents, KeepsEveryKthEventOfTheRangeOnlyWhenOverTheRate) {
  EventBuffer events;
  for (int i = 0; i < 10; ++i) events.push_back(Event{1000 + i, static_cast<uint16_t>(i), 0, 1});
  EventBuffer kept;
  kept.push_back(Event{1, 1, 1, -1});
  // Events 2..9 (8 of them) in 1 ms at 3,000 events/s: 3 allowed, every 3rd kept.
  EXPECT_EQ(ThinEvents(events, 2, 10, 1'000'000, 3'000, &kept), 3u);
  ASSERT_EQ(kept.size(), 3u);
  EXPECT_EQ(kept.x, (EventArray<uint16_t>{2, 5, 8}));
  // Within the rate: stride 1, `kept` untouched.
  EXPECT_EQ(ThinEvents(events, 0, 10, 1'000'000, 10'000, &kept), 1u);
  EXPECT_EQ(kept.size(), 3u);
}

}  // namespace
}  // namespace evloc::wire
