// The geo points file of `evloc-mapper build|georef --geo-points FILE` (docs/geo.md, "Geo points
// file"): WGS84 positions of photos (by image name) or of map-frame points. One record a line:
//
//   image NAME LATITUDE LONGITUDE ALTITUDE
//   point X Y Z LATITUDE LONGITUDE ALTITUDE
//
// degrees and metres above the WGS84 ellipsoid; X Y Z in the map frame, metres. Fields are
// separated by spaces or tabs; NAME has no blanks; '#' starts a comment line; blank lines are
// skipped. The reader is strict: every error names the file and line.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/geo/geodetic.h"

namespace evloc {

// One line of a geo points file.
struct GeoPointRecord {
  enum class Kind { kImage, kPoint };
  Kind kind = Kind::kImage;
  // The image's name as the map's keyframes name it (Kind::kImage).
  std::string image_name;
  // The point in the map frame, metres (Kind::kPoint).
  Eigen::Vector3d p_map = Eigen::Vector3d::Zero();
  // Its WGS84 position.
  GeodeticPoint geodetic;
  // 1-based line number in the file.
  int64_t line = 0;
};

// Longest line accepted, bytes (a bound against malformed input).
inline constexpr size_t kMaxGeoPointsLineBytes = 4096;

// Parses the text of a geo points file; `source` names it in errors. Throws ParseError ("FILE:
// line N: ...") on an unknown record kind, a wrong field count, a number that is not a whole
// finite decimal, a latitude/longitude/altitude out of range (CheckGeodeticPoint), a non-finite
// map point, a duplicated image name, an over-long line, a NUL byte, or a file without records.
std::vector<GeoPointRecord> ParseGeoPoints(std::string_view text, const std::string& source);

// Reads and parses a geo points file. Throws IoError when it cannot be read, ParseError as above.
std::vector<GeoPointRecord> ReadGeoPoints(const std::filesystem::path& path);

}  // namespace evloc
