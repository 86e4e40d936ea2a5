// ROS1 bag files (format 2.0; uncompressed, bz2 and lz4 chunks), read as a stream of messages
// chunk by chunk, and the little-endian reader of ROS serialization the message decoders use
// (docs/event-formats.md, section 7).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <istream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace evloc {

// One connection (a topic with its message type) of a bag.
struct RosbagConnection {
  // The connection id the message records refer to.
  uint32_t id = 0;
  // Topic name, e.g. "/dvs/events".
  std::string topic;
  // Message type, e.g. "dvs_msgs/EventArray".
  std::string type;
  // MD5 sum of the message definition (as written by the recorder).
  std::string md5sum;
  // Full message definition text (may be empty in hand-written bags).
  std::string message_definition;
};

// A message of a bag. `data` points into the reader's chunk buffer and stays valid until the
// next call of RosbagReader::Next().
struct RosbagMessage {
  // The message's connection.
  const RosbagConnection* connection = nullptr;
  // The record time (when the recorder received it), nanoseconds.
  int64_t record_t_ns = 0;
  // The serialized message.
  const uint8_t* data = nullptr;
  // Its size in bytes.
  size_t size = 0;
  // Where the serialized message starts, for error messages: "byte N" for an uncompressed bag,
  // "byte N of the bz2 chunk at byte M" inside a compressed chunk. Computed on demand.
  uint64_t chunk_file_offset = 0;
  // Offset of `data` in the chunk's uncompressed bytes.
  uint64_t offset_in_chunk = 0;
  // True when the chunk was compressed (offsets are then in the uncompressed bytes).
  bool compressed_chunk = false;
};

// Names a position in a bag for ParseError: the file byte for uncompressed chunks, else the byte
// of the uncompressed chunk and the chunk's file byte.
std::string RosbagPosition(const RosbagMessage& message, uint64_t offset_in_message);

// True when `path` starts with the bag 2.0 magic line "#ROSBAG V2.0\n". Throws IoError when it
// cannot be read.
bool IsRosbagFile(const std::filesystem::path& path);

// Streams the messages of a ROS1 bag (format 2.0) in file order, one chunk in memory at a time.
// Every malformed or truncated structure is a ParseError naming the source, the byte offset and
// what was expected.
class RosbagReader {
 public:
  // Largest uncompressed chunk accepted (rosbag writes 768 KiB chunks by default).
  static constexpr uint64_t kMaxChunkBytes = uint64_t{256} << 20;

  // Opens `path`; reads the bag header and the connection index at its end (or, for a bag
  // without index, e.g. a recording that was interrupted, scans the chunks for connections).
  // Throws IoError when it cannot be opened, ParseError when it is not a valid bag.
  explicit RosbagReader(const std::filesystem::path& path);
  // Reads from a seekable `stream`; `source` names it in error messages.
  RosbagReader(std::unique_ptr<std::istream> stream, std::string source);
  ~RosbagReader();
  RosbagReader(const RosbagReader&) = delete;
  RosbagReader& operator=(const RosbagReader&) = delete;

  // Every connection of the bag (one per topic in bags written by rosbag).
  const std::vector<RosbagConnection>& connections() const { return connections_; }
  // The distinct topics with their types, "topic (type)", sorted, for error messages.
  std::string DescribeTopics() const;
  // The connections on `topic`.
  std::vector<const RosbagConnection*> ConnectionsOf(const std::string& topic) const;
  // True when the bag has an index (written by a cleanly closed recorder).
  bool indexed() const { return indexed_; }
  // The source name used in errors.
  const std::string& source() const { return source_; }

  // Restricts Next() to messages on these topics (empty: all topics). Call before Next().
  void SetTopics(const std::vector<std::string>& topics);
  // Reads the next message on the selected topics; false at the end of the bag.
  bool Next(RosbagMessage* message);

 private:
  struct Record;
  void Open();
  // Reads a record header and the data length at file offset `offset`.
  bool ReadRecordHeaderAt(uint64_t offset, Record* record);
  // Loads the chunk whose record starts at `position_`; false at the end.
  bool LoadNextChunk();
  void ScanForConnections();
  void AddConnection(uint32_t id, const std::string& topic, const uint8_t* data, size_t size,
                     const std::string& position);

  std::unique_ptr<std::istream> stream_;
  std::string source_;
  uint64_t file_size_ = 0;
  uint64_t index_position_ = 0;
  bool indexed_ = false;
  std::vector<RosbagConnection> connections_;
  // Selection by connection id (index into connections_), -1 = not selected.
  std::vector<int> selected_;
  bool select_all_ = true;
  // File position of the next top-level record.
  uint64_t position_ = 0;
  // The current chunk's uncompressed bytes and the cursor in them.
  std::vector<uint8_t> chunk_;
  std::vector<uint8_t> compressed_;
  size_t chunk_size_ = 0;
  size_t chunk_cursor_ = 0;
  uint64_t chunk_file_offset_ = 0;
  uint64_t chunk_data_file_offset_ = 0;
  bool chunk_compressed_ = false;
  std::string chunk_compression_;
  bool in_chunk_ = false;
};

// A bounds-checked little-endian cursor over a serialized ROS message. Every read past the end
// throws ParseError naming the message's position and the field that was expected.
class RosMessageCursor {
 public:
  RosMessageCursor(const RosbagMessage& message, std::string source)
      : message_(message), source_(std::move(source)) {}

  uint8_t U8(const char* field) { return Fixed<uint8_t>(field); }
  uint16_t U16(const char* field) { return Fixed<uint16_t>(field); }
  uint32_t U32(const char* field) { return Fixed<uint32_t>(field); }
  uint64_t U64(const char* field) { return Fixed<uint64_t>(field); }
  double F64(const char* field) { return Fixed<double>(field); }
  // A ROS time or duration (uint32 seconds, uint32 nanoseconds) in nanoseconds.
  int64_t Time(const char* field);
  // A string: uint32 length, bytes.
  std::string String(const char* field);
  // A uint32 array length, checked against the bytes left for `element_size`-byte elements.
  uint32_t ArrayLength(const char* field, size_t element_size);
  // Skips a std_msgs/Header (seq, stamp, frame_id) and returns its stamp in nanoseconds.
  int64_t Header();
  // The current position and the bytes left.
  const uint8_t* here() const { return message_.data + offset_; }
  size_t remaining() const { return message_.size - offset_; }
  size_t offset() const { return offset_; }
  // Advances by `bytes` (already checked with Require).
  void Skip(size_t bytes) { offset_ += bytes; }
  // Throws ParseError unless `bytes` more bytes are present.
  void Require(size_t bytes, const char* field) const;
  // Throws ParseError at the current position with `what`.
  [[noreturn]] void Fail(const std::string& what) const;

 private:
  template <typename T>
  T Fixed(const char* field);

  const RosbagMessage& message_;
  std::string source_;
  size_t offset_ = 0;
};

}  // namespace evloc
