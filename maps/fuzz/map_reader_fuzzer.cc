// libFuzzer target: the .evmap reader, including the relocalization data of format v2
// (docs/reliability.md). Byte 0 selects the input: even, the rest is a whole .evmap file
// (LoadMapFromBytes: header, checksums, payload); odd, the rest is a MapFile payload decoded
// without the checksums (DecodeMapPayloadUnchecked), so that mutations reach the field checks
// instead of stopping at a checksum. Any input must either load or throw ParseError; what loads
// passes Map::Check() and has a computable content checksum.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "core/common/error.h"
#include "maps/map.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::string_view bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    const evloc::Map map = (data[0] & 1) == 0 ? evloc::LoadMapFromBytes(bytes, "fuzz.evmap")
                                              : evloc::DecodeMapPayloadUnchecked(bytes, "fuzz");
    try {
      map.Check();
    } catch (const evloc::InvalidArgumentError&) {
      std::abort();  // The reader returned a map that fails its own checks.
    }
    if (evloc::HasRelocalizationData(map) &&
        map.relocalization->keyframes.size() != map.keyframes.size()) {
      std::abort();
    }
    (void)evloc::ComputeMapContentChecksum(map);
  } catch (const evloc::ParseError&) {
  }
  return 0;
}
