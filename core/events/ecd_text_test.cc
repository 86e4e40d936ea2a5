#include "core/events/ecd_text.h"

#include <gtest/gtest.h>

#include <sstream>

#include "core/common/error.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

EventBuffer ReadText(const std::string& text, size_t block = 1000) {
  EcdTextReader reader(std::make_unique<std::istringstream>(text), "events.txt");
  EventBuffer events;
  while (reader.Read(block, &events) > 0) {
  }
  return events;
}

TEST(ParseSecondsToNanoseconds, IsExactWithoutFloatingPoint) {
  EXPECT_EQ(ParseSecondsToNanoseconds("49.006624000"), 49'006'624'000);
  EXPECT_EQ(ParseSecondsToNanoseconds("0.000000001"), 1);
  EXPECT_EQ(ParseSecondsToNanoseconds("1"), 1'000'000'000);
  EXPECT_EQ(ParseSecondsToNanoseconds(".5"), 500'000'000);
  // 1e9 + 0.1 s is not representable in a double with ns precision; parsed exactly here.
  EXPECT_EQ(ParseSecondsToNanoseconds("1000000000.123456789"), 1'000'000'000'123'456'789);
  EXPECT_EQ(ParseSecondsToNanoseconds("0.1234567894"), 123'456'789);
  EXPECT_EQ(ParseSecondsToNanoseconds("0.1234567895"), 123'456'790);
  EXPECT_EQ(ParseSecondsToNanoseconds("0.9999999999"), 1'000'000'000);
  EXPECT_FALSE(ParseSecondsToNanoseconds("-1.0"));
  EXPECT_FALSE(ParseSecondsToNanoseconds("1e3"));
  EXPECT_FALSE(ParseSecondsToNanoseconds(""));
  EXPECT_FALSE(ParseSecondsToNanoseconds("."));
  EXPECT_FALSE(ParseSecondsToNanoseconds("99999999999"));
}

TEST(EcdTextReader, ParsesEventsSkippingCommentsAndBlankLines) {
  const EventBuffer events =
      ReadText("# t x y p\n\n0.000001000 1 2 1\r\n  1.5\t3 4 0  \n2 65535 0 1");
  ASSERT_EQ(events.size(), 3u);
  EXPECT_EQ(events[0], (Event{1000, 1, 2, 1}));
  EXPECT_EQ(events[1], (Event{1'500'000'000, 3, 4, -1}));
  EXPECT_EQ(events[2], (Event{2'000'000'000, 65535, 0, 1}));
}

TEST(EcdTextReader, MalformedLinesNameTheLine) {
  for (const std::string bad : {"1.0 1 2 2", "1.0 1 2", "1.0 1 -2 1", "1.0 70000 2 1", "abc 1 2 1",
                                "1.0 1 2 1 extra", "1.0 1x 2 1"}) {
    try {
      ReadText("0.5 1 1 1\n# comment\n" + bad + "\n");
      ADD_FAILURE() << "no error for '" << bad << "'";
    } catch (const ParseError& error) {
      EXPECT_NE(std::string(error.what()).find("events.txt: line 3:"), std::string::npos)
          << error.what();
    }
  }
  EXPECT_THROW(ReadText(std::string(10000, '1')), ParseError);
}

TEST(EcdTextReader, SmallReadBlocksGiveTheSameEvents) {
  std::string text;
  for (int i = 0; i < 1000; ++i) {
    text += std::to_string(i) + "." + std::to_string(100000000 + i) + " " +
            std::to_string(i % 240) + " " + std::to_string(i % 180) + " " + std::to_string(i % 2) +
            "\n";
  }
  EXPECT_EQ(ReadText(text, 7), ReadText(text, 100000));
  EXPECT_EQ(ReadText(text).size(), 1000u);
}

TEST(EcdText, WriteThenReadRoundTripsExactly) {
  const auto directory = testing::MakeTempDir("ecd");
  const auto path = directory / "events.txt";
  EventBuffer events;
  events.push_back({0, 0, 0, 1});
  events.push_back({1, 239, 179, -1});
  events.push_back({49'006'624'000, 192, 13, -1});
  events.push_back({9'000'000'000'000'000'000, 65535, 65535, 1});
  {
    EcdTextWriter writer(path);
    writer.Write(events);
    writer.Close();
  }
  EcdTextReader reader(path);
  EventBuffer read;
  while (reader.Read(2, &read) > 0) {
  }
  EXPECT_EQ(read, events);
  std::filesystem::remove_all(directory);
}

TEST(EcdTextReader, EverySharedSnippetHasExactly30000Events) {
  EVLOC_REQUIRE_SHARED_DATA(snippets, "ecd/snippets");
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(snippets)) {
    const auto path = entry.path() / "events.txt";
    if (!std::filesystem::exists(path)) continue;
    EcdTextReader reader(path, SensorSize{240, 180});
    EventBuffer events;
    while (reader.Read(4096, &events) > 0) {
    }
    EXPECT_EQ(events.size(), 30000u) << path;
    for (size_t i = 1; i < events.size(); ++i) ASSERT_GE(events.t_ns[i], events.t_ns[i - 1]);
    ++files;
  }
  EXPECT_EQ(files, 8);
}

}  // namespace
}  // namespace evloc
