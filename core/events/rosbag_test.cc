#include "core/events/rosbag.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <sstream>

#include "core/common/error.h"
#include "core/events/event_reader.h"
#include "core/events/rosbag_events.h"
#include "core/events/testing/test_bags.h"

namespace evloc {
namespace {

using testing::ReadAllEvents;
using testing::ReadBytes;
using testing::StreamOf;

std::string ParseErrorOf(const std::string& bytes, const std::string& topic) {
  try {
    RosbagEventOptions options;
    options.topic = topic;
    RosbagEventReader reader(StreamOf(bytes), "cut.bag", options);
    ReadAllEvents(&reader, 1000);
  } catch (const ParseError& error) {
    return error.what();
  }
  return "";
}

TEST(RosbagReader, ListsTheTopicsOfBagsWrittenByPythonRosbag) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  for (const char* compression : {"none", "bz2", "lz4"}) {
    const RosbagReader bag(dir / (std::string("test_") + compression + ".bag"));
    EXPECT_TRUE(bag.indexed());
    EXPECT_EQ(bag.DescribeTopics(),
              "/dvs/camera_info (sensor_msgs/CameraInfo), /dvs/events (dvs_msgs/EventArray), "
              "/dvs/image_raw (sensor_msgs/Image), /optitrack/davis (geometry_msgs/PoseStamped), "
              "/packets/evt3 (event_camera_msgs/EventPacket), /packets/mono "
              "(event_camera_msgs/EventPacket), /prophesee/events "
              "(prophesee_event_msgs/EventArray)")
        << compression;
    ASSERT_EQ(bag.ConnectionsOf("/dvs/events").size(), 1u);
    EXPECT_EQ(bag.ConnectionsOf("/dvs/events")[0]->md5sum.size(), 32u);
    EXPECT_NE(bag.ConnectionsOf("/dvs/events")[0]->message_definition.find("Event[] events"),
              std::string::npos);
  }
}

TEST(RosbagReader, StreamsEveryMessageOfATopicInOrderWithItsRecordTime) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  for (const char* compression : {"none", "bz2", "lz4"}) {
    RosbagReader bag(dir / (std::string("test_") + compression + ".bag"));
    bag.SetTopics({"/optitrack/davis"});
    const auto poses = testing::ReadExpectedLines(dir, "poses");
    RosbagMessage message;
    size_t count = 0;
    while (bag.Next(&message)) {
      ASSERT_LT(count, poses.size());
      EXPECT_EQ(message.connection->topic, "/optitrack/davis");
      EXPECT_EQ(message.record_t_ns, std::stoll(poses[count][0]));
      // Header (4 + 8 + 4 + "davis") + 7 float64.
      EXPECT_EQ(message.size, 4 + 8 + 4 + 5 + 7 * 8u);
      ++count;
    }
    EXPECT_EQ(count, poses.size()) << compression;
  }
}

TEST(RosbagEventReader, ReadsDvsEventArraysOfEveryCompressionExactly) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  const EventBuffer expected = testing::ReadExpectedEvents(dir, "dvs");
  ASSERT_GT(expected.size(), 1000u);
  for (const char* compression : {"none", "bz2", "lz4"}) {
    RosbagEventReader reader(dir / (std::string("test_") + compression + ".bag"));
    EXPECT_EQ(reader.sensor_size(), (SensorSize{240, 180}));
    for (size_t batch : {size_t{1}, size_t{77}, size_t{1} << 20}) {
      RosbagEventReader fresh(dir / (std::string("test_") + compression + ".bag"));
      EXPECT_EQ(ReadAllEvents(&fresh, batch), expected) << compression << " batch " << batch;
      EXPECT_EQ(fresh.dropped_event_count(), 0u);
      // 12 messages, one of them empty.
      EXPECT_EQ(fresh.messages(), 12u);
    }
  }
}

TEST(RosbagEventReader, ReadsPropheseeArraysAndMonoAndEvt3EventPackets) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  const struct {
    const char* topic;
    const char* expected;
    SensorSize size;
  } cases[] = {{"/prophesee/events", "prophesee", {640, 480}},
               {"/packets/mono", "mono", {1280, 720}},
               {"/packets/evt3", "evt3", {1280, 720}}};
  for (const auto& test : cases) {
    for (const char* compression : {"none", "lz4"}) {
      RosbagEventOptions options;
      options.topic = test.topic;
      RosbagEventReader reader(dir / (std::string("test_") + compression + ".bag"), options);
      EXPECT_EQ(reader.sensor_size(), test.size);
      EXPECT_EQ(ReadAllEvents(&reader, 100), testing::ReadExpectedEvents(dir, test.expected))
          << test.topic << " " << compression;
    }
  }
}

TEST(RosbagEventReader, OpenEventFileDetectsBagsAndReadsTheDefaultTopic) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  EXPECT_EQ(DetectEventFileFormat(dir / "test_bz2.bag"), EventFileFormat::kRosbag);
  EXPECT_STREQ(EventFileFormatName(EventFileFormat::kRosbag), "ROS1 bag");
  const auto reader = OpenEventFile(dir / "test_bz2.bag");
  EXPECT_EQ(ReadAllEvents(reader.get(), 500), testing::ReadExpectedEvents(dir, "dvs"));
}

TEST(RosbagEventReader, AMissingOrNonEventTopicIsAnErrorListingTheTopics) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  RosbagEventOptions options;
  options.topic = "/davis/left/events";
  try {
    RosbagEventReader reader(dir / "test_none.bag", options);
    FAIL() << "a missing topic was accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("no topic '/davis/left/events'"), std::string::npos);
    EXPECT_NE(std::string(error.what()).find("/dvs/events (dvs_msgs/EventArray)"),
              std::string::npos)
        << error.what();
  }
  options.topic = "/dvs/image_raw";
  EXPECT_THROW(RosbagEventReader(dir / "test_none.bag", options), InvalidArgumentError);
  options.topic = "";
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

TEST(RosbagEventReader, ATruncatedBagIsAParseErrorNamingTheByteOffset) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  for (const char* compression : {"none", "bz2", "lz4"}) {
    const std::string bytes = ReadBytes(dir / (std::string("test_") + compression + ".bag"));
    // Every cut, a few hundred of them: never a crash, always a ParseError with a byte offset.
    for (size_t length = 0; length < bytes.size(); length += 997) {
      const std::string error = ParseErrorOf(bytes.substr(0, length), "/dvs/events");
      ASSERT_NE(error.find("cut.bag: byte "), std::string::npos)
          << compression << " cut at " << length << ": " << error;
    }
    const std::string error = ParseErrorOf(bytes.substr(0, bytes.size() - 10), "/dvs/events");
    EXPECT_NE(error.find("truncated"), std::string::npos) << error;
  }
  EXPECT_NE(ParseErrorOf("#ROSBAG V1.2\n", "/dvs/events").find("only ROS bag format 2.0"),
            std::string::npos);
  EXPECT_NE(ParseErrorOf("not a bag", "/dvs/events").find("byte 0: expected the ROS bag magic"),
            std::string::npos);
}

// Finds the (first) header field `name=` in `bytes` and returns the offset of its value.
size_t FieldValue(const std::string& bytes, const std::string& name, size_t from = 0) {
  const size_t at = bytes.find(name + "=", from);
  EXPECT_NE(at, std::string::npos) << name;
  return at + name.size() + 1;
}

TEST(RosbagEventReader, AnUnindexedBagIsReadByScanningItsChunks) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  for (const char* compression : {"none", "lz4"}) {
    std::string bytes = ReadBytes(dir / (std::string("test_") + compression + ".bag"));
    // rosbag record leaves index_pos 0 until it closes the bag; cut the index off too.
    const size_t index_pos = FieldValue(bytes, "index_pos");
    uint64_t index_start = 0;
    std::memcpy(&index_start, bytes.data() + index_pos, 8);
    bytes.resize(index_start);
    std::memset(bytes.data() + index_pos, 0, 8);
    RosbagEventReader reader(StreamOf(bytes), "active.bag");
    EXPECT_FALSE(reader.bag().indexed());
    EXPECT_EQ(ReadAllEvents(&reader, 4096), testing::ReadExpectedEvents(dir, "dvs")) << compression;
  }
}

TEST(RosbagEventReader, CorruptChunksAndMessagesAreParseErrorsSayingWhatWasExpected) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  {
    std::string bytes = ReadBytes(dir / "test_lz4.bag");
    const size_t compression = FieldValue(bytes, "compression");
    bytes.replace(compression, 3, "zst");
    const std::string error = ParseErrorOf(bytes, "/dvs/events");
    EXPECT_NE(error.find("unknown chunk compression 'zst' (expected none, bz2 or lz4)"),
              std::string::npos)
        << error;
  }
  {
    // A flipped byte inside the compressed data of the first chunk.
    std::string bytes = ReadBytes(dir / "test_bz2.bag");
    const size_t data = FieldValue(bytes, "compression") + 200;
    bytes[data] = static_cast<char>(bytes[data] ^ 0x5a);
    const std::string error = ParseErrorOf(bytes, "/dvs/events");
    EXPECT_NE(error.find("corrupt bz2 chunk"), std::string::npos) << error;
  }
  {
    // The event count of the first EventArray made larger than the message: the error names
    // the count and the bytes left, at the count's file offset (uncompressed bag).
    std::string bytes = ReadBytes(dir / "test_none.bag");
    RosbagReader bag(StreamOf(bytes), "a.bag");
    bag.SetTopics({"/dvs/events"});
    RosbagMessage message;
    ASSERT_TRUE(bag.Next(&message));
    ASSERT_FALSE(message.compressed_chunk);
    const uint64_t count_offset =
        message.chunk_file_offset + message.offset_in_chunk + 4 + 8 + 4 + 5 + 4 + 4;
    bytes[count_offset + 3] = 0x10;
    const std::string error = ParseErrorOf(bytes, "/dvs/events");
    EXPECT_NE(error.find("cut.bag: byte " + std::to_string(count_offset) +
                         ": dvs_msgs/EventArray on /dvs/events: expected events of"),
              std::string::npos)
        << error;
  }
}

}  // namespace
}  // namespace evloc
