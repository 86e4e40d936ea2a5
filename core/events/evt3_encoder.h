// A streaming encoder of events into Prophesee EVT 3.0 words (docs/event-formats.md §3.1), the
// inverse of Evt3Decoder (prophesee_decoder.h): for clients that stream raw EVT 3.0 to the
// localizer (evloc-replay --encoding evt3) and for tests.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/events/event.h"

namespace evloc {

// Encodes time-ordered events with microsecond times into EVT 3.0. Uses EVT_TIME_HIGH,
// EVT_TIME_LOW, EVT_ADDR_Y and EVT_ADDR_X words only (no vector words): 2 bytes per event plus
// a word whenever the row or the time changes. Long gaps are bridged with intermediate
// EVT_TIME_HIGH words so that a decoder unrolls the 24-bit counter correctly. Not thread-safe.
class Evt3Encoder {
 public:
  // Appends the words of `events` to `out`. Event times are sensor times in nanoseconds and must
  // be multiples of 1000, at or after 0, and not decrease (also across calls); coordinates must
  // be below 2048. Throws InvalidArgumentError (nothing appended) otherwise.
  void Encode(const EventBuffer& events, std::string* out);

 private:
  void Word(uint16_t word, std::string* out);

  // Unrolled time >> 12 of the last EVT_TIME_HIGH, microseconds / 4096.
  std::optional<uint64_t> time_high_;
  std::optional<uint32_t> time_low_;
  std::optional<uint32_t> y_;
  int64_t last_t_ns_ = 0;
};

}  // namespace evloc
