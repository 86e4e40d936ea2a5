// The geo-reference of a map (docs/geo.md): its GeoAnchor from a given WGS84 origin, from a file
// of surveyed points (core/geo/geo_points.h), or from the GNSS tags in the EXIF data of the
// photos the map was built from (read with exiv2), whose camera centres are aligned to the tagged
// positions robustly (core/geo/geo_alignment.h). Used by `evloc-mapper build` and `georef`.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

#include "core/geo/geo_alignment.h"
#include "maps/map.h"

namespace evloc::mapper {

// An anchor given on the command line (--geo-anchor LAT,LON,ALT[,HEADING]).
struct GivenGeoAnchor {
  // The WGS84 position of the map frame's origin.
  GeodeticPoint origin;
  // Heading of the map frame's +y axis, degrees clockwise from north (0: the map frame is the
  // ENU frame, x east, y north, z up).
  double map_y_heading_deg = 0.0;
};

// Parses `LAT,LON,ALT` or `LAT,LON,ALT,HEADING` (degrees, metres above the WGS84 ellipsoid,
// degrees). Throws UsageError naming `flag` when malformed or out of range.
GivenGeoAnchor ParseGeoAnchorFlag(const std::string& flag, const std::string& value);

// Where an anchor comes from; at most one source.
struct GeoReferenceOptions {
  // --geo-anchor.
  std::optional<GivenGeoAnchor> given;
  // --geo-points FILE.
  std::optional<std::filesystem::path> points_file;
  // --geo-exif: the GNSS tags of the keyframe images (read from the image folder).
  bool exif = false;
  // The robust alignment of the points and exif sources.
  GeoAlignmentOptions alignment;

  // True when a source is set.
  bool Any() const { return given.has_value() || points_file.has_value() || exif; }
  // Throws InvalidArgumentError when more than one source is set or the alignment options are
  // invalid.
  void Check() const;
};

// What GeoReferenceMap found.
struct GeoReferenceResult {
  // The anchor to store in the map.
  GeoAnchor anchor;
  // The alignment, for the points and exif sources.
  std::optional<GeoAlignment> alignment;
  // Points (or images) used, for messages: "23 of 25 images with GNSS tags".
  std::string inputs;
};

// Computes the anchor of `map` from options' source (which must be set). The points source
// resolves `image NAME` records to the keyframe of that name (its camera centre) and `point`
// records as given; the exif source reads the keyframe images from `image_dir` by the names the
// map records and uses those with GNSS tags. Throws InvalidArgumentError (too few points, an image
// name that is no keyframe, no tagged image, a failed alignment), ParseError (the points file)
// and IoError (an unreadable image).
GeoReferenceResult GeoReferenceMap(const Map& map, const std::filesystem::path& image_dir,
                                   const GeoReferenceOptions& options);

// Lines for the CLI: the anchor (origin, source, sigmas), what it came from and, with an
// alignment, its residual statistics.
std::string FormatGeoReference(const GeoAnchor& anchor,
                               const std::optional<GeoAlignment>& alignment,
                               const std::string& inputs);

// The WGS84 position in an image's EXIF GNSS tags (GPSLatitude/Ref, GPSLongitude/Ref, and
// GPSAltitude/Ref, 0 when absent), or nullopt when the image has no latitude and longitude.
// EXIF altitudes are above mean sea level; evloc takes them as heights above the ellipsoid
// (docs/geo.md, "Altitudes"). Throws IoError when the image cannot be read and ParseError when
// the tags are malformed (wrong count, zero denominator, out of range).
std::optional<GeodeticPoint> ReadExifGnssPosition(const std::filesystem::path& image);

// Writes `position` into an image's EXIF GNSS tags (GPSVersionID, latitude, longitude, altitude
// with their references; degrees as degrees, minutes, seconds with 1e-6 s resolution: 3 cm),
// keeping its other metadata. Throws IoError when the image cannot be written. For tests and
// the simulator's tagged photos.
void WriteExifGnssPosition(const std::filesystem::path& image, const GeodeticPoint& position);

}  // namespace evloc::mapper
