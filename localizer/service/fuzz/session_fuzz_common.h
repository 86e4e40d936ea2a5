// Shared parts of the session fuzz targets (docs/reliability.md §4): the reader of the fuzz
// input, the writers of the same formats (for the seed corpus) and the checks that every request
// the session accepts or refuses must pass. A failed check aborts, which libFuzzer reports.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <initializer_list>
#include <optional>
#include <string>

#include <grpcpp/support/status.h>

#include "core/events/event.h"
#include "evloc/localizer.pb.h"
#include "localizer/service/session.h"
#include "localizer/service/testing/service_fixture.h"

namespace evloc::service::fuzz {

// Aborts (a fuzz finding) naming the oracle when `condition` is false.
#define EVLOC_FUZZ_REQUIRE(condition) \
  ::evloc::service::fuzz::RequireAt((condition), #condition, __FILE__, __LINE__)

// EVLOC_FUZZ_REQUIRE's body.
inline void RequireAt(bool condition, const char* text, const char* file, int line) {
  if (condition) return;
  std::fprintf(stderr, "%s:%d: fuzz oracle failed: %s\n", file, line, text);
  std::abort();
}

// Reads little-endian fields and length-prefixed records from fuzz input; reading past the end
// yields zeros (fixed fields) or nothing (records).
class FuzzInput {
 public:
  // Reads `size` bytes at `data` (not copied).
  FuzzInput(const uint8_t* data, size_t size) : data_(data), size_(size) {}

  // The next sizeof(T) bytes as a little-endian integer (missing bytes are zero).
  template <typename T>
  T Read() {
    uint64_t value = 0;
    for (size_t i = 0; i < sizeof(T); ++i) {
      const uint64_t byte = offset_ < size_ ? data_[offset_++] : 0;
      value |= byte << (8 * i);
    }
    return static_cast<T>(value);
  }
  // The next min(count, remaining) bytes.
  std::string Bytes(size_t count) {
    count = std::min(count, size_ - offset_);
    std::string bytes(reinterpret_cast<const char*>(data_ + offset_), count);
    offset_ += count;
    return bytes;
  }
  // A record: a LEB128 varint length, then that many bytes. False when the input is exhausted.
  bool Record(std::string* out) {
    if (offset_ >= size_) return false;
    uint64_t length = 0;
    for (int shift = 0; offset_ < size_ && shift < 35; shift += 7) {
      const uint8_t byte = data_[offset_++];
      length |= static_cast<uint64_t>(byte & 0x7f) << shift;
      if ((byte & 0x80) == 0) break;
    }
    *out = Bytes(static_cast<size_t>(std::min<uint64_t>(length, size_)));
    return true;
  }
  // True when every byte was read.
  bool done() const { return offset_ >= size_; }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t offset_ = 0;
};

// Appends `value` as `bytes` little-endian bytes (the inverse of FuzzInput::Read).
inline void AppendLittleEndian(uint64_t value, size_t bytes, std::string* out) {
  for (size_t i = 0; i < bytes; ++i) out->push_back(static_cast<char>((value >> (8 * i)) & 0xff));
}

// Appends a record as FuzzInput::Record reads it.
inline void AppendRecord(const std::string& record, std::string* out) {
  uint64_t length = record.size();
  do {
    uint8_t byte = length & 0x7f;
    length >>= 7;
    if (length != 0) byte |= 0x80;
    out->push_back(static_cast<char>(byte));
  } while (length != 0);
  out->append(record);
}

// The anchored copy of the test map that the requests target serves beside it.
inline constexpr char kAnchoredTestMapName[] = "rectangles_geo";
inline Map AnchoredTestMap() {
  Map map = testing::TestMap();
  GeoAnchor anchor;
  anchor.origin = {46.5191, 6.5668, 372.0};
  anchor.horizontal_sigma_m = 0.5;
  map.geo_anchor = anchor;
  return map;
}

// Aborts unless `status` is OK or has one of the `allowed` codes with a message (the documented
// statuses of docs/api.md, "Errors").
inline void CheckStatus(const grpc::Status& status,
                        std::initializer_list<grpc::StatusCode> allowed) {
  if (status.ok()) return;
  EVLOC_FUZZ_REQUIRE(!status.error_message().empty());
  bool listed = false;
  for (grpc::StatusCode code : allowed) listed |= status.error_code() == code;
  EVLOC_FUZZ_REQUIRE(listed);
}

// Aborts unless an accepted EventPacket item keeps RequestValidator's promises: its events are
// consistent, on the sensor, in time order, after `previous_end_t_ns` and at or before the
// packet's end, which does not go back.
inline void CheckAcceptedPacket(const SessionItem& item, SensorSize sensor,
                                std::optional<int64_t> previous_end_t_ns) {
  EVLOC_FUZZ_REQUIRE(item.kind == SessionItem::Kind::kEvents);
  EVLOC_FUZZ_REQUIRE(item.events.IsConsistent());
  EVLOC_FUZZ_REQUIRE(item.t_ns >= -kMaxSessionTimeNs && item.t_ns <= kMaxSessionTimeNs);
  EVLOC_FUZZ_REQUIRE(!previous_end_t_ns || item.t_ns >= *previous_end_t_ns);
  for (size_t i = 0; i < item.events.size(); ++i) {
    EVLOC_FUZZ_REQUIRE(sensor.Contains(item.events.x[i], item.events.y[i]));
    EVLOC_FUZZ_REQUIRE(item.events.polarity[i] == 1 || item.events.polarity[i] == -1);
    EVLOC_FUZZ_REQUIRE(item.events.t_ns[i] <= item.t_ns);
    EVLOC_FUZZ_REQUIRE(i > 0 ? item.events.t_ns[i] >= item.events.t_ns[i - 1]
                             : !previous_end_t_ns || item.events.t_ns[i] > *previous_end_t_ns);
  }
}

}  // namespace evloc::service::fuzz
