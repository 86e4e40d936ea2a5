// Test helper: edits the protobuf payload of a .evmap file and rewrites its header checksums, to
// make files the writer would not write (corrupted fields, older format versions).
#pragma once

#include <cstdint>
#include <cstring>
#include <functional>
#include <string>
#include <string_view>
#include <utility>

#include "evloc/map.pb.h"
#include "maps/crc32c.h"
#include "maps/map.h"

namespace evloc::testing {

// The bytes of a .evmap file whose payload is `payload` (any bytes), with the header's version set
// to `version` (0: kept) and valid payload and header checksums.
inline std::string WithPayload(std::string file_bytes, const std::string& payload,
                               uint32_t version) {
  const uint32_t payload_crc = Crc32c(payload);
  const uint64_t length = payload.size();
  if (version != 0) std::memcpy(file_bytes.data() + 8, &version, 4);
  std::memcpy(file_bytes.data() + 12, &payload_crc, 4);
  std::memcpy(file_bytes.data() + 16, &length, 8);
  const uint32_t header_crc = Crc32c(std::string_view(file_bytes).substr(0, 24));
  std::memcpy(file_bytes.data() + 24, &header_crc, 4);
  return file_bytes.substr(0, kMapFileHeaderSize) + payload;
}

// The bytes of a .evmap file whose payload `edit` changed (its summary field and geo anchor, if it
// keeps them, written first as SaveMap does; an edit that clears it makes a file of an earlier
// writer), with the header's version set to `version` (0: kept) and valid payload and header
// checksums (the content checksum is what the edit leaves). Returns an empty string when
// `file_bytes` has no parsable payload.
inline std::string EditMapPayload(std::string file_bytes,
                                  const std::function<void(map_format::MapFile&)>& edit,
                                  uint32_t version = 0) {
  map_format::MapFile file;
  if (file_bytes.size() < kMapFileHeaderSize ||
      !file.ParseFromString(file_bytes.substr(kMapFileHeaderSize))) {
    return "";
  }
  edit(file);
  // As SaveMap writes it: the summary field (when the edited file has one) first, then the geo
  // anchor (when it has one).
  map_format::MapFile summary_only;
  if (file.has_summary()) {
    *summary_only.mutable_summary() = file.summary();
    file.clear_summary();
  }
  if (file.has_geo_anchor()) {
    *summary_only.mutable_geo_anchor() = file.geo_anchor();
    file.clear_geo_anchor();
  }
  return WithPayload(std::move(file_bytes),
                     summary_only.SerializeAsString() + file.SerializeAsString(), version);
}

}  // namespace evloc::testing
