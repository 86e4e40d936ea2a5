#include "core/events/prophesee_raw.h"

#include <gtest/gtest.h>

#include <sstream>

#include "core/common/error.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

std::unique_ptr<std::istream> Stream(const std::string& bytes) {
  return std::make_unique<std::istringstream>(bytes);
}

TEST(PropheseeRawHeader, ReadsEncodingAndSizeFromFormatGeometryOrGeneration) {
  std::istringstream modern(
      "% camera_integrator_name Prophesee\n"
      "% format EVT3;height=720;width=1280\n% end\n\x01\x02");
  const auto header = ReadPropheseeRawHeader(modern, "a.raw");
  EXPECT_EQ(header.encoding, PropheseeEncoding::kEvt3);
  EXPECT_EQ(header.sensor_size, (SensorSize{1280, 720}));
  EXPECT_FALSE(header.sensor_size_inferred);
  EXPECT_EQ(modern.get(), 1);

  std::istringstream geometry("% evt 2.0\n% geometry 640x480\n%payload");
  const auto geometry_header = ReadPropheseeRawHeader(geometry, "b.raw");
  EXPECT_EQ(geometry_header.encoding, PropheseeEncoding::kEvt2);
  EXPECT_EQ(geometry_header.sensor_size, (SensorSize{640, 480}));
  // "%p" is payload, not header: the header ends before it.
  EXPECT_EQ(geometry_header.size_bytes, 29u);

  std::istringstream legacy("% evt 3.0\n% plugin_name hal_plugin_gen41_evk3\n");
  const auto legacy_header = ReadPropheseeRawHeader(legacy, "c.raw");
  EXPECT_EQ(legacy_header.sensor_size, (SensorSize{1280, 720}));
  EXPECT_TRUE(legacy_header.sensor_size_inferred);

  std::istringstream unknown("% date today\n\x01\x02");
  EXPECT_THROW(ReadPropheseeRawHeader(unknown, "d.raw"), ParseError);
  std::istringstream evt21("% format EVT21;height=720;width=1280\n");
  EXPECT_THROW(ReadPropheseeRawHeader(evt21, "e.raw"), ParseError);
}

TEST(PropheseeRawReader, TruncatedPayloadIsAParseErrorWithTheFileOffset) {
  // Header 10 bytes, then TIME_HIGH, ADDR_Y, ADDR_X and half a word.
  const std::string payload("\x00\x80\x01\x00\x01\x28\x02", 7);
  const std::string bytes = std::string("% evt 3.0\n") + payload;
  PropheseeRawReader reader(Stream(bytes), "cut.raw");
  EventBuffer events;
  try {
    reader.Read(100, &events);
    FAIL() << "no ParseError";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("cut.raw: byte 17:"), std::string::npos)
        << error.what();
  }
}

TEST(PropheseeRawReader, Evt3SampleStreamsTheSameEventsInAnyReadSize) {
  EVLOC_REQUIRE_SHARED_DATA(path, "prophesee/evt3_sample.raw");
  PropheseeRawReader reader(path);
  EXPECT_EQ(reader.header().encoding, PropheseeEncoding::kEvt3);
  EXPECT_EQ(reader.sensor_size(), (SensorSize{1280, 720}));
  EventBuffer small_reads, large_reads;
  while (reader.Read(1000, &small_reads) > 0) {
  }
  PropheseeRawReader second(path);
  while (second.Read(1 << 20, &large_reads) > 0) {
  }
  EXPECT_EQ(small_reads.size(), 219596u);
  EXPECT_EQ(small_reads, large_reads);
  EXPECT_EQ(reader.dropped_event_count(), 0u);
}

TEST(PropheseeRawReader, Evt2SampleHasNonDecreasingTimeInsideTheSensor) {
  EVLOC_REQUIRE_SHARED_DATA(path, "prophesee/evt2_sample.raw");
  PropheseeRawReader reader(path);
  EXPECT_EQ(reader.header().encoding, PropheseeEncoding::kEvt2);
  ASSERT_TRUE(reader.sensor_size().has_value());
  // The header names the Gen3 plugin but no size; Gen3 sensors are 640 x 480.
  EXPECT_EQ(*reader.sensor_size(), (SensorSize{640, 480}));
  EventBuffer events;
  while (reader.Read(4096, &events) > 0) {
  }
  EXPECT_GT(events.size(), 400000u);
  EXPECT_EQ(reader.statistics().dropped_outside_sensor, 0u);
  EXPECT_EQ(reader.statistics().malformed_words, 0u);
  for (size_t i = 0; i < events.size(); ++i) {
    ASSERT_LT(events.x[i], 640);
    ASSERT_LT(events.y[i], 480);
    if (i > 0) {
      ASSERT_GE(events.t_ns[i], events.t_ns[i - 1]) << "event " << i;
    }
  }
}

}  // namespace
}  // namespace evloc
