#include "core/events/rosbag.h"

#include <bzlib.h>
#include <lz4frame.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <set>
#include <string_view>

#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc {
namespace {

constexpr char kMagic[] = "#ROSBAG V2.0\n";
constexpr size_t kMagicSize = 13;
// Record headers are small (a connection record's carries the message definition, a few KiB).
constexpr uint32_t kMaxHeaderBytes = 1u << 24;

constexpr uint8_t kOpMessageData = 0x02;
constexpr uint8_t kOpBagHeader = 0x03;
constexpr uint8_t kOpIndexData = 0x04;
constexpr uint8_t kOpChunk = 0x05;
constexpr uint8_t kOpChunkInfo = 0x06;
constexpr uint8_t kOpConnection = 0x07;

uint32_t LoadU32(const uint8_t* p) {
  uint32_t value;
  std::memcpy(&value, p, 4);
  return value;
}

// The `name=value` fields of a record header.
struct Fields {
  std::vector<std::pair<std::string_view, std::string_view>> items;

  const std::string_view* Find(std::string_view name) const {
    for (const auto& item : items) {
      if (item.first == name) return &item.second;
    }
    return nullptr;
  }
};

// Parses `size` header bytes; `fail(offset, what)` throws with the offset inside the header.
template <typename Fail>
Fields ParseFields(const uint8_t* data, size_t size, const Fail& fail) {
  Fields fields;
  size_t offset = 0;
  while (offset < size) {
    if (size - offset < 4) fail(offset, "expected a 4-byte header field length");
    const uint32_t length = LoadU32(data + offset);
    if (length > size - offset - 4) {
      fail(offset, "header field length " + std::to_string(length) + " runs past the header's " +
                       std::to_string(size) + " bytes");
    }
    const std::string_view field(reinterpret_cast<const char*>(data + offset + 4), length);
    const size_t equals = field.find('=');
    if (equals == std::string_view::npos) fail(offset, "expected a `name=value` header field");
    fields.items.emplace_back(field.substr(0, equals), field.substr(equals + 1));
    offset += 4 + length;
  }
  return fields;
}

template <typename Fail>
uint8_t OpOf(const Fields& fields, const Fail& fail) {
  const std::string_view* op = fields.Find("op");
  if (op == nullptr || op->size() != 1) fail(0, "expected a one-byte `op` field in the header");
  return static_cast<uint8_t>((*op)[0]);
}

template <typename Fail>
uint64_t IntegerField(const Fields& fields, std::string_view name, size_t bytes, const Fail& fail) {
  const std::string_view* value = fields.Find(name);
  if (value == nullptr || value->size() != bytes) {
    fail(0, "expected a " + std::to_string(bytes) + "-byte `" + std::string(name) + "` field");
  }
  uint64_t result = 0;
  std::memcpy(&result, value->data(), bytes);
  return result;
}

template <typename Fail>
std::string StringField(const Fields& fields, std::string_view name, const Fail& fail) {
  const std::string_view* value = fields.Find(name);
  if (value == nullptr) fail(0, "expected a `" + std::string(name) + "` field");
  return std::string(*value);
}

}  // namespace

struct RosbagReader::Record {
  uint64_t offset = 0;
  std::vector<uint8_t> header;
  Fields fields;
  uint8_t op = 0;
  uint64_t data_offset = 0;
  uint32_t data_size = 0;
};

std::string RosbagPosition(const RosbagMessage& message, uint64_t offset_in_message) {
  const uint64_t in_chunk = message.offset_in_chunk + offset_in_message;
  if (!message.compressed_chunk)
    return "byte " + std::to_string(message.chunk_file_offset + in_chunk);
  return "byte " + std::to_string(in_chunk) + " of the uncompressed chunk at byte " +
         std::to_string(message.chunk_file_offset);
}

bool IsRosbagFile(const std::filesystem::path& path) {
  return FileStartsWith(path, std::string_view(kMagic, kMagicSize));
}

RosbagReader::RosbagReader(const std::filesystem::path& path)
    : RosbagReader(OpenInputFile(path), path.string()) {}

RosbagReader::RosbagReader(std::unique_ptr<std::istream> stream, std::string source)
    : stream_(std::move(stream)), source_(std::move(source)) {
  Open();
}

RosbagReader::~RosbagReader() = default;

bool RosbagReader::ReadRecordHeaderAt(uint64_t offset, Record* record) {
  if (offset == file_size_) return false;
  const auto fail = [&](uint64_t at, const std::string& what) -> void {
    throw ParseError::AtByte(source_, at, what);
  };
  if (file_size_ - offset < 4) {
    fail(offset, "truncated: expected a 4-byte record header length, the file ends at byte " +
                     std::to_string(file_size_));
  }
  uint8_t length_bytes[4];
  stream_->clear();
  stream_->seekg(static_cast<std::streamoff>(offset));
  stream_->read(reinterpret_cast<char*>(length_bytes), 4);
  if (!*stream_) throw IoError(source_ + ": read failed at byte " + std::to_string(offset));
  const uint32_t header_size = LoadU32(length_bytes);
  if (header_size > kMaxHeaderBytes || header_size > file_size_ - offset - 4) {
    fail(offset, "expected a record header length of at most " +
                     std::to_string(std::min<uint64_t>(kMaxHeaderBytes, file_size_ - offset - 4)) +
                     " bytes, found " + std::to_string(header_size) +
                     (header_size > file_size_ - offset - 4 ? " (truncated file?)" : ""));
  }
  record->offset = offset;
  record->header.resize(header_size);
  stream_->read(reinterpret_cast<char*>(record->header.data()), header_size);
  const uint64_t data_length_offset = offset + 4 + header_size;
  if (file_size_ - data_length_offset < 4) {
    fail(data_length_offset,
         "truncated: expected a 4-byte record data length, the file ends at "
         "byte " +
             std::to_string(file_size_));
  }
  stream_->read(reinterpret_cast<char*>(length_bytes), 4);
  if (!*stream_) throw IoError(source_ + ": read failed at byte " + std::to_string(offset));
  record->data_size = LoadU32(length_bytes);
  record->data_offset = data_length_offset + 4;
  if (record->data_size > file_size_ - record->data_offset) {
    fail(data_length_offset, "truncated: the record at byte " + std::to_string(offset) +
                                 " declares " + std::to_string(record->data_size) +
                                 " data bytes, the file ends at byte " +
                                 std::to_string(file_size_));
  }
  const auto header_fail = [&](uint64_t at, const std::string& what) -> void {
    throw ParseError::AtByte(source_, offset + 4 + at, what);
  };
  record->fields = ParseFields(record->header.data(), record->header.size(), header_fail);
  record->op = OpOf(record->fields, header_fail);
  return true;
}

void RosbagReader::Open() {
  stream_->seekg(0, std::ios::end);
  const std::streamoff end = stream_->tellg();
  if (end < 0) throw IoError(source_ + ": cannot determine the size");
  file_size_ = static_cast<uint64_t>(end);
  stream_->seekg(0);
  char magic[kMagicSize] = {0};
  stream_->read(magic, kMagicSize);
  if (stream_->gcount() != static_cast<std::streamsize>(kMagicSize) ||
      std::memcmp(magic, kMagic, kMagicSize) != 0) {
    const bool other_version = std::memcmp(magic, "#ROSBAG V", 9) == 0;
    throw ParseError::AtByte(source_, 0,
                             other_version ? "only ROS bag format 2.0 is supported (found '" +
                                                 std::string(magic, 12) + "')"
                                           : "expected the ROS bag magic line '#ROSBAG V2.0'");
  }
  Record header;
  if (!ReadRecordHeaderAt(kMagicSize, &header)) {
    throw ParseError::AtByte(source_, kMagicSize,
                             "truncated: expected the bag header record after the magic line");
  }
  const auto fail = [&](uint64_t, const std::string& what) -> void {
    throw ParseError::AtByte(source_, kMagicSize, "bag header record: " + what);
  };
  if (header.op != kOpBagHeader) {
    fail(0, "expected op 0x03 (bag header), found 0x" + std::to_string(header.op));
  }
  index_position_ = IntegerField(header.fields, "index_pos", 8, fail);
  IntegerField(header.fields, "conn_count", 4, fail);
  IntegerField(header.fields, "chunk_count", 4, fail);
  position_ = header.data_offset + header.data_size;
  if (index_position_ != 0 && index_position_ < position_) {
    fail(0, "index_pos " + std::to_string(index_position_) + " points before the first chunk");
  }
  if (index_position_ >= file_size_) {
    throw ParseError::AtByte(source_, file_size_,
                             "truncated: the bag header places the index at byte " +
                                 std::to_string(index_position_) + ", the file ends at byte " +
                                 std::to_string(file_size_));
  }
  // index_pos 0: a recording that was never closed (rosbag's .bag.active); read it unindexed.
  indexed_ = index_position_ != 0;
  if (indexed_) {
    Record record;
    uint64_t offset = index_position_;
    while (ReadRecordHeaderAt(offset, &record)) {
      const auto record_fail = [&](uint64_t, const std::string& what) -> void {
        throw ParseError::AtByte(source_, offset, what);
      };
      if (record.op == kOpConnection) {
        const auto id = static_cast<uint32_t>(IntegerField(record.fields, "conn", 4, record_fail));
        const std::string topic = StringField(record.fields, "topic", record_fail);
        std::vector<uint8_t> data(record.data_size);
        stream_->read(reinterpret_cast<char*>(data.data()), record.data_size);
        AddConnection(id, topic, data.data(), data.size(), "byte " + std::to_string(offset));
      } else if (record.op != kOpChunkInfo) {
        record_fail(0,
                    "expected a connection (op 0x07) or chunk info (op 0x06) record in the "
                    "index, found op " +
                        std::to_string(record.op));
      }
      offset = record.data_offset + record.data_size;
    }
  } else {
    ScanForConnections();
  }
  selected_.assign(connections_.size(), 0);
  SetTopics({});
}

void RosbagReader::AddConnection(uint32_t id, const std::string& topic, const uint8_t* data,
                                 size_t size, const std::string& position) {
  for (const RosbagConnection& connection : connections_) {
    if (connection.id == id) return;
  }
  const auto fail = [&](uint64_t, const std::string& what) -> void {
    throw ParseError(source_, position, "connection " + std::to_string(id) + ": " + what);
  };
  const Fields fields = ParseFields(data, size, fail);
  RosbagConnection connection;
  connection.id = id;
  connection.topic = topic;
  connection.type = StringField(fields, "type", fail);
  connection.md5sum = StringField(fields, "md5sum", fail);
  if (const std::string_view* definition = fields.Find("message_definition")) {
    connection.message_definition = std::string(*definition);
  }
  connections_.push_back(std::move(connection));
}

void RosbagReader::ScanForConnections() {
  // A bag without index: read every chunk once for its connection records.
  select_all_ = false;
  selected_.clear();
  RosbagMessage message;
  while (Next(&message)) {
  }
  position_ = kMagicSize;
  Record header;
  ReadRecordHeaderAt(kMagicSize, &header);
  position_ = header.data_offset + header.data_size;
  in_chunk_ = false;
}

void RosbagReader::SetTopics(const std::vector<std::string>& topics) {
  select_all_ = topics.empty();
  selected_.assign(connections_.size(), 0);
  for (size_t i = 0; i < connections_.size(); ++i) {
    selected_[i] = std::find(topics.begin(), topics.end(), connections_[i].topic) != topics.end();
  }
}

std::vector<const RosbagConnection*> RosbagReader::ConnectionsOf(const std::string& topic) const {
  std::vector<const RosbagConnection*> result;
  for (const RosbagConnection& connection : connections_) {
    if (connection.topic == topic) result.push_back(&connection);
  }
  return result;
}

std::string RosbagReader::DescribeTopics() const {
  std::set<std::string> topics;
  for (const RosbagConnection& connection : connections_) {
    topics.insert(connection.topic + " (" + connection.type + ")");
  }
  if (topics.empty()) return "none";
  std::string text;
  for (const std::string& topic : topics) text += (text.empty() ? "" : ", ") + topic;
  return text;
}

bool RosbagReader::LoadNextChunk() {
  Record record;
  while (ReadRecordHeaderAt(position_, &record)) {
    const uint64_t offset = position_;
    position_ = record.data_offset + record.data_size;
    const auto fail = [&](uint64_t, const std::string& what) -> void {
      throw ParseError::AtByte(source_, offset, what);
    };
    if (record.op == kOpIndexData || record.op == kOpChunkInfo || record.op == kOpConnection) {
      continue;
    }
    if (record.op != kOpChunk) {
      fail(0, "expected a chunk (op 0x05), index data, connection or chunk info record, found op " +
                  std::to_string(record.op));
    }
    const std::string compression = StringField(record.fields, "compression", fail);
    const uint64_t size = IntegerField(record.fields, "size", 4, fail);
    if (size > kMaxChunkBytes) {
      fail(0, "chunk of " + std::to_string(size) + " bytes exceeds the limit of " +
                  std::to_string(kMaxChunkBytes));
    }
    chunk_file_offset_ = offset;
    chunk_data_file_offset_ = record.data_offset;
    chunk_compression_ = compression;
    if (chunk_.size() < size) chunk_.resize(size);
    if (compression == "none") {
      if (size != record.data_size) {
        fail(0, "uncompressed chunk: expected `size` " + std::to_string(size) +
                    " to equal the data length " + std::to_string(record.data_size));
      }
      stream_->read(reinterpret_cast<char*>(chunk_.data()), record.data_size);
      chunk_compressed_ = false;
    } else if (compression == "bz2" || compression == "lz4") {
      compressed_.resize(record.data_size);
      stream_->read(reinterpret_cast<char*>(compressed_.data()), record.data_size);
      chunk_compressed_ = true;
      size_t produced = 0;
      bool ok = false;
      if (compression == "bz2") {
        unsigned int length = static_cast<unsigned int>(size);
        const int result = BZ2_bzBuffToBuffDecompress(
            reinterpret_cast<char*>(chunk_.data()), &length,
            reinterpret_cast<char*>(compressed_.data()), record.data_size, 0, 0);
        ok = result == BZ_OK;
        produced = length;
      } else {
        LZ4F_dctx* context = nullptr;
        if (LZ4F_isError(LZ4F_createDecompressionContext(&context, LZ4F_VERSION))) {
          throw IoError(source_ + ": cannot create an LZ4 decompression context");
        }
        size_t in_offset = 0;
        ok = true;
        while (in_offset < record.data_size && produced < size) {
          size_t out_size = size - produced;
          size_t in_size = record.data_size - in_offset;
          const size_t hint = LZ4F_decompress(context, chunk_.data() + produced, &out_size,
                                              compressed_.data() + in_offset, &in_size, nullptr);
          if (LZ4F_isError(hint)) {
            ok = false;
            break;
          }
          produced += out_size;
          in_offset += in_size;
          if (hint == 0) break;
          if (in_size == 0 && out_size == 0) {
            ok = false;
            break;
          }
        }
        LZ4F_freeDecompressionContext(context);
      }
      if (!stream_) throw IoError(source_ + ": read failed at byte " + std::to_string(offset));
      if (!ok || produced != size) {
        fail(0, "corrupt " + compression + " chunk: expected " + std::to_string(size) +
                    " uncompressed bytes" +
                    (ok ? ", got " + std::to_string(produced) : " (decompression failed)"));
      }
    } else {
      fail(0, "unknown chunk compression '" + compression + "' (expected none, bz2 or lz4)");
    }
    if (!*stream_) throw IoError(source_ + ": read failed at byte " + std::to_string(offset));
    chunk_size_ = size;
    chunk_cursor_ = 0;
    in_chunk_ = true;
    return true;
  }
  return false;
}

bool RosbagReader::Next(RosbagMessage* message) {
  while (true) {
    if (!in_chunk_ || chunk_cursor_ == chunk_size_) {
      in_chunk_ = false;
      if (!LoadNextChunk()) return false;
      continue;
    }
    const size_t record_offset = chunk_cursor_;
    const uint8_t* chunk = chunk_.data();
    const auto position = [&](uint64_t at) {
      return chunk_compressed_
                 ? "byte " + std::to_string(at) + " of the uncompressed " + chunk_compression_ +
                       " chunk at byte " + std::to_string(chunk_file_offset_)
                 : "byte " + std::to_string(chunk_data_file_offset_ + at);
    };
    const auto fail_at = [&](uint64_t at, const std::string& what) -> void {
      throw ParseError(source_, position(at), what);
    };
    const size_t left = chunk_size_ - record_offset;
    if (left < 4) fail_at(record_offset, "truncated chunk: expected a 4-byte record header length");
    const uint32_t header_size = LoadU32(chunk + record_offset);
    if (header_size > left - 4 || left - 4 - header_size < 4) {
      fail_at(record_offset, "record header of " + std::to_string(header_size) +
                                 " bytes and its data length run past the chunk's end");
    }
    const uint8_t* header = chunk + record_offset + 4;
    const size_t data_length_offset = record_offset + 4 + header_size;
    const uint32_t data_size = LoadU32(chunk + data_length_offset);
    const size_t data_offset = data_length_offset + 4;
    if (data_size > chunk_size_ - data_offset) {
      fail_at(data_length_offset,
              "record data of " + std::to_string(data_size) + " bytes runs past the chunk's end");
    }
    chunk_cursor_ = data_offset + data_size;
    const auto header_fail = [&](uint64_t at, const std::string& what) -> void {
      fail_at(record_offset + 4 + at, what);
    };
    const Fields fields = ParseFields(header, header_size, header_fail);
    const uint8_t op = OpOf(fields, header_fail);
    const auto record_fail = [&](uint64_t, const std::string& what) -> void {
      fail_at(record_offset, what);
    };
    if (op == kOpConnection) {
      const auto id = static_cast<uint32_t>(IntegerField(fields, "conn", 4, record_fail));
      AddConnection(id, StringField(fields, "topic", record_fail), chunk + data_offset, data_size,
                    position(record_offset));
      continue;
    }
    if (op != kOpMessageData) {
      record_fail(0,
                  "expected a message (op 0x02) or connection (op 0x07) record in the chunk, "
                  "found op " +
                      std::to_string(op));
    }
    const auto id = static_cast<uint32_t>(IntegerField(fields, "conn", 4, record_fail));
    const uint64_t time = IntegerField(fields, "time", 8, record_fail);
    size_t index = 0;
    while (index < connections_.size() && connections_[index].id != id) ++index;
    if (index == connections_.size()) {
      record_fail(0, "message on connection " + std::to_string(id) +
                         ", which no connection record defines");
    }
    if (!select_all_ && (index >= selected_.size() || !selected_[index])) continue;
    message->connection = &connections_[index];
    message->record_t_ns =
        static_cast<int64_t>(time & 0xffffffffu) * 1000000000 + static_cast<int64_t>(time >> 32);
    message->data = chunk + data_offset;
    message->size = data_size;
    message->compressed_chunk = chunk_compressed_;
    message->chunk_file_offset = chunk_compressed_ ? chunk_file_offset_ : chunk_data_file_offset_;
    message->offset_in_chunk = data_offset;
    return true;
  }
}

int64_t RosMessageCursor::Time(const char* field) {
  const uint32_t seconds = U32(field);
  const uint32_t nanoseconds = U32(field);
  return static_cast<int64_t>(seconds) * 1000000000 + nanoseconds;
}

std::string RosMessageCursor::String(const char* field) {
  const uint32_t length = ArrayLength(field, 1);
  std::string text(reinterpret_cast<const char*>(here()), length);
  Skip(length);
  return text;
}

uint32_t RosMessageCursor::ArrayLength(const char* field, size_t element_size) {
  const uint32_t length = U32(field);
  if (static_cast<uint64_t>(length) * element_size > remaining()) {
    offset_ -= 4;
    Fail(std::string("expected ") + field + " of " + std::to_string(length) + " elements of " +
         std::to_string(element_size) + " bytes, only " + std::to_string(remaining() - 4) +
         " bytes are left in the message");
  }
  return length;
}

int64_t RosMessageCursor::Header() {
  U32("header.seq");
  const int64_t stamp = Time("header.stamp");
  const uint32_t frame_id_length = ArrayLength("header.frame_id", 1);
  Skip(frame_id_length);
  return stamp;
}

void RosMessageCursor::Require(size_t bytes, const char* field) const {
  if (bytes > remaining()) {
    Fail(std::string("expected ") + field + " (" + std::to_string(bytes) + " bytes), only " +
         std::to_string(remaining()) + " bytes are left in the message");
  }
}

void RosMessageCursor::Fail(const std::string& what) const {
  throw ParseError(source_, RosbagPosition(message_, offset_),
                   message_.connection->type + " on " + message_.connection->topic + ": " + what);
}

template <typename T>
T RosMessageCursor::Fixed(const char* field) {
  Require(sizeof(T), field);
  T value;
  std::memcpy(&value, here(), sizeof(T));
  offset_ += sizeof(T);
  return value;
}

template uint8_t RosMessageCursor::Fixed<uint8_t>(const char*);
template uint16_t RosMessageCursor::Fixed<uint16_t>(const char*);
template uint32_t RosMessageCursor::Fixed<uint32_t>(const char*);
template uint64_t RosMessageCursor::Fixed<uint64_t>(const char*);
template double RosMessageCursor::Fixed<double>(const char*);

}  // namespace evloc
