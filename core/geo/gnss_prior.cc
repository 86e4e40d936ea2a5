#include "core/geo/gnss_prior.h"

#include <cmath>
#include <utility>
#include <vector>

#include "core/common/cli.h"
#include "core/common/error.h"

namespace evloc {

void CheckGnssPrior(const GnssPrior& prior, const std::string& what) {
  CheckGeodeticPoint(prior.position, what);
  for (const auto& [name, value] : {std::pair{"horizontal_accuracy_m", prior.horizontal_accuracy_m},
                                    {"vertical_accuracy_m", prior.vertical_accuracy_m}}) {
    if (!std::isfinite(value) || value <= 0.0 || value > kMaxGnssAccuracyM) {
      throw InvalidArgumentError(what + "." + name + " " + std::to_string(value) +
                                 " is outside (0, " + std::to_string(kMaxGnssAccuracyM) + "] m");
    }
  }
}

GnssPrior ParseGnssPrior(std::string_view flag, std::string_view text) {
  std::vector<double> values;
  size_t start = 0;
  while (true) {
    const size_t comma = text.find(',', start);
    values.push_back(ParseDoubleFlag(flag, text.substr(start, comma - start)));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  if (values.size() != 4 && values.size() != 5) {
    throw InvalidArgumentError(std::string(flag) + " '" + std::string(text) +
                               "': give LAT,LON,ALT,SIGMA or LAT,LON,ALT,SIGMA,SIGMA_V");
  }
  GnssPrior prior;
  prior.position = {values[0], values[1], values[2]};
  prior.horizontal_accuracy_m = values[3];
  prior.vertical_accuracy_m = values.size() == 5 ? values[4] : values[3];
  CheckGnssPrior(prior, std::string(flag));
  return prior;
}

double GnssSearchRadiusM(const GnssPrior& prior, const GeoAnchor& anchor) {
  return kGnssPriorSigmas * std::sqrt(prior.horizontal_accuracy_m * prior.horizontal_accuracy_m +
                                      prior.vertical_accuracy_m * prior.vertical_accuracy_m +
                                      anchor.horizontal_sigma_m * anchor.horizontal_sigma_m +
                                      anchor.vertical_sigma_m * anchor.vertical_sigma_m);
}

}  // namespace evloc
