#include "core/events/aedat4.h"

#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/events/aedat4_schema/events_generated.h"
#include "core/events/aedat4_schema/file_data_table_generated.h"
#include "core/events/aedat4_schema/frame_generated.h"
#include "core/events/aedat4_schema/imu_generated.h"
#include "core/events/aedat4_schema/ioheader_generated.h"
#include "core/events/aedat4_schema/trigger_generated.h"
#include "core/events/aedat4_xml.h"

namespace evloc {
namespace {

constexpr char kMagic[] = "#!AER-DAT4.0\r\n";
constexpr size_t kMagicSize = 14;
// A packet header: int32 stream id, int32 body size.
constexpr size_t kPacketHeaderSize = 8;
// Times are int64 microseconds; beyond this they do not fit in int64 nanoseconds.
constexpr int64_t kMaxMicroseconds = std::numeric_limits<int64_t>::max() / 1000;

uint32_t LoadU32(const uint8_t* p) {
  uint32_t value;
  std::memcpy(&value, p, 4);
  return value;
}

int32_t LoadI32(const uint8_t* p) {
  int32_t value;
  std::memcpy(&value, p, 4);
  return value;
}

// A decimal integer attribute of DV's XML ("346"), or nullopt when absent or malformed.
std::optional<int64_t> ParseInteger(const std::string& text) {
  if (text.empty() || text.size() > 18) return std::nullopt;
  size_t i = 0;
  const bool negative = text[0] == '-';
  if (negative) i = 1;
  if (i == text.size()) return std::nullopt;
  int64_t value = 0;
  for (; i < text.size(); ++i) {
    if (text[i] < '0' || text[i] > '9') return std::nullopt;
    value = value * 10 + (text[i] - '0');
  }
  return negative ? -value : value;
}

// The text of `<attr key="KEY">` among the children of `node`, or nullptr.
const std::string* AttrText(const aedat4_xml::Element& node, const std::string& key) {
  const aedat4_xml::Element* attr = node.Child("attr", "key", key);
  return attr == nullptr ? nullptr : &attr->text;
}

int64_t MicrosecondsToNanoseconds(int64_t t_us, const Aedat4Packet& packet,
                                  const std::string& source, const char* what) {
  if (t_us > kMaxMicroseconds || t_us < -kMaxMicroseconds) {
    throw ParseError(source, Aedat4Position(packet, 0),
                     std::string(what) + " time " + std::to_string(t_us) +
                         " us does not fit in 64-bit nanoseconds");
  }
  return t_us * 1000;
}

// The root table of a verified packet body (size prefix, identifier and tables checked).
template <typename Table>
const Table* Root(const Aedat4Packet& packet) {
  return flatbuffers::GetSizePrefixedRoot<Table>(packet.data);
}

}  // namespace

const char* Aedat4CompressionName(Aedat4Compression compression) {
  switch (compression) {
    case Aedat4Compression::kNone:
      return "none";
    case Aedat4Compression::kLz4:
      return "lz4";
    case Aedat4Compression::kLz4High:
      return "lz4-high";
    case Aedat4Compression::kZstd:
      return "zstd";
    case Aedat4Compression::kZstdHigh:
      return "zstd-high";
  }
  return "unknown";
}

std::string Aedat4Position(const Aedat4Packet& packet, uint64_t offset_in_body) {
  if (packet.compression == Aedat4Compression::kNone) {
    return "byte " + std::to_string(packet.file_offset + kPacketHeaderSize + offset_in_body);
  }
  return "byte " + std::to_string(offset_in_body) + " of the decompressed " +
         Aedat4CompressionName(packet.compression) + " packet at byte " +
         std::to_string(packet.file_offset);
}

bool IsAedat4File(const std::filesystem::path& path) {
  return FileStartsWith(path, std::string_view(kMagic, kMagicSize));
}

// The decompression contexts, made once per reader.
struct Aedat4Reader::Decompressor {
  LZ4F_dctx* lz4 = nullptr;
  ZSTD_DCtx* zstd = nullptr;
  ~Decompressor() {
    if (lz4 != nullptr) LZ4F_freeDecompressionContext(lz4);
    if (zstd != nullptr) ZSTD_freeDCtx(zstd);
  }
};

Aedat4Reader::Aedat4Reader(const std::filesystem::path& path)
    : Aedat4Reader(OpenInputFile(path), path.string()) {}

Aedat4Reader::Aedat4Reader(std::unique_ptr<std::istream> stream, std::string source)
    : stream_(std::move(stream)), source_(std::move(source)) {
  Open();
}

Aedat4Reader::~Aedat4Reader() = default;

void Aedat4Reader::ReadAt(uint64_t offset, void* data, size_t size, const char* what) {
  if (offset > file_size_ || size > file_size_ - offset) {
    throw ParseError::AtByte(source_, offset,
                             std::string("truncated: expected ") + what + " (" +
                                 std::to_string(size) + " bytes), the file ends at byte " +
                                 std::to_string(file_size_));
  }
  stream_->clear();
  stream_->seekg(static_cast<std::streamoff>(offset));
  stream_->read(static_cast<char*>(data), static_cast<std::streamsize>(size));
  if (!*stream_) throw IoError(source_ + ": read failed at byte " + std::to_string(offset));
}

void Aedat4Reader::Open() {
  stream_->seekg(0, std::ios::end);
  const std::streamoff end = stream_->tellg();
  if (end < 0) throw IoError(source_ + ": cannot determine the size");
  file_size_ = static_cast<uint64_t>(end);
  char magic[kMagicSize] = {0};
  if (file_size_ < kMagicSize) {
    throw ParseError::AtByte(source_, 0,
                             "expected the AEDAT 4.0 magic '#!AER-DAT4.0\\r\\n', the file has " +
                                 std::to_string(file_size_) + " bytes");
  }
  ReadAt(0, magic, kMagicSize, "the AEDAT 4.0 magic");
  if (std::memcmp(magic, kMagic, kMagicSize) != 0) {
    const bool other_version = std::memcmp(magic, "#!AER-DAT", 9) == 0;
    throw ParseError::AtByte(
        source_, 0,
        other_version ? "only AEDAT 4.0 is supported (found '" + std::string(magic, 12) + "')"
                      : "expected the AEDAT 4.0 magic '#!AER-DAT4.0\\r\\n'");
  }
  // The IOHeader is a size-prefixed flatbuffer (its alignment counts the 4-byte prefix).
  uint8_t length_bytes[4];
  ReadAt(kMagicSize, length_bytes, 4, "the 4-byte IOHeader length");
  const uint32_t header_size = LoadU32(length_bytes);
  const uint64_t header_offset = kMagicSize + 4;
  if (header_size < 8 || header_size > kMaxHeaderBytes) {
    throw ParseError::AtByte(source_, kMagicSize,
                             "expected an IOHeader length of 8.." +
                                 std::to_string(kMaxHeaderBytes) + " bytes, found " +
                                 std::to_string(header_size));
  }
  std::vector<uint8_t> header(4 + header_size);
  std::memcpy(header.data(), length_bytes, 4);
  ReadAt(header_offset, header.data() + 4, header_size, "the IOHeader flatbuffer");
  flatbuffers::Verifier verifier(header.data(), header.size());
  if (!aedat4::VerifySizePrefixedIOHeaderBuffer(verifier)) {
    throw ParseError::AtByte(source_, header_offset,
                             "expected an IOHeader flatbuffer (compression, data table position, "
                             "stream description); the flatbuffers verifier rejected it");
  }
  const aedat4::IOHeader* io_header = aedat4::GetSizePrefixedIOHeader(header.data());
  const int32_t compression = static_cast<int32_t>(io_header->compression());
  if (compression < 0 || compression > 4) {
    throw ParseError::AtByte(source_, header_offset,
                             "unknown compression " + std::to_string(compression) +
                                 " in the IOHeader (expected 0 none, 1 LZ4, 2 LZ4 high, 3 Zstd, "
                                 "4 Zstd high)");
  }
  compression_ = static_cast<Aedat4Compression>(compression);
  position_ = header_offset + header_size;
  const int64_t table = io_header->data_table_position();
  if (table >= 0 &&
      (static_cast<uint64_t>(table) < position_ || static_cast<uint64_t>(table) > file_size_)) {
    throw ParseError::AtByte(source_, header_offset,
                             "the IOHeader's data table position " + std::to_string(table) +
                                 " is outside the packets (bytes " + std::to_string(position_) +
                                 ".." + std::to_string(file_size_) + "; truncated file?)");
  }
  packets_end_ = table >= 0 ? static_cast<uint64_t>(table) : file_size_;
  if (io_header->info_node() == nullptr) {
    throw ParseError::AtByte(source_, header_offset,
                             "the IOHeader has no stream description (infoNode)");
  }
  description_ = io_header->info_node()->str();

  // The streams: <dv><node name="outInfo"><node name="ID"> <attr key=...> ... </node></node></dv>.
  const std::string where = "the IOHeader's infoNode XML at byte " + std::to_string(header_offset);
  std::unique_ptr<aedat4_xml::Element> root;
  try {
    root = aedat4_xml::Parse(description_);
  } catch (const aedat4_xml::XmlError& error) {
    throw ParseError(source_, "byte " + std::to_string(error.offset) + " of " + where, error.what);
  }
  const aedat4_xml::Element* out_info = root->Child("node", "name", "outInfo");
  if (out_info == nullptr) {
    throw ParseError(
        source_, where,
        "expected a <node name=\"outInfo\"> listing the streams under <" + root->name + ">");
  }
  for (const auto& node : out_info->children) {
    if (node->name != "node") continue;
    Aedat4Stream stream;
    const std::string* id_text = node->Attribute("name");
    const std::optional<int64_t> id = id_text ? ParseInteger(*id_text) : std::nullopt;
    if (!id || *id < 0 || *id > std::numeric_limits<int32_t>::max()) {
      throw ParseError(source_, where,
                       "expected a stream node named by its id (a non-negative integer), found '" +
                           (id_text ? *id_text : std::string()) + "'");
    }
    stream.id = static_cast<int32_t>(*id);
    const std::string* type = AttrText(*node, "typeIdentifier");
    if (type == nullptr || type->empty()) {
      throw ParseError(source_, where,
                       "stream " + *id_text + " has no typeIdentifier (expected EVTS, FRME, ...)");
    }
    stream.type = *type;
    const std::string* name = AttrText(*node, "originalOutputName");
    stream.name = name != nullptr && !name->empty() ? *name : *id_text;
    if (const std::string* module = AttrText(*node, "originalModuleName")) stream.module = *module;
    if (const aedat4_xml::Element* info = node->Child("node", "name", "info")) {
      if (const std::string* camera = AttrText(*info, "source")) stream.camera = *camera;
      const std::string* size_x = AttrText(*info, "sizeX");
      const std::string* size_y = AttrText(*info, "sizeY");
      if (size_x != nullptr && size_y != nullptr) {
        const std::optional<int64_t> width = ParseInteger(*size_x);
        const std::optional<int64_t> height = ParseInteger(*size_y);
        if (!width || !height || *width < 1 || *height < 1 || *width > 32767 || *height > 32767) {
          throw ParseError(source_, where,
                           "stream " + *id_text + ": expected sizeX and sizeY in 1..32767, found " +
                               *size_x + " x " + *size_y);
        }
        stream.size = SensorSize{static_cast<int>(*width), static_cast<int>(*height)};
      }
    }
    for (const Aedat4Stream& other : streams_) {
      if (other.id == stream.id) {
        throw ParseError(source_, where, "stream id " + *id_text + " appears twice");
      }
    }
    streams_.push_back(std::move(stream));
  }
  if (streams_.empty()) throw ParseError(source_, where, "expected at least one stream");
  decompressor_ = std::make_unique<Decompressor>();
}

const Aedat4Stream* Aedat4Reader::FindStream(const std::string& name_or_id) const {
  for (const Aedat4Stream& stream : streams_) {
    if (stream.name == name_or_id) return &stream;
  }
  for (const Aedat4Stream& stream : streams_) {
    if (std::to_string(stream.id) == name_or_id) return &stream;
  }
  return nullptr;
}

std::string Aedat4Reader::DescribeStreams() const {
  std::vector<const Aedat4Stream*> sorted;
  for (const Aedat4Stream& stream : streams_) sorted.push_back(&stream);
  std::sort(sorted.begin(), sorted.end(),
            [](const Aedat4Stream* a, const Aedat4Stream* b) { return a->id < b->id; });
  std::string text;
  for (const Aedat4Stream* stream : sorted) {
    if (!text.empty()) text += ", ";
    text += stream->name + " (id " + std::to_string(stream->id) + ", " + stream->type + ")";
  }
  return text;
}

void Aedat4Reader::SetStreams(const std::vector<int32_t>& ids) { selected_ = ids; }

void Aedat4Reader::Decompress(uint64_t offset, const char* what) {
  const size_t input_size = compressed_.size();
  const auto fail = [&](const std::string& message) {
    throw ParseError::AtByte(source_, offset,
                             std::string("expected a valid ") +
                                 Aedat4CompressionName(compression_) + " " + what + ": " + message);
  };
  body_size_ = 0;
  if (body_.size() < 4096) body_.resize(4096);
  const auto grow = [&]() {
    if (body_.size() >= kMaxPacketBytes) {
      fail("it decompresses to more than " + std::to_string(kMaxPacketBytes) + " bytes");
    }
    body_.resize(std::min<uint64_t>(kMaxPacketBytes, body_.size() * 2));
  };
  if (compression_ == Aedat4Compression::kLz4 || compression_ == Aedat4Compression::kLz4High) {
    if (decompressor_->lz4 == nullptr &&
        LZ4F_isError(LZ4F_createDecompressionContext(&decompressor_->lz4, LZ4F_VERSION))) {
      throw IoError(source_ + ": cannot create an LZ4 decompression context");
    }
    // Every packet body is one LZ4 frame (or several); decompress until the input is consumed
    // and the last frame has ended (hint 0).
    size_t consumed = 0;
    size_t hint = 1;
    while (consumed < input_size || hint != 0) {
      if (body_size_ == body_.size()) grow();
      size_t out_size = body_.size() - body_size_;
      size_t in_size = input_size - consumed;
      hint = LZ4F_decompress(decompressor_->lz4, body_.data() + body_size_, &out_size,
                             compressed_.data() + consumed, &in_size, nullptr);
      if (LZ4F_isError(hint)) {
        LZ4F_resetDecompressionContext(decompressor_->lz4);
        fail(LZ4F_getErrorName(hint));
      }
      consumed += in_size;
      body_size_ += out_size;
      if (in_size == 0 && out_size == 0 && body_size_ < body_.size()) {
        LZ4F_resetDecompressionContext(decompressor_->lz4);
        fail("the LZ4 frame is truncated (the body ends before the frame's end mark)");
      }
    }
  } else {
    if (decompressor_->zstd == nullptr) {
      decompressor_->zstd = ZSTD_createDCtx();
      if (decompressor_->zstd == nullptr) {
        throw IoError(source_ + ": cannot create a Zstd decompression context");
      }
    }
    ZSTD_DCtx_reset(decompressor_->zstd, ZSTD_reset_session_only);
    // One frame that states its decompressed size (DV's one-shot compression writes it): one
    // call straight into the body buffer.
    const unsigned long long content = ZSTD_getFrameContentSize(compressed_.data(), input_size);
    if (content != ZSTD_CONTENTSIZE_UNKNOWN && content != ZSTD_CONTENTSIZE_ERROR &&
        content <= kMaxPacketBytes &&
        ZSTD_findFrameCompressedSize(compressed_.data(), input_size) == input_size) {
      if (body_.size() < content) body_.resize(static_cast<size_t>(content));
      const size_t produced =
          ZSTD_decompressDCtx(decompressor_->zstd, body_.data(), static_cast<size_t>(content),
                              compressed_.data(), input_size);
      if (ZSTD_isError(produced)) fail(ZSTD_getErrorName(produced));
      if (produced != content) {
        fail("the Zstd frame states " + std::to_string(content) + " bytes but holds " +
             std::to_string(produced));
      }
      body_size_ = produced;
      return;
    }
    ZSTD_inBuffer input{compressed_.data(), input_size, 0};
    size_t hint = 1;
    for (;;) {
      if (body_size_ == body_.size()) grow();
      ZSTD_outBuffer output{body_.data(), body_.size(), body_size_};
      hint = ZSTD_decompressStream(decompressor_->zstd, &output, &input);
      if (ZSTD_isError(hint)) fail(ZSTD_getErrorName(hint));
      body_size_ = output.pos;
      if (input.pos == input.size && output.pos < output.size) break;
    }
    if (hint != 0) fail("the Zstd frame is truncated (it ends before its last block)");
  }
}

void Aedat4Reader::VerifyBody(const Aedat4Packet& packet) const {
  const auto fail = [&](uint64_t offset, const std::string& what) {
    throw ParseError(source_, Aedat4Position(packet, offset),
                     "stream " + packet.stream->name + " (" + packet.stream->type + "): " + what);
  };
  if (packet.size < 12) {
    fail(0, "expected a size-prefixed flatbuffer of at least 12 bytes, found " +
                std::to_string(packet.size));
  }
  const uint32_t prefix = LoadU32(packet.data);
  if (prefix > packet.size - 4) {
    fail(0, "the flatbuffer's size prefix " + std::to_string(prefix) + " exceeds the " +
                std::to_string(packet.size - 4) + " bytes that follow it");
  }
  const std::string& type = packet.stream->type;
  if (std::memcmp(packet.data + 8, type.data(), std::min<size_t>(4, type.size())) != 0 &&
      (type == "EVTS" || type == "FRME" || type == "IMUS" || type == "TRIG")) {
    fail(8, "expected the file identifier " + type + ", found '" +
                std::string(reinterpret_cast<const char*>(packet.data + 8), 4) + "'");
  }
  flatbuffers::Verifier verifier(packet.data, prefix + 4);
  bool valid = true;
  if (type == "EVTS") {
    valid = aedat4::VerifySizePrefixedEventPacketBuffer(verifier);
  } else if (type == "FRME") {
    valid = aedat4::VerifySizePrefixedFrameBuffer(verifier);
  } else if (type == "IMUS") {
    valid = aedat4::VerifySizePrefixedIMUPacketBuffer(verifier);
  } else if (type == "TRIG") {
    valid = aedat4::VerifySizePrefixedTriggerPacketBuffer(verifier);
  }
  if (!valid)
    fail(4, "expected a valid " + type + " flatbuffer; the flatbuffers verifier rejected it");
}

bool Aedat4Reader::Next(Aedat4Packet* packet) {
  while (position_ < packets_end_) {
    const uint64_t offset = position_;
    if (packets_end_ - offset < kPacketHeaderSize) {
      throw ParseError::AtByte(source_, offset,
                               "truncated: expected an 8-byte packet header (stream id, size), " +
                                   std::to_string(packets_end_ - offset) + " bytes remain");
    }
    uint8_t header[kPacketHeaderSize];
    ReadAt(offset, header, kPacketHeaderSize, "a packet header");
    const int32_t stream_id = LoadI32(header);
    const int32_t size = LoadI32(header + 4);
    const Aedat4Stream* stream = nullptr;
    for (const Aedat4Stream& candidate : streams_) {
      if (candidate.id == stream_id) stream = &candidate;
    }
    if (stream == nullptr) {
      throw ParseError::AtByte(
          source_, offset,
          "packet of stream id " + std::to_string(stream_id) +
              ", which the header does not describe (its streams: " + DescribeStreams() + ")");
    }
    if (size <= 0 || static_cast<uint64_t>(size) > kMaxPacketBytes) {
      throw ParseError::AtByte(source_, offset + 4,
                               "expected a packet size of 1.." + std::to_string(kMaxPacketBytes) +
                                   " bytes, found " + std::to_string(size));
    }
    const uint64_t body_offset = offset + kPacketHeaderSize;
    if (static_cast<uint64_t>(size) > packets_end_ - body_offset) {
      throw ParseError::AtByte(source_, offset,
                               "truncated: the packet declares " + std::to_string(size) +
                                   " bytes, the packets end at byte " +
                                   std::to_string(packets_end_));
    }
    position_ = body_offset + static_cast<uint64_t>(size);
    if (!selected_.empty() &&
        std::find(selected_.begin(), selected_.end(), stream_id) == selected_.end()) {
      continue;
    }
    if (compression_ == Aedat4Compression::kNone) {
      if (body_.size() < static_cast<size_t>(size)) body_.resize(static_cast<size_t>(size));
      ReadAt(body_offset, body_.data(), static_cast<size_t>(size), "a packet body");
      body_size_ = static_cast<size_t>(size);
    } else {
      compressed_.resize(static_cast<size_t>(size));
      ReadAt(body_offset, compressed_.data(), compressed_.size(), "a packet body");
      Decompress(body_offset, "packet body");
    }
    packet->stream = stream;
    packet->file_offset = offset;
    packet->data = body_.data();
    packet->size = body_size_;
    packet->compression = compression_;
    VerifyBody(*packet);
    return true;
  }
  if (!table_checked_ && packets_end_ < file_size_) VerifyDataTable();
  return false;
}

void Aedat4Reader::VerifyDataTable() {
  table_checked_ = true;
  const uint64_t size = file_size_ - packets_end_;
  const auto fail = [&](uint64_t at, const std::string& what) {
    throw ParseError::AtByte(source_, at, "the file data table (the packet index): " + what);
  };
  if (size > kMaxPacketBytes) {
    fail(packets_end_, "expected at most " + std::to_string(kMaxPacketBytes) + " bytes, found " +
                           std::to_string(size));
  }
  compressed_.resize(static_cast<size_t>(size));
  ReadAt(packets_end_, compressed_.data(), compressed_.size(), "the file data table");
  if (compression_ == Aedat4Compression::kNone) {
    body_.assign(compressed_.begin(), compressed_.end());
    body_size_ = compressed_.size();
  } else {
    Decompress(packets_end_, "file data table");
  }
  const uint32_t prefix = body_size_ >= 4 ? LoadU32(body_.data()) : 0;
  flatbuffers::Verifier verifier(body_.data(), body_size_);
  if (body_size_ < 8 || prefix != body_size_ - 4 ||
      !aedat4::VerifySizePrefixedFileDataTableBuffer(verifier)) {
    fail(packets_end_, "expected a size-prefixed FileDataTable flatbuffer of " +
                           std::to_string(body_size_) +
                           " bytes up to the file's end (truncated file?)");
  }
}

void DecodeAedat4Events(const Aedat4Packet& packet, const std::string& source,
                        const std::optional<SensorSize>& bounds, EventBuffer* out,
                        uint64_t* dropped) {
  const auto* elements = Root<aedat4::EventPacket>(packet)->elements();
  if (elements == nullptr) return;
  const size_t count = elements->size();
  const auto* events = reinterpret_cast<const aedat4::Event*>(elements->Data());
  const size_t base = out->size();
  out->t_ns.resize(base + count);
  out->x.resize(base + count);
  out->y.resize(base + count);
  out->polarity.resize(base + count);
  int64_t* t = out->t_ns.data() + base;
  uint16_t* xs = out->x.data() + base;
  uint16_t* ys = out->y.data() + base;
  int8_t* ps = out->polarity.data() + base;
  // Unsigned comparison drops negative coordinates too. Branch-free: every event is written at
  // `kept`, which advances only for events inside the sensor; everything stays in locals (the
  // int8_t stores may alias anything in memory).
  const uint32_t width = bounds ? static_cast<uint32_t>(bounds->width) : 32768u;
  const uint32_t height = bounds ? static_cast<uint32_t>(bounds->height) : 32768u;
  size_t kept = 0;
  bool time_overflow = false;
  for (size_t i = 0; i < count; ++i) {
    const aedat4::Event& event = events[i];
    const int64_t t_us = event.timestamp();
    time_overflow |= (t_us > kMaxMicroseconds) | (t_us < -kMaxMicroseconds);
    const auto x = static_cast<uint32_t>(static_cast<int32_t>(event.x()));
    const auto y = static_cast<uint32_t>(static_cast<int32_t>(event.y()));
    t[kept] = static_cast<int64_t>(static_cast<uint64_t>(t_us) * 1000u);
    xs[kept] = static_cast<uint16_t>(x);
    ys[kept] = static_cast<uint16_t>(y);
    ps[kept] = static_cast<int8_t>(event.polarity() ? 1 : -1);
    kept += static_cast<size_t>((x < width) & (y < height));
  }
  if (time_overflow) {
    for (size_t i = 0; i < count; ++i) {
      MicrosecondsToNanoseconds(events[i].timestamp(), packet, source, "event");
    }
  }
  *dropped += count - kept;
  out->t_ns.resize(base + kept);
  out->x.resize(base + kept);
  out->y.resize(base + kept);
  out->polarity.resize(base + kept);
}

Aedat4Frame DecodeAedat4Frame(const Aedat4Packet& packet, const std::string& source) {
  const aedat4::Frame* frame = Root<aedat4::Frame>(packet);
  Aedat4Frame result;
  result.t_ns = MicrosecondsToNanoseconds(frame->timestamp(), packet, source, "frame");
  result.exposure_begin_ns =
      MicrosecondsToNanoseconds(frame->timestamp_start_of_exposure(), packet, source, "exposure");
  result.exposure_end_ns =
      MicrosecondsToNanoseconds(frame->timestamp_end_of_exposure(), packet, source, "exposure");
  switch (frame->format()) {
    case aedat4::FrameFormat_GRAY:
      break;
    case aedat4::FrameFormat_GRAY16:
      result.bytes_per_channel = 2;
      break;
    case aedat4::FrameFormat_BGR:
      result.channels = 3;
      break;
    case aedat4::FrameFormat_BGRA:
      result.channels = 4;
      break;
    default:
      throw ParseError(source, Aedat4Position(packet, 0),
                       "frame of unknown format " +
                           std::to_string(static_cast<int>(frame->format())) +
                           " (evloc reads 0 gray, 2 gray 16-bit, 16 BGR, 24 BGRA)");
  }
  result.width = frame->size_x();
  result.height = frame->size_y();
  result.position_x = frame->position_x();
  result.position_y = frame->position_y();
  const uint64_t expected = static_cast<uint64_t>(std::max(result.width, 0)) *
                            static_cast<uint64_t>(std::max(result.height, 0)) *
                            static_cast<uint64_t>(result.channels * result.bytes_per_channel);
  const size_t found = frame->pixels() ? frame->pixels()->size() : 0;
  if (result.width < 1 || result.height < 1 || expected != found) {
    throw ParseError(source, Aedat4Position(packet, 0),
                     "frame of " + std::to_string(result.width) + " x " +
                         std::to_string(result.height) + " pixels with " +
                         std::to_string(result.channels * result.bytes_per_channel) +
                         " bytes each: expected " + std::to_string(expected) +
                         " pixel bytes, found " + std::to_string(found));
  }
  result.pixels.assign(frame->pixels()->begin(), frame->pixels()->end());
  return result;
}

void DecodeAedat4Imu(const Aedat4Packet& packet, const std::string& source,
                     std::vector<Aedat4ImuSample>* out) {
  const auto* elements = Root<aedat4::IMUPacket>(packet)->elements();
  if (elements == nullptr) return;
  for (const aedat4::IMU* imu : *elements) {
    Aedat4ImuSample sample;
    sample.t_ns = MicrosecondsToNanoseconds(imu->timestamp(), packet, source, "IMU");
    sample.temperature_c = imu->temperature();
    sample.accelerometer_g[0] = imu->accelerometer_x();
    sample.accelerometer_g[1] = imu->accelerometer_y();
    sample.accelerometer_g[2] = imu->accelerometer_z();
    sample.gyroscope_dps[0] = imu->gyroscope_x();
    sample.gyroscope_dps[1] = imu->gyroscope_y();
    sample.gyroscope_dps[2] = imu->gyroscope_z();
    sample.magnetometer_ut[0] = imu->magnetometer_x();
    sample.magnetometer_ut[1] = imu->magnetometer_y();
    sample.magnetometer_ut[2] = imu->magnetometer_z();
    out->push_back(sample);
  }
}

void DecodeAedat4Triggers(const Aedat4Packet& packet, const std::string& source,
                          std::vector<Aedat4Trigger>* out) {
  const auto* elements = Root<aedat4::TriggerPacket>(packet)->elements();
  if (elements == nullptr) return;
  for (const aedat4::Trigger* trigger : *elements) {
    out->push_back({MicrosecondsToNanoseconds(trigger->timestamp(), packet, source, "trigger"),
                    static_cast<int>(trigger->type())});
  }
}

std::vector<const Aedat4Stream*> Aedat4StreamsOfType(const Aedat4Reader& reader,
                                                     const std::string& type) {
  std::vector<const Aedat4Stream*> streams;
  for (const Aedat4Stream& stream : reader.streams()) {
    if (stream.type == type) streams.push_back(&stream);
  }
  return streams;
}

void Aedat4EventOptions::Check() const {
  if (stream.empty()) throw InvalidArgumentError("The AEDAT4 events stream must not be empty.");
}

Aedat4EventReader::Aedat4EventReader(const std::filesystem::path& path,
                                     const Aedat4EventOptions& options)
    : Aedat4EventReader(OpenInputFile(path), path.string(), options) {}

Aedat4EventReader::Aedat4EventReader(std::unique_ptr<std::istream> stream, std::string source,
                                     const Aedat4EventOptions& options)
    : file_(std::make_unique<Aedat4Reader>(std::move(stream), std::move(source))) {
  Initialise(options);
}

void Aedat4EventReader::Initialise(const Aedat4EventOptions& options) {
  options.Check();
  const Aedat4Stream* stream = file_->FindStream(options.stream);
  if (stream == nullptr) {
    throw InvalidArgumentError(file_->source() + " has no stream '" + options.stream +
                               "'; its streams are: " + file_->DescribeStreams() +
                               " (name the events stream: --events-topic NAME|ID)");
  }
  if (stream->type != "EVTS") {
    throw InvalidArgumentError(file_->source() + ": stream '" + options.stream + "' has type " +
                               stream->type +
                               ", not events (EVTS); its streams are: " + file_->DescribeStreams());
  }
  sensor_size_ = stream->size;
  file_->SetStreams({stream->id});
}

bool Aedat4EventReader::DecodeNextPacket(EventBuffer* out) {
  Aedat4Packet packet;
  if (!file_->Next(&packet)) return false;
  ++packets_;
  DecodeAedat4Events(packet, file_->source(), sensor_size_, out, &dropped_);
  return true;
}

}  // namespace evloc
