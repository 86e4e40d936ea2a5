// Import of Canny-EVT semi-dense maps stored as PCD (docs/map-format.md, docs/map-format.md):
// `FIELDS x y z normal_x normal_y normal_z` (other fields are skipped), where normal_* is not a
// unit normal but a point 2-3 cm from xyz along the 3D gradient, in world coordinates. The
// gradient is g = normalize(normal - xyz). DATA ascii and DATA binary are read.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "maps/map.h"

namespace evloc {

// How a PCD map is imported.
struct PcdImportOptions {
  // Points whose gradient end point lies closer than this to the point have no usable gradient
  // direction and are dropped, metres.
  double min_gradient_offset_m = 1e-6;

  // Throws InvalidArgumentError unless min_gradient_offset_m is finite and > 0.
  void Check() const;
};

// What an import kept and dropped.
struct PcdImportReport {
  // Points declared by the file (POINTS).
  size_t num_points_in_file = 0;
  // Points kept in the map.
  size_t num_imported = 0;
  // Points dropped because |normal - xyz| < min_gradient_offset_m.
  size_t num_dropped_zero_gradient = 0;
  // Points dropped because a coordinate is NaN or infinite.
  size_t num_dropped_non_finite = 0;
  // 0-based indices in the file of the first (at most 10) dropped points.
  std::vector<size_t> first_dropped_points;
  // Median |normal - xyz| over the kept points, metres (Canny-EVT writes about 0.02-0.03).
  double median_gradient_offset_m = 0.0;
};

// A map imported from a PCD file, with its report.
struct PcdImport {
  // The points, with gradients, no keyframes and no cameras; sigma, magnitude unknown (0),
  // source keyframe kNoKeyframe. Provenance is left for the caller to fill.
  Map map;
  // What was kept and dropped.
  PcdImportReport report;
};

// Reads a Canny-EVT PCD map. Throws IoError when the file cannot be read, ParseError naming the
// file and the line (ASCII) or byte offset (binary) when it is malformed or lacks the fields,
// InvalidArgumentError for invalid options.
PcdImport ImportCannyEvtPcd(const std::filesystem::path& path,
                            const PcdImportOptions& options = {});

}  // namespace evloc
