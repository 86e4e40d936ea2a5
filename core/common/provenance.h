// What the tools stamp on the files they write (map provenance, dataset info): the evloc version
// and the current time in UTC.
#pragma once

#include <string>

namespace evloc {

// The evloc version, the CMake project version (e.g. "0.1.0").
std::string ToolVersion();

// The current time, UTC, ISO 8601 to the second with a trailing Z ("2024-05-01T12:00:00Z").
std::string UtcNowIso8601();

}  // namespace evloc
