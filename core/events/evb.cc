#include "core/events/evb.h"

#include <bit>
#include <cstring>
#include <fstream>
#include <string>
#include <utility>

#include "core/common/error.h"
#include "core/events/crc32.h"

namespace evloc {
namespace {

static_assert(std::endian::native == std::endian::little, ".evb I/O assumes a little-endian host");

constexpr char kFileMagic[8] = {'E', 'V', 'L', 'O', 'C', 'E', 'V', 'B'};
constexpr char kChunkMagic[4] = {'E', 'V', 'C', 'K'};
constexpr char kEndMagic[4] = {'E', 'V', 'N', 'D'};
constexpr uint32_t kVersion = 1;
constexpr size_t kFileHeaderSize = 32;
constexpr size_t kChunkHeaderSize = 24;
constexpr size_t kEventSize = 8;
constexpr uint32_t kMaxEventsPerChunk = 1u << 20;
constexpr int64_t kMaxTimeOffsetNs = (int64_t{1} << 31) - 1;

template <typename T>
void Put(std::vector<uint8_t>* bytes, size_t offset, T value) {
  std::memcpy(bytes->data() + offset, &value, sizeof(T));
}
template <typename T>
T Get(const uint8_t* bytes) {
  T value;
  std::memcpy(&value, bytes, sizeof(T));
  return value;
}

// A chunk or end-record header: magic, count, 64-bit value, payload CRC, header CRC.
std::vector<uint8_t> RecordHeader(const char (&magic)[4], uint32_t count, int64_t value,
                                  uint32_t payload_crc) {
  std::vector<uint8_t> header(kChunkHeaderSize);
  std::memcpy(header.data(), magic, 4);
  Put(&header, 4, count);
  Put(&header, 8, value);
  Put(&header, 16, payload_crc);
  Put(&header, 20, Crc32(header.data(), 20));
  return header;
}

}  // namespace

void EvbWriterOptions::Check() const {
  if (max_events_per_chunk < 1 || max_events_per_chunk > static_cast<int>(kMaxEventsPerChunk)) {
    throw InvalidArgumentError("EvbWriterOptions.max_events_per_chunk must be in 1..1048576, got " +
                               std::to_string(max_events_per_chunk));
  }
}

EvbWriter::EvbWriter(const std::filesystem::path& path, std::optional<SensorSize> sensor_size,
                     EvbWriterOptions options)
    : options_(options), sensor_size_(sensor_size), file_(path) {
  options_.Check();
  if (sensor_size_) sensor_size_->Check();
  std::vector<uint8_t> header(kFileHeaderSize, 0);
  std::memcpy(header.data(), kFileMagic, 8);
  Put(&header, 8, kVersion);
  Put(&header, 12, static_cast<uint32_t>(sensor_size_ ? sensor_size_->width : 0));
  Put(&header, 16, static_cast<uint32_t>(sensor_size_ ? sensor_size_->height : 0));
  Put(&header, 28, Crc32(header.data(), 28));
  file_.stream().write(reinterpret_cast<const char*>(header.data()), kFileHeaderSize);
  chunk_.reserve(options_.max_events_per_chunk);
}

void EvbWriter::Write(const Event& event) {
  EventBuffer single;
  single.push_back(event);
  Write(single);
}

void EvbWriter::Write(const EventBuffer& events) {
  if (closed_) throw InvalidArgumentError(file_.path().string() + ": write after Close()");
  if (!events.IsConsistent()) {
    throw InvalidArgumentError("EvbWriter::Write: the event buffer's arrays differ in length");
  }
  for (size_t i = 0; i < events.size(); ++i) {
    if (events.polarity[i] != 1 && events.polarity[i] != -1) {
      throw InvalidArgumentError("EvbWriter::Write: event " + std::to_string(i) + " has polarity " +
                                 std::to_string(events.polarity[i]) + ", expected +1 or -1");
    }
    if (sensor_size_ && !sensor_size_->Contains(events.x[i], events.y[i])) {
      throw InvalidArgumentError("EvbWriter::Write: event " + std::to_string(i) + " at (" +
                                 std::to_string(events.x[i]) + ", " + std::to_string(events.y[i]) +
                                 ") lies outside the sensor");
    }
  }
  for (size_t i = 0; i < events.size(); ++i) {
    if (!chunk_.empty()) {
      const int64_t base = chunk_.t_ns.front();
      // Subtract in unsigned arithmetic: the two times may be far apart.
      const uint64_t offset = static_cast<uint64_t>(events.t_ns[i]) - static_cast<uint64_t>(base);
      const bool representable = events.t_ns[i] >= base && offset <= kMaxTimeOffsetNs;
      if (!representable || chunk_.size() >= static_cast<size_t>(options_.max_events_per_chunk)) {
        FlushChunk();
      }
    }
    chunk_.t_ns.push_back(events.t_ns[i]);
    chunk_.x.push_back(events.x[i]);
    chunk_.y.push_back(events.y[i]);
    chunk_.polarity.push_back(events.polarity[i]);
  }
  event_count_ += events.size();
}

void EvbWriter::FlushChunk() {
  if (chunk_.empty()) return;
  const size_t count = chunk_.size();
  bytes_.resize(count * kEventSize);
  const int64_t base = chunk_.t_ns.front();
  for (size_t i = 0; i < count; ++i) {
    const uint32_t offset_and_polarity =
        static_cast<uint32_t>(chunk_.t_ns[i] - base) | (chunk_.polarity[i] > 0 ? 1u << 31 : 0u);
    Put(&bytes_, i * kEventSize, offset_and_polarity);
    Put(&bytes_, i * kEventSize + 4, chunk_.x[i]);
    Put(&bytes_, i * kEventSize + 6, chunk_.y[i]);
  }
  const auto header = RecordHeader(kChunkMagic, static_cast<uint32_t>(count), base,
                                   Crc32(bytes_.data(), bytes_.size()));
  file_.stream().write(reinterpret_cast<const char*>(header.data()), header.size());
  file_.stream().write(reinterpret_cast<const char*>(bytes_.data()), bytes_.size());
  if (!file_.stream()) throw IoError(file_.path().string() + ": write failed");
  chunk_.clear();
}

void EvbWriter::Close() {
  if (closed_) return;
  FlushChunk();
  const auto end = RecordHeader(kEndMagic, 0, static_cast<int64_t>(event_count_), 0);
  file_.stream().write(reinterpret_cast<const char*>(end.data()), end.size());
  file_.Commit();
  closed_ = true;
}

// ---------------------------------------------------------------------------------------------

EvbReader::EvbReader(const std::filesystem::path& path)
    : stream_(std::make_unique<std::ifstream>(path, std::ios::binary)), source_(path.string()) {
  if (!*stream_) throw IoError(source_ + ": cannot open");
  ReadHeader();
}

EvbReader::EvbReader(std::unique_ptr<std::istream> stream, std::string source)
    : stream_(std::move(stream)), source_(std::move(source)) {
  if (!stream_) throw InvalidArgumentError("EvbReader: null stream");
  ReadHeader();
}

void EvbReader::ReadHeader() {
  uint8_t header[kFileHeaderSize];
  stream_->read(reinterpret_cast<char*>(header), kFileHeaderSize);
  if (stream_->gcount() != static_cast<std::streamsize>(kFileHeaderSize)) {
    throw ParseError::AtByte(source_, static_cast<uint64_t>(stream_->gcount()),
                             "file ends inside the 32-byte .evb header");
  }
  if (std::memcmp(header, kFileMagic, 8) != 0) {
    throw ParseError::AtByte(source_, 0, "not an .evb file (magic EVLOCEVB missing)");
  }
  if (Get<uint32_t>(header + 28) != Crc32(header, 28)) {
    throw ParseError::AtByte(source_, 28, "header CRC mismatch (corrupt .evb header)");
  }
  const uint32_t version = Get<uint32_t>(header + 8);
  if (version != kVersion) {
    throw ParseError::AtByte(source_, 8, "unsupported .evb version " + std::to_string(version));
  }
  const uint32_t width = Get<uint32_t>(header + 12);
  const uint32_t height = Get<uint32_t>(header + 16);
  if ((width == 0) != (height == 0) || width > 65535 || height > 65535) {
    throw ParseError::AtByte(
        source_, 12, "invalid sensor size " + std::to_string(width) + "x" + std::to_string(height));
  }
  if (width > 0) sensor_size_ = SensorSize{static_cast<int>(width), static_cast<int>(height)};
  offset_ = kFileHeaderSize;
}

bool EvbReader::ReadChunk() {
  uint8_t header[kChunkHeaderSize];
  stream_->read(reinterpret_cast<char*>(header), kChunkHeaderSize);
  const auto got = static_cast<size_t>(stream_->gcount());
  if (got != kChunkHeaderSize) {
    throw ParseError::AtByte(source_, offset_ + got,
                             got == 0 ? "file ends without the end record (truncated .evb)"
                                      : "file ends inside a chunk header (truncated .evb)");
  }
  if (Get<uint32_t>(header + 20) != Crc32(header, 20)) {
    throw ParseError::AtByte(source_, offset_, "chunk header CRC mismatch (corrupt .evb)");
  }
  const uint32_t count = Get<uint32_t>(header + 4);
  const int64_t value = Get<int64_t>(header + 8);
  if (std::memcmp(header, kEndMagic, 4) == 0) {
    if (count != 0 || value != static_cast<int64_t>(events_read_)) {
      throw ParseError::AtByte(source_, offset_,
                               "end record counts " + std::to_string(value) + " events, read " +
                                   std::to_string(events_read_));
    }
    offset_ += kChunkHeaderSize;
    if (stream_->peek() != std::char_traits<char>::eof()) {
      throw ParseError::AtByte(source_, offset_, "data after the end record");
    }
    return false;
  }
  if (std::memcmp(header, kChunkMagic, 4) != 0) {
    throw ParseError::AtByte(source_, offset_, "expected a chunk (EVCK) or end record (EVND)");
  }
  if (count == 0 || count > kMaxEventsPerChunk) {
    throw ParseError::AtByte(source_, offset_ + 4,
                             "chunk event count " + std::to_string(count) + " outside 1..1048576");
  }
  offset_ += kChunkHeaderSize;
  std::vector<uint8_t> payload(size_t{count} * kEventSize);
  stream_->read(reinterpret_cast<char*>(payload.data()),
                static_cast<std::streamsize>(payload.size()));
  if (static_cast<size_t>(stream_->gcount()) != payload.size()) {
    throw ParseError::AtByte(
        source_, offset_ + static_cast<uint64_t>(stream_->gcount()),
        "file ends inside a chunk of " + std::to_string(count) + " events (truncated .evb)");
  }
  if (Get<uint32_t>(header + 16) != Crc32(payload.data(), payload.size())) {
    throw ParseError::AtByte(source_, offset_, "chunk data CRC mismatch (corrupt .evb)");
  }
  chunk_.clear();
  chunk_.t_ns.resize(count);
  chunk_.x.resize(count);
  chunk_.y.resize(count);
  chunk_.polarity.resize(count);
  const uint64_t base = static_cast<uint64_t>(value);
  for (size_t i = 0; i < count; ++i) {
    const uint8_t* record = payload.data() + i * kEventSize;
    const uint32_t offset_and_polarity = Get<uint32_t>(record);
    chunk_.t_ns[i] = static_cast<int64_t>(base + (offset_and_polarity & 0x7FFFFFFFu));
    chunk_.polarity[i] = (offset_and_polarity >> 31) ? int8_t{1} : int8_t{-1};
    chunk_.x[i] = Get<uint16_t>(record + 4);
    chunk_.y[i] = Get<uint16_t>(record + 6);
    if (sensor_size_ && !sensor_size_->Contains(chunk_.x[i], chunk_.y[i])) {
      throw ParseError::AtByte(source_, offset_ + i * kEventSize + 4,
                               "event outside the sensor size of the header");
    }
  }
  offset_ += payload.size();
  chunk_position_ = 0;
  return true;
}

size_t EvbReader::Read(size_t max_events, EventBuffer* out) {
  if (out == nullptr) throw InvalidArgumentError("EvbReader::Read: output buffer is null");
  size_t appended = 0;
  while (appended < max_events && !finished_) {
    if (chunk_position_ == chunk_.size()) {
      if (!ReadChunk()) {
        finished_ = true;
        break;
      }
      events_read_ += chunk_.size();
    }
    const size_t count = std::min(max_events - appended, chunk_.size() - chunk_position_);
    out->Append(chunk_.t_ns.data() + chunk_position_, chunk_.x.data() + chunk_position_,
                chunk_.y.data() + chunk_position_, chunk_.polarity.data() + chunk_position_, count);
    chunk_position_ += count;
    appended += count;
  }
  return appended;
}

}  // namespace evloc
