// A GNSS fix used as a prior on where a camera is (docs/geo.md, "GNSS priors"): its WGS84
// position and accuracies, their checks, the text form of the command-line flags (--gnss) and
// the radius of the search around it.
#pragma once

#include <string>
#include <string_view>

#include "core/geo/geo_anchor.h"
#include "core/geo/geodetic.h"

namespace evloc {

// A fix's search radius is this many sigmas of its and the anchor's combined uncertainty.
inline constexpr double kGnssPriorSigmas = 3.0;
// The largest accuracy a fix may state, metres (a coarser fix narrows nothing on Earth).
inline constexpr double kMaxGnssAccuracyM = 10000.0;

// A validated GNSS fix (TrackRequest.gnss_fix, LocateRequest.gnss_fix, --gnss).
struct GnssPrior {
  // The WGS84 position.
  GeodeticPoint position;
  // One-sigma accuracies, metres.
  double horizontal_accuracy_m = 0.0;
  double vertical_accuracy_m = 0.0;
};

// Throws InvalidArgumentError naming `what` and the field unless the position passes
// CheckGeodeticPoint and both accuracies are finite and in (0, kMaxGnssAccuracyM].
void CheckGnssPrior(const GnssPrior& prior, const std::string& what);

// Parses "LAT,LON,ALT,SIGMA" or "LAT,LON,ALT,SIGMA,SIGMA_V" (degrees, metres; SIGMA_V defaults
// to SIGMA) and checks it; errors name `flag`.
GnssPrior ParseGnssPrior(std::string_view flag, std::string_view text);

// The radius of the search around a fix: kGnssPriorSigmas times the fix's and the anchor's
// horizontal and vertical sigmas combined, metres.
double GnssSearchRadiusM(const GnssPrior& prior, const GeoAnchor& anchor);

}  // namespace evloc
