// libFuzzer target: the Prophesee .raw reader, header parsing included (docs/reliability.md).
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include "core/common/error.h"
#include "core/events/prophesee_raw.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  try {
    evloc::PropheseeRawReader reader(std::make_unique<std::istringstream>(bytes), "fuzz.raw");
    evloc::EventBuffer events;
    while (reader.Read(333, &events) > 0) {
    }
    const auto sensor_size = reader.sensor_size();
    for (size_t i = 0; i < events.size(); ++i) {
      if (sensor_size && !sensor_size->Contains(events.x[i], events.y[i])) std::abort();
    }
  } catch (const evloc::ParseError&) {
  }
  return 0;
}
