// libFuzzer target: the .evmap loader behind the service's map registry, with valid checksums
// (docs/reliability.md §5). The input is a MapFile payload; the target wraps it in a header whose
// payload and header CRC32Cs are right (byte 0: bit 0 selects format version 1 or 2), and with
// bit 1 set first recomputes the payload's content checksum (when the payload decodes), so that
// mutations reach the parser, the size checks and Map::Check() instead of stopping at a
// checksum. The file goes through the real file path (a memfd, /proc/self/fd/N): LoadMap and
// ReadMapFileSummary (ListMaps' reader).
// Oracles (abort): either call throws anything but ParseError / IoError; a map that loads fails
// Map::Check(); the summary of a map that loads disagrees with SummarizeMap of the loaded map
// (counts, bounding box, content checksum).
#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include "core/common/error.h"
#include "evloc/map.pb.h"
#include "maps/crc32c.h"
#include "maps/map.h"

namespace {

template <typename T>
void Put(std::string& bytes, size_t offset, T value) {
  std::memcpy(bytes.data() + offset, &value, sizeof(T));
}

// A .evmap file around `payload` with valid header and payload checksums.
std::string WrapInHeader(const std::string& payload, uint32_t version) {
  std::string file(evloc::kMapFileHeaderSize, '\0');
  std::memcpy(file.data(), "EVLOCMAP", 8);
  Put<uint32_t>(file, 8, version);
  Put<uint32_t>(file, 12, evloc::Crc32c(payload));
  Put<uint64_t>(file, 16, payload.size());
  Put<uint32_t>(file, 24, evloc::ExtendCrc32c(0, file.data(), 24));
  return file + payload;
}

// `payload` with its content_crc32c set to the checksum of what it decodes to (unchanged when it
// does not decode).
std::string WithContentChecksum(const std::string& payload) {
  evloc::map_format::MapFile file;
  if (!file.ParseFromString(payload)) return payload;
  try {
    const evloc::Map map = evloc::DecodeMapPayloadUnchecked(payload, "fuzz");
    file.set_content_crc32c(evloc::ComputeMapContentChecksum(map));
    return file.SerializeAsString();
  } catch (const evloc::ParseError&) {
    return payload;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  std::string payload(reinterpret_cast<const char*>(data) + 1, size - 1);
  if ((data[0] & 2) != 0) payload = WithContentChecksum(payload);
  const std::string bytes = WrapInHeader(payload, (data[0] & 1) != 0 ? 1 : 2);
  static const int fd = memfd_create("fuzz.evmap", 0);
  if (fd < 0) std::abort();
  if (ftruncate(fd, 0) != 0 ||
      pwrite(fd, bytes.data(), bytes.size(), 0) != static_cast<ssize_t>(bytes.size())) {
    std::abort();
  }
  const std::string path = "/proc/self/fd/" + std::to_string(fd);
  bool loaded = false;
  evloc::MapInfo info;
  try {
    const evloc::Map map = evloc::LoadMap(path);
    try {
      map.Check();
    } catch (const evloc::InvalidArgumentError&) {
      std::abort();  // The loader returned a map that fails its own checks.
    }
    info = evloc::SummarizeMap(map);
    loaded = true;
  } catch (const evloc::ParseError&) {
  } catch (const evloc::IoError&) {
  }
  try {
    const evloc::MapFileSummary summary = evloc::ReadMapFileSummary(path);
    if (loaded && (summary.info.num_points != info.num_points ||
                   summary.info.num_keyframes != info.num_keyframes ||
                   summary.info.content_crc32c != info.content_crc32c ||
                   summary.info.bounding_box_min != info.bounding_box_min ||
                   summary.info.bounding_box_max != info.bounding_box_max ||
                   summary.info.has_relocalization != info.has_relocalization)) {
      std::abort();  // ListMaps would describe the map differently from the loaded map.
    }
  } catch (const evloc::ParseError&) {
    if (loaded) std::abort();  // A map that loads must summarise.
  } catch (const evloc::IoError&) {
    if (loaded) std::abort();
  }
  return 0;
}
