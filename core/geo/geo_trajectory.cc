#include "core/geo/geo_trajectory.h"

#include <cinttypes>
#include <cstdio>

#include "core/common/file_util.h"

namespace evloc {

std::string FormatGeoTrajectory(const GeoAnchor& anchor, const std::vector<TimedGeoPose>& poses) {
  std::string text =
      "# t_s latitude_deg longitude_deg altitude_m heading_deg pitch_deg east_m north_m up_m\n";
  char line[320];
  std::snprintf(line, sizeof(line),
                "# anchor %.10f %.10f %.4f source %s (WGS84, heights above the ellipsoid)\n",
                anchor.origin.latitude_deg, anchor.origin.longitude_deg, anchor.origin.altitude_m,
                anchor.source.c_str());
  text += line;
  for (const TimedGeoPose& timed : poses) {
    const int64_t t = timed.t_ns;
    const uint64_t magnitude = t < 0 ? 0 - static_cast<uint64_t>(t) : static_cast<uint64_t>(t);
    const GeoPose& pose = timed.pose;
    std::snprintf(line, sizeof(line),
                  "%s%" PRIu64 ".%09" PRIu64 " %.10f %.10f %.4f %.4f %.4f %.4f %.4f %.4f\n",
                  t < 0 ? "-" : "", magnitude / 1000000000u, magnitude % 1000000000u,
                  pose.position.latitude_deg, pose.position.longitude_deg, pose.position.altitude_m,
                  pose.heading_deg, pose.pitch_deg, pose.enu.x(), pose.enu.y(), pose.enu.z());
    text += line;
  }
  return text;
}

void WriteGeoTrajectory(const std::filesystem::path& path, const GeoAnchor& anchor,
                        const std::vector<TimedGeoPose>& poses) {
  WriteFileAtomically(path, FormatGeoTrajectory(anchor, poses));
}

std::string MissingGeoAnchorMessage(const std::string& map) {
  return "map '" + map +
         "' has no geo anchor, so poses cannot be given in WGS84; add one with `evloc-mapper "
         "georef --map MAP --geo-anchor LAT,LON,ALT` (or --geo-points FILE, --geo-exif)";
}

}  // namespace evloc
