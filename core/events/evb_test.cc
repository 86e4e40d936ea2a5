#include "core/events/evb.h"

#include <gtest/gtest.h>

#include <fstream>
#include <random>
#include <sstream>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/events/crc32.h"

namespace evloc {
namespace {

EventBuffer RandomEvents(size_t count, uint32_t seed) {
  std::mt19937_64 random(seed);
  EventBuffer events;
  int64_t t_ns = 1'600'000'000'000'000'000;
  for (size_t i = 0; i < count; ++i) {
    // Mostly small steps, sometimes jumps beyond a chunk's 2^31 ns range or backwards.
    const uint64_t kind = random() % 100;
    if (kind == 0) {
      t_ns += int64_t{5'000'000'000};
    } else if (kind == 1) {
      t_ns -= 1000;
    } else {
      t_ns += static_cast<int64_t>(random() % 5000);
    }
    events.push_back({t_ns, static_cast<uint16_t>(random() % 640),
                      static_cast<uint16_t>(random() % 480),
                      random() % 2 ? int8_t{1} : int8_t{-1}});
  }
  return events;
}

std::string ReadAll(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
}

EventBuffer ReadAllEvents(EventReader& reader, size_t block) {
  EventBuffer events;
  while (reader.Read(block, &events) > 0) {
  }
  return events;
}

TEST(Crc32, MatchesTheStandardCheckValuesAndContinues) {
  EXPECT_EQ(Crc32("123456789", 9), 0xCBF43926u);
  EXPECT_EQ(Crc32("", 0), 0u);
  // 32 zero bytes (the CRC-32 catalogue's second check value).
  const std::string zeros(32, '\0');
  EXPECT_EQ(Crc32(zeros.data(), zeros.size()), 0x190A55ADu);
  // A CRC continued over the second part equals the CRC of the whole, at every split.
  std::string bytes(1000, '\0');
  std::mt19937 random(7);
  for (char& byte : bytes) byte = static_cast<char>(random());
  const uint32_t whole = Crc32(bytes.data(), bytes.size());
  for (const size_t split :
       {size_t{0}, size_t{1}, size_t{7}, size_t{8}, size_t{513}, size_t{1000}}) {
    EXPECT_EQ(Crc32(bytes.data() + split, bytes.size() - split, Crc32(bytes.data(), split)), whole)
        << "split at " << split;
  }
}

TEST(Evb, RoundTripIsExactAcrossChunksJumpsAndRegressions) {
  const auto directory = testing::MakeTempDir("evb");
  const auto path = directory / "events.evb";
  const EventBuffer events = RandomEvents(20000, 7);
  EvbWriterOptions options;
  options.max_events_per_chunk = 1000;
  {
    EvbWriter writer(path, SensorSize{640, 480}, options);
    writer.Write(events);
    EXPECT_FALSE(std::filesystem::exists(path));  // only the temporary file exists before Close
    writer.Close();
  }
  ASSERT_TRUE(std::filesystem::exists(path));
  EvbReader reader(path);
  EXPECT_EQ(reader.sensor_size(), (SensorSize{640, 480}));
  EXPECT_EQ(ReadAllEvents(reader, 777), events);
  // 8 bytes per event plus headers.
  EXPECT_LT(std::filesystem::file_size(path), 20000 * 8 + 32 + 24 * 300);
  std::filesystem::remove_all(directory);
}

TEST(Evb, WriterWithoutCloseLeavesNoFile) {
  const auto directory = testing::MakeTempDir("evb");
  const auto path = directory / "events.evb";
  {
    EvbWriter writer(path);
    writer.Write(RandomEvents(10, 1));
  }
  EXPECT_TRUE(std::filesystem::is_empty(directory));
  std::filesystem::remove_all(directory);
}

TEST(Evb, WriterRejectsEventsOutsideTheSensor) {
  const auto directory = testing::MakeTempDir("evb");
  EvbWriter writer(directory / "events.evb", SensorSize{10, 10});
  EventBuffer events;
  events.push_back({0, 10, 0, 1});
  EXPECT_THROW(writer.Write(events), InvalidArgumentError);
  std::filesystem::remove_all(directory);
}

TEST(Evb, EveryCorruptedByteOrTruncationIsAParseErrorWithOffset) {
  const auto directory = testing::MakeTempDir("evb");
  const auto path = directory / "events.evb";
  EvbWriterOptions options;
  options.max_events_per_chunk = 16;
  EvbWriter writer(path, SensorSize{640, 480}, options);
  writer.Write(RandomEvents(40, 3));
  writer.Close();
  const std::string good = ReadAll(path);
  size_t detected = 0;
  for (size_t i = 0; i < good.size(); ++i) {
    std::string bad = good;
    bad[i] = static_cast<char>(bad[i] ^ 0x10);
    try {
      EvbReader corrupted(std::make_unique<std::istringstream>(bad), "bad.evb");
      ReadAllEvents(corrupted, 1000);
    } catch (const ParseError& error) {
      EXPECT_NE(std::string(error.what()).find("bad.evb: byte "), std::string::npos);
      ++detected;
    }
  }
  EXPECT_EQ(detected, good.size());
  for (size_t length = 0; length < good.size(); ++length) {
    EXPECT_THROW(
        {
          EvbReader truncated(std::make_unique<std::istringstream>(good.substr(0, length)), "t");
          ReadAllEvents(truncated, 1000);
        },
        ParseError)
        << "length " << length;
  }
  std::filesystem::remove_all(directory);
}

}  // namespace
}  // namespace evloc
