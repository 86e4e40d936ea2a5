#include "core/events/evt3_encoder.h"

#include <gtest/gtest.h>

#include <random>

#include "core/common/error.h"
#include "core/events/prophesee_decoder.h"

namespace evloc {
namespace {

EventBuffer RandomEvents(size_t count, uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_int_distribution<int> x(0, 1279), y(0, 719), step(0, 40), polarity(0, 1);
  std::uniform_int_distribution<int> long_gap(0, 999);
  EventBuffer events;
  int64_t t_us = 123;
  for (size_t i = 0; i < count; ++i) {
    t_us += step(random) == 0 ? 7 : 0;
    if (long_gap(random) == 0) t_us += 20'000'000;  // 20 s gaps cross the 24-bit wrap (16.7 s)
    events.push_back({t_us * 1000, static_cast<uint16_t>(x(random)),
                      static_cast<uint16_t>(y(random)), polarity(random) ? int8_t{1} : int8_t{-1}});
  }
  return events;
}

TEST(Evt3Encoder, RoundTripsThroughTheDecoderInAnySplit) {
  const EventBuffer events = RandomEvents(20000, 7);
  ASSERT_GT(events.t_ns.back(), 2 * 16'777'216'000LL) << "the stream should wrap twice";
  Evt3Encoder encoder;
  std::string bytes;
  encoder.Encode(events, &bytes);
  EXPECT_LT(bytes.size(), 5 * 2 * events.size());

  // Decode in uneven chunks, splitting words.
  Evt3Decoder decoder;
  EventBuffer decoded;
  for (size_t offset = 0; offset < bytes.size(); offset += 333) {
    const size_t size = std::min<size_t>(333, bytes.size() - offset);
    decoder.Decode(reinterpret_cast<const uint8_t*>(bytes.data()) + offset, size, &decoded);
  }
  EXPECT_EQ(decoded, events);
  EXPECT_EQ(decoder.statistics().malformed_words, 0u);
  EXPECT_GE(decoder.statistics().time_wraps, 2u);

  // Encoding in two calls gives the same bytes as one.
  Evt3Encoder split_encoder;
  std::string split_bytes;
  EventBuffer first, second;
  for (size_t i = 0; i < events.size(); ++i) (i < 777 ? first : second).push_back(events[i]);
  split_encoder.Encode(first, &split_bytes);
  split_encoder.Encode(second, &split_bytes);
  EXPECT_EQ(split_bytes, bytes);
}

TEST(Evt3Encoder, RejectsWhatEvt3CannotCarry) {
  Evt3Encoder encoder;
  std::string bytes;
  EventBuffer sub_microsecond;
  sub_microsecond.push_back({1500, 1, 1, 1});
  EXPECT_THROW(encoder.Encode(sub_microsecond, &bytes), InvalidArgumentError);
  EventBuffer too_wide;
  too_wide.push_back({1000, 2048, 1, 1});
  EXPECT_THROW(encoder.Encode(too_wide, &bytes), InvalidArgumentError);
  EventBuffer backwards;
  backwards.push_back({5000, 1, 1, 1});
  backwards.push_back({4000, 1, 1, 1});
  EXPECT_THROW(encoder.Encode(backwards, &bytes), InvalidArgumentError);
  EXPECT_TRUE(bytes.empty());
}

}  // namespace
}  // namespace evloc
