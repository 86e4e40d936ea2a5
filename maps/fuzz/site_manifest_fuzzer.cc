// libFuzzer target: the site manifest reader (maps/site.h, docs/map-format.md "Sites";
// docs/reliability.md). Byte 0 selects the input: even, the rest is a whole site.manifest file
// (DecodeSiteManifest: magic, version, length, checksum, payload); odd, the rest is a
// SiteManifest payload that this target wraps in a valid header (length and CRC32C recomputed),
// so that mutations reach the protobuf and the manifest's own checks instead of stopping at the
// checksum. Any input must either decode or throw ParseError; what decodes passes
// SiteManifest::Check(), encodes again, decodes to the same tiles, and its geo anchor (if any)
// decodes.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "core/common/error.h"
#include "maps/crc32c.h"
#include "maps/site.h"

namespace {

std::string WithHeader(std::string_view payload) {
  std::string bytes = "EVLOCSIT";
  const auto put = [&bytes](uint64_t value, int size) {
    for (int i = 0; i < size; ++i) bytes.push_back(static_cast<char>(value >> (8 * i)));
  };
  put(evloc::kSiteFormatVersion, 4);
  put(evloc::Crc32c(payload), 4);
  put(payload.size(), 8);
  bytes.append(payload);
  return bytes;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::string_view rest(reinterpret_cast<const char*>(data) + 1, size - 1);
  const std::string bytes = (data[0] & 1) == 0 ? std::string(rest) : WithHeader(rest);
  evloc::SiteManifest manifest;
  try {
    manifest = evloc::DecodeSiteManifest(bytes, "fuzz.manifest");
  } catch (const evloc::ParseError&) {
    return 0;
  }
  try {
    manifest.Check();
    const evloc::SiteManifest again =
        evloc::DecodeSiteManifest(evloc::EncodeSiteManifest(manifest), "again");
    if (again.tiles.size() != manifest.tiles.size() || again.version != manifest.version) {
      std::abort();
    }
    for (size_t t = 0; t < manifest.tiles.size(); ++t) {
      if (manifest.Find(manifest.tiles[t].index) != t) std::abort();
    }
    (void)evloc::SummarizeSite(manifest);
    (void)evloc::SiteGeoAnchor(manifest);  // Checked by the decoder: never throws here.
  } catch (const evloc::Error&) {
    std::abort();  // The reader returned a manifest that fails its own checks.
  }
  return 0;
}
