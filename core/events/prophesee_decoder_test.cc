#include "core/events/prophesee_decoder.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

std::vector<uint8_t> Evt3Bytes(const std::vector<uint16_t>& words) {
  std::vector<uint8_t> bytes;
  for (uint16_t word : words) {
    bytes.push_back(static_cast<uint8_t>(word & 0xFF));
    bytes.push_back(static_cast<uint8_t>(word >> 8));
  }
  return bytes;
}

std::vector<uint8_t> Evt2Bytes(const std::vector<uint32_t>& words) {
  std::vector<uint8_t> bytes;
  for (uint32_t word : words) {
    for (int shift = 0; shift < 32; shift += 8)
      bytes.push_back(static_cast<uint8_t>(word >> shift));
  }
  return bytes;
}

// EVT 2.0 CD word.
uint32_t Evt2Cd(bool on, uint32_t time_low, uint32_t x, uint32_t y) {
  return (on ? 1u : 0u) << 28 | (time_low & 0x3F) << 22 | (x & 0x7FF) << 11 | (y & 0x7FF);
}
uint32_t Evt2TimeHigh(uint32_t time_high) { return 0x8u << 28 | (time_high & 0x0FFFFFFF); }

EventBuffer DecodeAll(EventStreamDecoder& decoder, const std::vector<uint8_t>& bytes) {
  EventBuffer out;
  decoder.Decode(bytes.data(), bytes.size(), &out);
  return out;
}

int64_t Us(int64_t microseconds) { return microseconds * 1000; }

TEST(Evt3Decoder, DecodesSingleEventsWithTimeAndPolarity) {
  // TIME_HIGH 1, TIME_LOW 2, ADDR_Y 5, ADDR_X ON x=7, ADDR_X OFF x=9, TIME_LOW 3, ADDR_X ON x=1.
  const auto bytes = Evt3Bytes({0x8001, 0x6002, 0x0005, 0x2807, 0x2009, 0x6003, 0x2801});
  Evt3Decoder decoder;
  const EventBuffer events = DecodeAll(decoder, bytes);
  ASSERT_EQ(events.size(), 3u);
  EXPECT_EQ(events[0], (Event{Us((1 << 12) + 2), 7, 5, 1}));
  EXPECT_EQ(events[1], (Event{Us((1 << 12) + 2), 9, 5, -1}));
  EXPECT_EQ(events[2], (Event{Us((1 << 12) + 3), 1, 5, 1}));
  EXPECT_EQ(decoder.statistics().events, 3u);
  EXPECT_EQ(decoder.statistics().bytes, bytes.size());
}

TEST(Evt3Decoder, ExpandsVectorWordsFromTheBaseAddress) {
  // VECT_BASE_X OFF x=100; VECT_12 bits 0, 2, 11; VECT_8 bits 0, 7; VECT_BASE_X ON x=3; VECT_8
  // 0x02.
  const auto bytes = Evt3Bytes({0x8000, 0x6010, 0x0021, 0x3064, 0x4805, 0x5081, 0x3803, 0x5002});
  Evt3Decoder decoder;
  const EventBuffer events = DecodeAll(decoder, bytes);
  const EventArray<uint16_t> expected_x = {100, 102, 111, 112, 119, 4};
  const EventArray<int8_t> expected_polarity = {-1, -1, -1, -1, -1, 1};
  EXPECT_EQ(events.x, expected_x);
  EXPECT_EQ(events.polarity, expected_polarity);
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_EQ(events.y[i], 0x21);
    EXPECT_EQ(events.t_ns[i], Us(0x10));
  }
}

TEST(Evt3Decoder, UnrollsTimeHighWrapAround) {
  const auto bytes = Evt3Bytes({0x8FFF, 0x6FFF, 0x0001, 0x2802,  // t = 2^24 - 1 us
                                0x8000, 0x6001, 0x2803,          // wraps: t = 2^24 + 1 us
                                0x8FFF, 0x6000, 0x2804,          // wraps back: t = 2 * 2^24 - 4096
                                0x8000, 0x6000, 0x2805});        // t = 2 * 2^24
  Evt3Decoder decoder;
  const EventBuffer events = DecodeAll(decoder, bytes);
  ASSERT_EQ(events.size(), 4u);
  EXPECT_EQ(events.t_ns[0], Us((1 << 24) - 1));
  EXPECT_EQ(events.t_ns[1], Us((1 << 24) + 1));
  EXPECT_EQ(events.t_ns[2], Us((1 << 24) + (0xFFF << 12)));
  EXPECT_EQ(events.t_ns[3], Us(int64_t{2} << 24));
  EXPECT_EQ(decoder.statistics().time_wraps, 2u);
  EXPECT_EQ(decoder.statistics().time_regressions, 0u);
}

TEST(Evt3Decoder, SmallTimeHighStepBackIsARegressionNotAWrap) {
  const auto bytes = Evt3Bytes({0x8100, 0x6000, 0x0001, 0x2802, 0x80FF, 0x2803});
  Evt3Decoder decoder;
  const EventBuffer events = DecodeAll(decoder, bytes);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events.t_ns[1], Us(0xFF << 12));
  EXPECT_EQ(decoder.statistics().time_wraps, 0u);
  EXPECT_EQ(decoder.statistics().time_regressions, 1u);
}

TEST(Evt3Decoder, CountsEventsBeforeTimeBaseAndOutsideSensor) {
  PropheseeDecoderOptions options;
  options.sensor_size = SensorSize{10, 8};
  Evt3Decoder decoder(options);
  // Event before any TIME_HIGH; then x=12 (outside), x=9 (inside), y=8 row (outside), vector
  // at base 6 with bits 0..5 (x = 6..11, 4 inside, 2 outside), and trigger + others words.
  const auto bytes = Evt3Bytes({0x0001, 0x2801, 0x8000, 0x280C, 0x2809, 0x0008, 0x2801, 0x0002,
                                0x3006, 0x503F, 0xA001, 0xE000, 0xF000, 0x7000});
  const EventBuffer events = DecodeAll(decoder, bytes);
  const DecoderStatistics& statistics = decoder.statistics();
  EXPECT_EQ(events.size(), 5u);
  EXPECT_EQ(statistics.events, 5u);
  EXPECT_EQ(statistics.dropped_before_state, 1u);
  EXPECT_EQ(statistics.dropped_outside_sensor, 4u);
  EXPECT_EQ(statistics.trigger_words, 1u);
  EXPECT_EQ(statistics.skipped_words, 3u);
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_LT(events.x[i], 10);
    EXPECT_LT(events.y[i], 8);
  }
}

// A stream exercising every word type, for the chunking tests.
std::vector<uint8_t> MixedEvt3Stream() {
  std::vector<uint16_t> words;
  for (uint32_t step = 0; step < 40; ++step) {
    words.push_back(static_cast<uint16_t>(0x8000 | ((step * 300) & 0xFFF)));  // wraps sometimes
    words.push_back(static_cast<uint16_t>(0x6000 | ((step * 77) & 0xFFF)));
    words.push_back(static_cast<uint16_t>(0x0000 | (step * 13 % 720)));
    words.push_back(static_cast<uint16_t>(0x2000 | ((step & 1) << 11) | (step * 31 % 1280)));
    words.push_back(static_cast<uint16_t>(0x3000 | ((step & 2) << 10) | (step * 17 % 1200)));
    words.push_back(static_cast<uint16_t>(0x4000 | ((step * 2654435761u) & 0xFFF)));
    words.push_back(static_cast<uint16_t>(0x5000 | ((step * 40503u) & 0xFF)));
    if (step % 7 == 0) words.push_back(0xA101);
    if (step % 5 == 0) words.push_back(0xE123);
  }
  return Evt3Bytes(words);
}

std::vector<uint8_t> MixedEvt2Stream() {
  std::vector<uint32_t> words;
  for (uint32_t step = 0; step < 40; ++step) {
    words.push_back(Evt2TimeHigh((step * 0x3000000u) & 0x0FFFFFFF));
    for (uint32_t k = 0; k < 4; ++k) {
      words.push_back(Evt2Cd((step + k) % 2 == 0, step * 7 + k, step * 31 + k, step * 13 % 480));
    }
    if (step % 7 == 0) words.push_back(0xA0000001u);
    if (step % 5 == 0) words.push_back(0xE0000000u);
  }
  return Evt2Bytes(words);
}

template <typename Decoder>
void ExpectChunkingInvariant(const std::vector<uint8_t>& bytes) {
  Decoder whole_decoder;
  const EventBuffer whole = DecodeAll(whole_decoder, bytes);
  ASSERT_GT(whole.size(), 100u);
  for (size_t split = 0; split <= bytes.size(); ++split) {
    Decoder decoder;
    EventBuffer events;
    decoder.Decode(bytes.data(), split, &events);
    decoder.Decode(bytes.data() + split, bytes.size() - split, &events);
    ASSERT_EQ(events, whole) << "split at byte " << split;
    ASSERT_FALSE(decoder.has_partial_word());
  }
  Decoder byte_by_byte_decoder;
  EventBuffer events;
  for (size_t i = 0; i < bytes.size(); ++i) byte_by_byte_decoder.Decode(&bytes[i], 1, &events);
  EXPECT_EQ(events, whole);
  EXPECT_EQ(byte_by_byte_decoder.statistics().time_wraps, whole_decoder.statistics().time_wraps);
}

TEST(Evt3Decoder, ChunkSplitsAtEveryByteGiveIdenticalOutput) {
  const auto bytes = MixedEvt3Stream();
  ExpectChunkingInvariant<Evt3Decoder>(bytes);
  Evt3Decoder decoder;
  DecodeAll(decoder, bytes);
  EXPECT_GT(decoder.statistics().time_wraps, 0u);
}

// Regression (fuzzer, evt3 crash-7e08a46): events right after an EVT_TIME_HIGH with no
// EVT_TIME_LOW took a stale time when a chunk boundary fell between the two words.
TEST(Evt3Decoder, TimeHighWithoutTimeLowSurvivesChunkSplits) {
  std::vector<uint16_t> words;
  for (uint16_t step = 0; step < 60; ++step) {
    words.push_back(static_cast<uint16_t>(0x8000 | (step * 5)));
    if (step % 3 == 0) words.push_back(static_cast<uint16_t>(0x6000 | step));
    words.push_back(static_cast<uint16_t>(0x0000 | step));
    words.push_back(static_cast<uint16_t>(0x2800 | step));
    words.push_back(static_cast<uint16_t>(0x2000 | (step + 100)));
  }
  ExpectChunkingInvariant<Evt3Decoder>(Evt3Bytes(words));
}

TEST(Evt2Decoder, ChunkSplitsAtEveryByteGiveIdenticalOutput) {
  const auto bytes = MixedEvt2Stream();
  ExpectChunkingInvariant<Evt2Decoder>(bytes);
  Evt2Decoder decoder;
  DecodeAll(decoder, bytes);
  EXPECT_GT(decoder.statistics().time_wraps, 0u);
}

TEST(Evt3Decoder, ReservedWordThrowsParseErrorWithCumulativeOffsetAndContinues) {
  PropheseeDecoderOptions options;
  options.source = "camera-7";
  options.first_byte_offset = 100;
  Evt3Decoder decoder(options);
  const auto first = Evt3Bytes({0x8000, 0x0001, 0x2801});
  EventBuffer events;
  decoder.Decode(first.data(), first.size(), &events);
  // Bytes 106..107 of the source hold a reserved type 0x9 word, 108..109 another (0xC).
  const auto second = Evt3Bytes({0x9123, 0xC000, 0x2802});
  try {
    decoder.Decode(second.data(), second.size(), &events);
    FAIL() << "no ParseError";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("camera-7: byte 106:"), std::string::npos)
        << error.what();
  }
  EXPECT_EQ(decoder.statistics().malformed_words, 2u);
  // The event after the malformed words was decoded, and the decoder continues.
  EXPECT_EQ(events.size(), 2u);
  const auto third = Evt3Bytes({0x2803});
  decoder.Decode(third.data(), third.size(), &events);
  EXPECT_EQ(events.size(), 3u);
}

TEST(PropheseeDecoders, ResetForgetsStateAndStatistics) {
  PropheseeDecoderOptions options;
  options.sensor_size = SensorSize{1280, 720};
  Evt3Decoder evt3(options);
  const auto evt3_bytes = MixedEvt3Stream();
  const EventBuffer first3 = DecodeAll(evt3, evt3_bytes);
  evt3.Reset();
  EXPECT_EQ(evt3.statistics().bytes, 0u);
  EXPECT_EQ(DecodeAll(evt3, evt3_bytes), first3);
  // The options survive the reset: x = 2047 is still outside the 1280-wide sensor.
  evt3.Reset();
  EXPECT_TRUE(DecodeAll(evt3, Evt3Bytes({0x8000, 0x0001, 0x2FFF})).empty());
  EXPECT_EQ(evt3.statistics().dropped_outside_sensor, 1u);

  Evt2Decoder evt2;
  const auto evt2_bytes = MixedEvt2Stream();
  const EventBuffer first2 = DecodeAll(evt2, evt2_bytes);
  EventBuffer scratch;
  evt2.Decode(evt2_bytes.data(), 3, &scratch);
  EXPECT_TRUE(evt2.has_partial_word());
  evt2.Reset();
  EXPECT_FALSE(evt2.has_partial_word());
  EXPECT_EQ(DecodeAll(evt2, evt2_bytes), first2);
}

TEST(Evt3Decoder, OddLengthLeavesAPartialWord) {
  const auto bytes = Evt3Bytes({0x8000, 0x0001, 0x2801});
  Evt3Decoder decoder;
  EventBuffer events;
  decoder.Decode(bytes.data(), bytes.size() - 1, &events);
  EXPECT_TRUE(decoder.has_partial_word());
  EXPECT_EQ(events.size(), 0u);
  decoder.Decode(bytes.data() + bytes.size() - 1, 1, &events);
  EXPECT_FALSE(decoder.has_partial_word());
  EXPECT_EQ(events.size(), 1u);
}

TEST(Evt2Decoder, DecodesEventsWithSixBitTimeLow) {
  const auto bytes = Evt2Bytes({Evt2Cd(true, 5, 3, 4), Evt2TimeHigh(10), Evt2Cd(true, 5, 3, 4),
                                Evt2Cd(false, 63, 2047, 0), 0xA0000101u, Evt2TimeHigh(11),
                                Evt2Cd(false, 0, 639, 479)});
  Evt2Decoder decoder;
  const EventBuffer events = DecodeAll(decoder, bytes);
  ASSERT_EQ(events.size(), 3u);
  EXPECT_EQ(events[0], (Event{Us(10 * 64 + 5), 3, 4, 1}));
  EXPECT_EQ(events[1], (Event{Us(10 * 64 + 63), 2047, 0, -1}));
  EXPECT_EQ(events[2], (Event{Us(11 * 64), 639, 479, -1}));
  EXPECT_EQ(decoder.statistics().dropped_before_state, 1u);
  EXPECT_EQ(decoder.statistics().trigger_words, 1u);
}

TEST(Evt2Decoder, UnrollsTimeHighWrapAroundAndDropsOutsideSensor) {
  PropheseeDecoderOptions options;
  options.sensor_size = SensorSize{640, 480};
  Evt2Decoder decoder(options);
  const auto bytes = Evt2Bytes({Evt2TimeHigh(0x0FFFFFFF), Evt2Cd(true, 63, 1, 1),
                                Evt2Cd(true, 0, 640, 1), Evt2TimeHigh(0), Evt2Cd(false, 1, 2, 2)});
  const EventBuffer events = DecodeAll(decoder, bytes);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events.t_ns[0], Us((int64_t{1} << 34) - 1));
  EXPECT_EQ(events.t_ns[1], Us((int64_t{1} << 34) + 1));
  EXPECT_EQ(decoder.statistics().time_wraps, 1u);
  EXPECT_EQ(decoder.statistics().dropped_outside_sensor, 1u);
}

TEST(Evt2Decoder, ReservedWordThrowsParseErrorWithOffset) {
  Evt2Decoder decoder;
  const auto bytes = Evt2Bytes({Evt2TimeHigh(1), 0x30000000u, Evt2Cd(true, 1, 1, 1)});
  EventBuffer events;
  // Fed in two chunks split inside the malformed word: the offset stays cumulative.
  decoder.Decode(bytes.data(), 6, &events);
  try {
    decoder.Decode(bytes.data() + 6, bytes.size() - 6, &events);
    FAIL() << "no ParseError";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("byte 4:"), std::string::npos) << error.what();
  }
  EXPECT_EQ(events.size(), 1u);
}

TEST(PropheseeDecoders, RandomGarbageNeverCrashesAndKeepsBuffersConsistent) {
  std::mt19937 random(12345);
  std::vector<uint8_t> bytes(1 << 20);
  for (auto& byte : bytes) byte = static_cast<uint8_t>(random());
  PropheseeDecoderOptions options;
  options.sensor_size = SensorSize{1280, 720};
  Evt3Decoder evt3(options);
  Evt2Decoder evt2(options);
  EventBuffer events3, events2;
  size_t errors = 0;
  for (size_t offset = 0; offset < bytes.size(); offset += 4093) {
    const size_t size = std::min<size_t>(4093, bytes.size() - offset);
    try {
      evt3.Decode(bytes.data() + offset, size, &events3);
    } catch (const ParseError&) {
      ++errors;
    }
    try {
      evt2.Decode(bytes.data() + offset, size, &events2);
    } catch (const ParseError&) {
      ++errors;
    }
  }
  EXPECT_GT(errors, 0u);
  EXPECT_TRUE(events3.IsConsistent());
  EXPECT_TRUE(events2.IsConsistent());
  EXPECT_EQ(events3.size(), evt3.statistics().events);
  for (size_t i = 0; i < events3.size(); ++i) {
    ASSERT_LT(events3.x[i], 1280);
    ASSERT_LT(events3.y[i], 720);
  }
}

// ------------------------------------------------------------------------------------------
// Real data: the EVT 3.0 sample and its reference decoding by expelliarmus.

// Reads the bytes after the `% ...` header lines of a Prophesee .raw file.
std::vector<uint8_t> RawPayload(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(file)),
                             std::istreambuf_iterator<char>());
  size_t offset = 0;
  while (offset < bytes.size() && bytes[offset] == '%') {
    while (offset < bytes.size() && bytes[offset] != '\n') ++offset;
    ++offset;
  }
  return {bytes.begin() + static_cast<std::ptrdiff_t>(offset), bytes.end()};
}

// A structured NumPy array with fields t (int64), x, y (int16) and p (uint8), little-endian.
struct NumpyEvents {
  std::vector<int64_t> t;
  std::vector<int16_t> x, y;
  std::vector<uint8_t> p;
};

NumpyEvents ReadNumpyEvents(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  const std::string content((std::istreambuf_iterator<char>(file)),
                            std::istreambuf_iterator<char>());
  if (content.compare(0, 6, "\x93NUMPY") != 0) throw std::runtime_error("not a .npy file");
  const int major = static_cast<uint8_t>(content[6]);
  size_t header_length = 0, header_start = 0;
  if (major == 1) {
    header_length = static_cast<uint8_t>(content[8]) | static_cast<uint8_t>(content[9]) << 8;
    header_start = 10;
  } else {
    for (int i = 3; i >= 0; --i)
      header_length = header_length << 8 | static_cast<uint8_t>(content[8 + i]);
    header_start = 12;
  }
  const std::string header = content.substr(header_start, header_length);
  if (header.find("'fortran_order': False") == std::string::npos) {
    throw std::runtime_error("fortran order not supported");
  }
  std::smatch shape_match;
  if (!std::regex_search(header, shape_match, std::regex(R"('shape': \((\d+),\))"))) {
    throw std::runtime_error("no 1-D shape");
  }
  const size_t count = std::stoull(shape_match[1]);
  // Fields in order: ('name', '<i8'); offsets follow from the sizes.
  const std::regex field_regex(R"(\('(\w*)', '([<>|])([a-zA-Z])(\d+)'\))");
  struct Field {
    std::string name;
    char kind;
    size_t size, offset;
  };
  std::vector<Field> fields;
  size_t item_size = 0;
  for (auto it = std::sregex_iterator(header.begin(), header.end(), field_regex);
       it != std::sregex_iterator(); ++it) {
    if ((*it)[2] == ">") throw std::runtime_error("big-endian field");
    const size_t size = std::stoul((*it)[4]);
    fields.push_back({(*it)[1], (*it)[3].str()[0], size, item_size});
    item_size += size;
  }
  auto offset_of = [&](const std::string& name, char kind, size_t size) {
    for (const Field& field : fields) {
      if (field.name == name && field.kind == kind && field.size == size) return field.offset;
    }
    throw std::runtime_error("field " + name + " missing or of another type");
  };
  const size_t t_offset = offset_of("t", 'i', 8), x_offset = offset_of("x", 'i', 2),
               y_offset = offset_of("y", 'i', 2), p_offset = offset_of("p", 'u', 1);
  const size_t data_start = header_start + header_length;
  if (content.size() != data_start + count * item_size) throw std::runtime_error("bad size");
  NumpyEvents events;
  events.t.resize(count);
  events.x.resize(count);
  events.y.resize(count);
  events.p.resize(count);
  for (size_t i = 0; i < count; ++i) {
    const char* item = content.data() + data_start + i * item_size;
    std::memcpy(&events.t[i], item + t_offset, 8);
    std::memcpy(&events.x[i], item + x_offset, 2);
    std::memcpy(&events.y[i], item + y_offset, 2);
    std::memcpy(&events.p[i], item + p_offset, 1);
  }
  return events;
}

TEST(Evt3Decoder, ReproducesTheExpelliarmusReferenceDecodingExactly) {
  EVLOC_REQUIRE_SHARED_DATA(raw_path, "prophesee/evt3_sample.raw");
  EVLOC_REQUIRE_SHARED_DATA(npy_path, "prophesee/evt3_sample.npy");
  const std::vector<uint8_t> payload = RawPayload(raw_path);
  const NumpyEvents reference = ReadNumpyEvents(npy_path);
  // Expelliarmus (the reference) adds 4096 us whenever an EVT_TIME_LOW word is smaller than the
  // previous one, on top of EVT_TIME_HIGH: every real time-high step is counted twice and each
  // small backward step of the sensor becomes a 4 ms jump (docs/event-formats.md, "EVT 3.0
  // reference"). This decoder follows the format: the file's EVT_TIME_HIGH words span only
  // 0xb2d..0xb2f. The test feeds one word at a time and reproduces the reference exactly as
  // decoded time + 4096 us x (number of decreasing EVT_TIME_LOW words so far).
  Evt3Decoder decoder;
  EventBuffer events;
  std::vector<int64_t> reference_offset_us;
  int64_t decreasing_time_low_words = 0;
  int previous_time_low = -1;
  for (size_t offset = 0; offset + 1 < payload.size(); offset += 2) {
    const uint16_t word = static_cast<uint16_t>(payload[offset] | payload[offset + 1] << 8);
    if (word >> 12 == 0x6) {
      if ((word & 0xFFF) < previous_time_low) ++decreasing_time_low_words;
      previous_time_low = word & 0xFFF;
    }
    decoder.Decode(payload.data() + offset, 2, &events);
    reference_offset_us.resize(events.size(), 4096 * decreasing_time_low_words);
  }
  ASSERT_EQ(events.size(), reference.t.size());
  size_t mismatches = 0;
  for (size_t i = 0; i < events.size(); ++i) {
    const bool same = events.t_ns[i] == (reference.t[i] - reference_offset_us[i]) * 1000 &&
                      events.x[i] == reference.x[i] && events.y[i] == reference.y[i] &&
                      events.polarity[i] == (reference.p[i] ? 1 : -1);
    if (!same && mismatches++ < 5) {
      ADD_FAILURE() << "event " << i << ": decoded (" << events.t_ns[i] << " ns, " << events.x[i]
                    << ", " << events.y[i] << ", " << int{events.polarity[i]} << "), reference ("
                    << reference.t[i] << " us - " << reference_offset_us[i] << " us, "
                    << reference.x[i] << ", " << reference.y[i] << ", " << int{reference.p[i]}
                    << ")";
    }
  }
  EXPECT_EQ(mismatches, 0u);
  // 2 real time-high steps (0xb2d -> 0xb2e -> 0xb2f) and 9 small backward steps of the sensor.
  EXPECT_EQ(decreasing_time_low_words, 11);
  EXPECT_EQ(decoder.statistics().time_regressions, 9u);
  EXPECT_EQ(events.t_ns.front(), int64_t{0xb2d000} * 1000);
  EXPECT_LE(events.t_ns.back(), int64_t{0xb2ffff} * 1000);
  EXPECT_EQ(decoder.statistics().malformed_words, 0u);
  EXPECT_EQ(decoder.statistics().dropped_before_state, 0u);
}

}  // namespace
}  // namespace evloc
