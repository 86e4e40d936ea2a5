// The geodetic trajectory file of `evloc-track --geo` and `evloc-replay --geo` (docs/geo.md,
// "Geodetic trajectories"): one pose a line,
//
//   t_s latitude_deg longitude_deg altitude_m heading_deg pitch_deg east_m north_m up_m
//
// after a '#' header line naming the columns and one giving the anchor: the time as an exact
// decimal of nanoseconds, WGS84 latitude and longitude (10 decimals: 0.01 mm), height above the
// ellipsoid, the heading and pitch of GeoPose, and the camera centre in the anchor's ENU frame.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/geo/geo_anchor.h"

namespace evloc {

// A geodetic pose at a time.
struct TimedGeoPose {
  // Time, nanoseconds.
  int64_t t_ns = 0;
  // The pose.
  GeoPose pose;
};

// The text of a geodetic trajectory file for `poses` under `anchor`.
std::string FormatGeoTrajectory(const GeoAnchor& anchor, const std::vector<TimedGeoPose>& poses);

// Writes FormatGeoTrajectory atomically (a crash never leaves a half-written file). Throws
// IoError when the file cannot be written.
void WriteGeoTrajectory(const std::filesystem::path& path, const GeoAnchor& anchor,
                        const std::vector<TimedGeoPose>& poses);

// The message for a geodetic request on a map without a geo anchor, naming `map` and how to add
// one; evloc-track, evloc-replay and the service use these words.
std::string MissingGeoAnchorMessage(const std::string& map);

}  // namespace evloc
