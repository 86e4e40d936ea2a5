#include "core/events/event.h"

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "core/events/crc32.h"

namespace evloc {
namespace {

TEST(EventBuffer, PushBackIndexAndAppendKeepArraysParallel) {
  EventBuffer buffer;
  buffer.push_back({10, 1, 2, 1});
  buffer.push_back({20, 3, 4, -1});
  EventBuffer other;
  other.push_back({30, 5, 6, 1});
  buffer.Append(other);
  ASSERT_EQ(buffer.size(), 3u);
  EXPECT_TRUE(buffer.IsConsistent());
  EXPECT_EQ(buffer[1], (Event{20, 3, 4, -1}));
  EXPECT_EQ(buffer[2], (Event{30, 5, 6, 1}));
  buffer.clear();
  EXPECT_TRUE(buffer.empty());
}

TEST(EventBuffer, AppendEveryTakesEveryKthEventOfARange) {
  EventBuffer source;
  for (int i = 0; i < 10; ++i) source.push_back({100 + i, static_cast<uint16_t>(i), 0, 1});
  EventBuffer buffer;
  buffer.push_back({1, 0, 0, -1});
  buffer.AppendEvery(source, 2, 9, 3);  // events 2, 5, 8
  ASSERT_EQ(buffer.size(), 4u);
  EXPECT_TRUE(buffer.IsConsistent());
  EXPECT_EQ(buffer[0], (Event{1, 0, 0, -1}));
  EXPECT_EQ(buffer.x, (EventArray<uint16_t>{0, 2, 5, 8}));
  buffer.AppendEvery(source, 9, 10, 4);  // one
  buffer.AppendEvery(source, 1, 1, 2);   // an empty range
  buffer.AppendEvery(source, 3, 2, 2);   // a start past the end
  EXPECT_EQ(buffer.x, (EventArray<uint16_t>{0, 2, 5, 8, 9}));
}

TEST(SensorSize, ContainsAndCheck) {
  const SensorSize size{640, 480};
  EXPECT_TRUE(size.Contains(639, 479));
  EXPECT_FALSE(size.Contains(640, 0));
  EXPECT_FALSE(size.Contains(-1, 0));
  EXPECT_NO_THROW(size.Check());
  EXPECT_THROW((SensorSize{0, 10}.Check()), InvalidArgumentError);
  EXPECT_THROW((SensorSize{70000, 10}.Check()), InvalidArgumentError);
}

TEST(Crc32, MatchesTheStandardCheckValueInAnyChunking) {
  const char text[] = "123456789";
  EXPECT_EQ(Crc32(text, 9), 0xCBF43926u);
  EXPECT_EQ(Crc32(text + 4, 5, Crc32(text, 4)), 0xCBF43926u);
  EXPECT_EQ(Crc32(text, 0), 0u);
}

}  // namespace
}  // namespace evloc
