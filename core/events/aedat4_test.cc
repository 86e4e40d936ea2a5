#include "core/events/aedat4.h"

#include <gtest/gtest.h>

#include <cstring>
#include <map>
#include <numeric>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/events/aedat4_xml.h"
#include "core/events/event_reader.h"
#include "core/events/testing/test_bags.h"

namespace evloc {
namespace {

using testing::ReadAllEvents;
using testing::ReadBytes;
using testing::StreamOf;

constexpr const char* kCompressions[] = {"none", "lz4", "lz4-high", "zstd", "zstd-high"};

std::string FileOf(const char* compression) {
  return std::string("test_") + compression + ".aedat4";
}

// The message of the ParseError reading every event of `bytes` throws, or "" when none.
std::string ParseErrorOf(const std::string& bytes, const std::string& stream = "events") {
  try {
    Aedat4EventOptions options;
    options.stream = stream;
    Aedat4EventReader reader(StreamOf(bytes), "cut.aedat4", options);
    ReadAllEvents(&reader, 1000);
  } catch (const ParseError& error) {
    return error.what();
  }
  return "";
}

TEST(Aedat4Reader, ListsTheStreamsOfTheHeaderDescription) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  Aedat4Reader file(dir / "test_lz4.aedat4");
  EXPECT_EQ(file.compression(), Aedat4Compression::kLz4);
  ASSERT_EQ(file.streams().size(), 4u);
  EXPECT_EQ(file.DescribeStreams(),
            "events (id 0, EVTS), frames (id 1, FRME), imu (id 2, IMUS), triggers (id 3, TRIG)");
  const Aedat4Stream* events = file.FindStream("events");
  ASSERT_NE(events, nullptr);
  EXPECT_EQ(events->id, 0);
  EXPECT_EQ(events->module, "capture");
  EXPECT_EQ(events->camera, "DAVIS346_00000499");
  ASSERT_TRUE(events->size.has_value());
  EXPECT_EQ(events->size->width, 346);
  EXPECT_EQ(events->size->height, 260);
  EXPECT_EQ(file.FindStream("2"), file.FindStream("imu"));
  EXPECT_EQ(file.FindStream("imu")->size, std::nullopt);
  EXPECT_EQ(file.FindStream("gyro"), nullptr);
  // The entities of the description are decoded.
  EXPECT_NE(file.description().find("&lt;events&gt;"), std::string::npos);
}

TEST(Aedat4EventReader, ReadsTheEventsOfEveryCompressionExactlyInAnyBatchSize) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  const EventBuffer expected = testing::ReadExpectedEvents(dir, "events");
  const uint64_t dropped = std::stoull(testing::ReadExpectedLines(dir, "dropped").at(0).at(0));
  ASSERT_GT(expected.size(), 10000u);
  ASSERT_EQ(dropped, 3u);
  for (const char* compression : kCompressions) {
    for (size_t batch : {size_t{1} << 20, size_t{777}}) {
      Aedat4EventReader reader(dir / FileOf(compression));
      ASSERT_TRUE(reader.sensor_size().has_value());
      EXPECT_EQ(reader.sensor_size()->width, 346);
      EXPECT_EQ(ReadAllEvents(&reader, batch), expected) << compression << " batch " << batch;
      EXPECT_EQ(reader.dropped_event_count(), dropped) << compression;
      EXPECT_EQ(reader.packets(), 4u);
    }
  }
  // A recording that was never closed has no data table: the packets run to the file's end.
  Aedat4EventReader unclosed(dir / "test_no_table.aedat4");
  EXPECT_EQ(ReadAllEvents(&unclosed, 4096), expected);
}

TEST(Aedat4Reader, DecodesFramesImuSamplesAndTriggersLikeTheWriter) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  const auto expected_frames = testing::ReadExpectedLines(dir, "frames");
  const auto expected_imu = testing::ReadExpectedLines(dir, "imu");
  const auto expected_triggers = testing::ReadExpectedLines(dir, "triggers");
  for (const char* compression : kCompressions) {
    Aedat4Reader file(dir / FileOf(compression));
    file.SetStreams({1, 2, 3});
    std::vector<Aedat4Frame> frames;
    std::vector<Aedat4ImuSample> imu;
    std::vector<Aedat4Trigger> triggers;
    Aedat4Packet packet;
    while (file.Next(&packet)) {
      ASSERT_NE(packet.stream->type, "EVTS");
      if (packet.stream->type == "FRME") frames.push_back(DecodeAedat4Frame(packet, "t"));
      if (packet.stream->type == "IMUS") DecodeAedat4Imu(packet, "t", &imu);
      if (packet.stream->type == "TRIG") DecodeAedat4Triggers(packet, "t", &triggers);
    }
    ASSERT_EQ(frames.size(), expected_frames.size()) << compression;
    for (size_t i = 0; i < frames.size(); ++i) {
      const auto& line = expected_frames[i];
      EXPECT_EQ(frames[i].t_ns, std::stoll(line[0]));
      EXPECT_EQ(frames[i].width, std::stoi(line[1]));
      EXPECT_EQ(frames[i].height, std::stoi(line[2]));
      EXPECT_EQ(frames[i].channels, std::stoi(line[3]));
      EXPECT_EQ(frames[i].exposure_end_ns - frames[i].exposure_begin_ns, 500000);
      EXPECT_EQ(std::accumulate(frames[i].pixels.begin(), frames[i].pixels.end(), int64_t{0}),
                std::stoll(line[4]));
    }
    ASSERT_EQ(imu.size(), expected_imu.size()) << compression;
    for (size_t i = 0; i < imu.size(); ++i) {
      const auto& line = expected_imu[i];
      EXPECT_EQ(imu[i].t_ns, std::stoll(line[0]));
      EXPECT_FLOAT_EQ(imu[i].temperature_c, std::stof(line[1]));
      EXPECT_FLOAT_EQ(imu[i].accelerometer_g[0], std::stof(line[2]));
      EXPECT_FLOAT_EQ(imu[i].gyroscope_dps[2], std::stof(line[7]));
      EXPECT_FLOAT_EQ(imu[i].magnetometer_ut[2], std::stof(line[10]));
    }
    ASSERT_EQ(triggers.size(), expected_triggers.size()) << compression;
    for (size_t i = 0; i < triggers.size(); ++i) {
      EXPECT_EQ(triggers[i].t_ns, std::stoll(expected_triggers[i][0]));
      EXPECT_EQ(triggers[i].type, std::stoi(expected_triggers[i][1]));
    }
  }
}

TEST(Aedat4EventReader, OpenEventFileDetectsAedat4AndReadsTheEventsStream) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  EXPECT_EQ(DetectEventFileFormat(dir / "test_zstd.aedat4"), EventFileFormat::kAedat4);
  EXPECT_TRUE(IsAedat4File(dir / "test_zstd.aedat4"));
  EXPECT_FALSE(IsAedat4File(dir / "expected_events.txt"));
  const auto reader = OpenEventFile(dir / "test_zstd.aedat4");
  EXPECT_EQ(ReadAllEvents(reader.get(), 500), testing::ReadExpectedEvents(dir, "events"));
  // The stream may be named by its id too.
  Aedat4EventOptions options;
  options.stream = "0";
  Aedat4EventReader by_id(dir / "test_none.aedat4", options);
  EXPECT_EQ(ReadAllEvents(&by_id, 500).size(), testing::ReadExpectedEvents(dir, "events").size());
}

TEST(Aedat4EventReader, AMissingOrNonEventStreamIsAnErrorListingTheStreams) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  for (const char* stream : {"dvs", "frames"}) {
    Aedat4EventOptions options;
    options.stream = stream;
    try {
      Aedat4EventReader reader(dir / "test_lz4.aedat4", options);
      FAIL() << "expected an InvalidArgumentError for " << stream;
    } catch (const InvalidArgumentError& error) {
      const std::string message = error.what();
      EXPECT_NE(message.find("events (id 0, EVTS), frames (id 1, FRME)"), std::string::npos)
          << message;
    }
  }
  Aedat4EventOptions empty;
  empty.stream = "";
  EXPECT_THROW(empty.Check(), InvalidArgumentError);
}

TEST(Aedat4EventReader, ATruncatedFileIsAParseErrorNamingTheByteOffset) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  for (const char* name :
       {"test_none.aedat4", "test_lz4.aedat4", "test_zstd.aedat4", "test_no_table.aedat4"}) {
    const std::string bytes = ReadBytes(dir / name);
    // Every cut, several hundred of them: never a crash, always a ParseError with a byte offset.
    for (size_t length = 0; length < bytes.size(); length += 997) {
      const std::string error = ParseErrorOf(bytes.substr(0, length));
      ASSERT_NE(error.find("cut.aedat4: byte "), std::string::npos)
          << name << " cut at " << length << ": " << error;
    }
  }
  // A file whose data table was cut short, or cut off (its position is then beyond the end).
  const std::string closed = ReadBytes(dir / "test_lz4.aedat4");
  std::string error = ParseErrorOf(closed.substr(0, closed.size() - 10));
  EXPECT_NE(error.find("expected a valid lz4 file data table"), std::string::npos) << error;
  const std::string plain = ReadBytes(dir / "test_none.aedat4");
  error = ParseErrorOf(plain.substr(0, plain.size() - 10));
  EXPECT_NE(error.find("the file data table (the packet index): expected a size-prefixed "
                       "FileDataTable"),
            std::string::npos)
      << error;
  uint32_t header_size;
  std::memcpy(&header_size, plain.data() + 14, 4);
  error = ParseErrorOf(plain.substr(0, 18 + header_size + 100));
  EXPECT_NE(error.find("is outside the packets"), std::string::npos) << error;
  // An unclosed file cut inside a packet.
  const std::string open = ReadBytes(dir / "test_no_table.aedat4");
  error = ParseErrorOf(open.substr(0, open.size() - 10));
  EXPECT_NE(error.find("truncated: the packet declares"), std::string::npos) << error;
  EXPECT_NE(ParseErrorOf("#!AER-DAT3.1\r\n").find("only AEDAT 4.0"), std::string::npos);
  EXPECT_NE(ParseErrorOf("not an aedat file").find("byte 0: expected the AEDAT 4.0 magic"),
            std::string::npos);
}

// The file offset of the first packet (after the magic, the header length and the header).
size_t FirstPacket(const std::string& bytes) {
  uint32_t header_size;
  std::memcpy(&header_size, bytes.data() + 14, 4);
  return 18 + header_size;
}

TEST(Aedat4EventReader, CorruptPacketsAreParseErrorsSayingWhatWasExpected) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  const std::string none = ReadBytes(dir / "test_none.aedat4");
  const size_t first = FirstPacket(none);
  {
    std::string bytes = none;
    bytes[first] = 9;  // a stream id the header does not describe
    const std::string error = ParseErrorOf(bytes);
    EXPECT_NE(error.find("byte " + std::to_string(first) + ": packet of stream id 9"),
              std::string::npos)
        << error;
    EXPECT_NE(error.find("its streams: events (id 0, EVTS)"), std::string::npos) << error;
  }
  {
    std::string bytes = none;
    const int32_t negative = -5;
    std::memcpy(bytes.data() + first + 4, &negative, 4);
    EXPECT_NE(ParseErrorOf(bytes).find("expected a packet size of 1.."), std::string::npos);
  }
  {
    std::string bytes = none;
    std::memcpy(bytes.data() + first + 8 + 8, "FRME", 4);  // the identifier of another type
    const std::string error = ParseErrorOf(bytes);
    EXPECT_NE(error.find("expected the file identifier EVTS, found 'FRME'"), std::string::npos)
        << error;
  }
  {
    std::string bytes = none;
    // The root offset of the first packet's flatbuffer, pointing far outside it.
    const uint32_t wild = 0x7ffffff0;
    std::memcpy(bytes.data() + first + 8 + 4, &wild, 4);
    const std::string error = ParseErrorOf(bytes);
    EXPECT_NE(error.find("the flatbuffers verifier rejected it"), std::string::npos) << error;
  }
  for (const char* compression : {"lz4", "zstd"}) {
    std::string bytes = ReadBytes(dir / FileOf(compression));
    const size_t packet = FirstPacket(bytes);
    for (size_t i = 0; i < 64; ++i) bytes[packet + 8 + 40 + i] ^= 0x5a;
    const std::string error = ParseErrorOf(bytes);
    EXPECT_NE(error.find("cut.aedat4: byte "), std::string::npos) << compression << ": " << error;
  }
}

// The summary lines of summarize_aedat4.py (core/events/testing) of what evloc's reader reads
// in `path`: packets per stream, then per stream type the events (count, ON events, events
// outside the sensor, first and last time, sums of time since the first, x and y), the IMU
// samples (count, first and last time) and the triggers (count).
std::string SummaryOf(const std::filesystem::path& path) {
  Aedat4Reader file(path);
  Aedat4Packet packet;
  std::map<int32_t, int> packets;
  for (const Aedat4Stream& stream : file.streams()) packets[stream.id] = 0;
  std::map<int32_t, EventBuffer> events;
  std::map<int32_t, uint64_t> outside;
  std::map<int32_t, std::vector<Aedat4ImuSample>> imu;
  std::map<int32_t, std::vector<Aedat4Trigger>> triggers;
  while (file.Next(&packet)) {
    const int32_t id = packet.stream->id;
    ++packets[id];
    if (packet.stream->type == "EVTS") {
      DecodeAedat4Events(packet, file.source(), packet.stream->size, &events[id], &outside[id]);
    } else if (packet.stream->type == "IMUS") {
      DecodeAedat4Imu(packet, file.source(), &imu[id]);
    } else if (packet.stream->type == "TRIG") {
      DecodeAedat4Triggers(packet, file.source(), &triggers[id]);
    }
  }
  std::ostringstream out;
  for (const auto& [id, count] : packets) {
    out << "stream " << id << " " << file.FindStream(std::to_string(id))->type << " packets "
        << count << "\n";
  }
  for (const auto& [id, buffer] : events) {
    if (buffer.empty()) continue;
    const int64_t first_us = buffer.t_ns.front() / 1000;
    int64_t on = 0, sum_dt = 0, sum_x = 0, sum_y = 0;
    for (size_t i = 0; i < buffer.size(); ++i) {
      on += buffer.polarity[i] > 0;
      sum_dt += buffer.t_ns[i] / 1000 - first_us;
      sum_x += buffer.x[i];
      sum_y += buffer.y[i];
    }
    out << "events " << id << " count " << buffer.size() << " on " << on << " outside "
        << outside[id] << " t_first_us " << first_us << " t_last_us " << buffer.t_ns.back() / 1000
        << " sum_dt_us " << sum_dt << " sum_x " << sum_x << " sum_y " << sum_y << "\n";
  }
  for (const auto& [id, samples] : imu) {
    if (samples.empty()) continue;
    out << "imu " << id << " count " << samples.size() << " t_first_us "
        << samples.front().t_ns / 1000 << " t_last_us " << samples.back().t_ns / 1000 << "\n";
  }
  for (const auto& [id, list] : triggers) {
    if (!list.empty()) out << "triggers " << id << " count " << list.size() << "\n";
  }
  return out.str();
}

// A real recording, written by iniVation's DV with a DVXplorer (core/events/testdata/README.md:
// its source and licence): evloc's reader reads what an independent reader of the format
// (summarize_aedat4.py) read in it, and the independent reader, when /usr/bin/python3 has its
// packages, still reads the summary that is checked in.
TEST(Aedat4Reader, ReadsARealDvxplorerRecordingAsAnIndependentReaderDoes) {
  const std::filesystem::path folder = testing::SourceDir() / "core/events/testdata";
  const std::filesystem::path file = folder / "dvxplorer_sample.aedat4";
  const std::string expected = ReadBytes(folder / "dvxplorer_sample.summary.txt");
  ASSERT_NE(expected.find("events 0 count 111954 "), std::string::npos) << expected;
  EXPECT_EQ(SummaryOf(file), expected);

  Aedat4Reader reader(file);
  const Aedat4Stream* events = reader.FindStream("events");
  ASSERT_NE(events, nullptr);
  ASSERT_TRUE(events->size.has_value());
  EXPECT_EQ(events->size->width, 320);
  EXPECT_EQ(events->size->height, 240);
  EXPECT_EQ(events->camera, "DVXplorer_DXB00010");

  std::string output;
  if (testing::RunShellCommand(
          "/usr/bin/python3 -c 'import flatbuffers, lz4.frame, zstandard' 2>&1", &output) != 0) {
    GTEST_SKIP()
        << "the independent reader was not run: /usr/bin/python3 lacks python3-flatbuffers, "
           "python3-lz4 or python3-zstandard: "
        << output;
  }
  output.clear();
  ASSERT_EQ(testing::RunShellCommand(
                "/usr/bin/python3 '" +
                    (testing::SourceDir() / "core/events/testing/summarize_aedat4.py").string() +
                    "' '" + file.string() + "' 2>&1",
                &output),
            0)
      << output;
  EXPECT_EQ(output, expected);
}

// Real DV recordings, when someone puts them in the shared data folder (one is in the
// repository: the test above): every packet of every stream decodes, events lie inside the
// stated sensor and their times never decrease within a stream.
TEST(Aedat4Reader, ReadsRealRecordingsOfTheSharedData) {
  EVLOC_REQUIRE_SHARED_DATA(folder, "aedat4");
  size_t files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    if (entry.path().extension() != ".aedat4") continue;
    ++files;
    Aedat4Reader file(entry.path());
    Aedat4Packet packet;
    std::map<int32_t, int64_t> last_t;
    uint64_t events = 0;
    while (file.Next(&packet)) {
      if (packet.stream->type == "EVTS") {
        EventBuffer buffer;
        uint64_t dropped = 0;
        DecodeAedat4Events(packet, file.source(), packet.stream->size, &buffer, &dropped);
        EXPECT_EQ(dropped, 0u) << entry.path();
        for (size_t i = 0; i < buffer.size(); ++i) {
          ASSERT_GE(buffer.t_ns[i], last_t[packet.stream->id]) << entry.path();
          last_t[packet.stream->id] = buffer.t_ns[i];
        }
        events += buffer.size();
      } else if (packet.stream->type == "FRME") {
        EXPECT_FALSE(DecodeAedat4Frame(packet, file.source()).pixels.empty());
      }
    }
    EXPECT_GT(events, 0u) << entry.path() << " has no events";
  }
  if (files == 0) GTEST_SKIP() << folder << " holds no .aedat4 file";
}

TEST(Aedat4Xml, ParsesDvDescriptionsWithEntitiesCommentsAndCdata) {
  const auto root = aedat4_xml::Parse(
      "<?xml version=\"1.0\"?>\n<!-- c --><dv version='2.0'><node name=\"outInfo\">"
      "<attr key=\"a\">x &amp; &lt;y&gt; &#65;&#x42;</attr><![CDATA[<raw>]]><empty/>"
      "</node></dv>\n");
  EXPECT_EQ(root->name, "dv");
  ASSERT_NE(root->Attribute("version"), nullptr);
  EXPECT_EQ(*root->Attribute("version"), "2.0");
  const aedat4_xml::Element* node = root->Child("node", "name", "outInfo");
  ASSERT_NE(node, nullptr);
  ASSERT_NE(node->Child("attr", "key", "a"), nullptr);
  EXPECT_EQ(node->Child("attr", "key", "a")->text, "x & <y> AB");
  EXPECT_EQ(node->text, "<raw>");
  EXPECT_EQ(node->children.size(), 2u);
}

TEST(Aedat4Xml, MalformedTextNamesTheOffsetAndWhatWasExpected) {
  const auto error_of = [](const std::string& text) {
    try {
      aedat4_xml::Parse(text);
    } catch (const aedat4_xml::XmlError& error) {
      return std::to_string(error.offset) + ": " + error.what;
    }
    return std::string("no error");
  };
  EXPECT_EQ(error_of("<a><b></a>"), "6: expected the end tag '</b>', found '</a>'");
  EXPECT_EQ(error_of("<a x=1/>"), "5: expected a quoted value of attribute 'x'");
  EXPECT_EQ(error_of("<a>&bogus;</a>"),
            "3: unknown entity '&bogus;' (expected lt, gt, amp, quot, apos or &#N;)");
  EXPECT_EQ(error_of("<a></a><b/>"), "7: expected the end of the document after the root element");
  EXPECT_EQ(error_of("<a>"), "3: expected the end tag '</a>'");
  std::string deep;
  for (int i = 0; i < 100; ++i) deep += "<n>";
  EXPECT_NE(error_of(deep).find("nested deeper than 64"), std::string::npos);
}

}  // namespace
}  // namespace evloc
