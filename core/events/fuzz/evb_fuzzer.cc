// libFuzzer target: the .evb reader (docs/reliability.md). Any input must either read or
// throw ParseError; what reads must lie inside the header's sensor size.
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include "core/common/error.h"
#include "core/events/evb.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  try {
    evloc::EvbReader reader(std::make_unique<std::istringstream>(bytes), "fuzz.evb");
    evloc::EventBuffer events;
    while (reader.Read(1000, &events) > 0) {
    }
    if (!events.IsConsistent()) std::abort();
    const auto sensor_size = reader.sensor_size();
    for (size_t i = 0; i < events.size(); ++i) {
      if (sensor_size && !sensor_size->Contains(events.x[i], events.y[i])) std::abort();
    }
  } catch (const evloc::ParseError&) {
  }
  return 0;
}
