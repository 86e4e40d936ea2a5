// libFuzzer target: the geo points file reader (core/geo/geo_points.h, docs/reliability.md).
// Any input must either parse or throw ParseError; what parses has at least one record, every
// position passes CheckGeodeticPoint, map points are finite, line numbers increase and image
// names are unique and without blanks.
#include <cstdint>
#include <cstdlib>
#include <set>
#include <string>
#include <string_view>

#include "core/common/error.h"
#include "core/geo/geo_points.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const auto records = evloc::ParseGeoPoints(text, "fuzz.txt");
    if (records.empty()) std::abort();
    std::set<std::string> names;
    int64_t previous_line = 0;
    for (const evloc::GeoPointRecord& record : records) {
      evloc::CheckGeodeticPoint(record.geodetic, "fuzz");  // throws InvalidArgumentError: abort
      if (!record.p_map.allFinite() || record.line <= previous_line) std::abort();
      previous_line = record.line;
      if (record.kind == evloc::GeoPointRecord::Kind::kImage) {
        if (record.image_name.empty() ||
            record.image_name.find_first_of(" \t\n") != std::string::npos ||
            !names.insert(record.image_name).second) {
          std::abort();
        }
      }
    }
  } catch (const evloc::ParseError&) {
  } catch (...) {
    std::abort();
  }
  return 0;
}
