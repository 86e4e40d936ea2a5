// Shared body of the Prophesee decoder fuzz targets: decodes the input whole and in chunks whose
// sizes come from the input, and traps when the outputs differ or an invariant breaks.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "core/common/error.h"
#include "core/events/event.h"
#include "core/events/prophesee_decoder.h"

namespace evloc::fuzz {

template <typename Decoder>
void DecodeOrCatch(Decoder& decoder, const uint8_t* data, size_t size, EventBuffer* out) {
  try {
    decoder.Decode(data, size, out);
  } catch (const ParseError&) {
    // Malformed words are expected in fuzzed input; the decoder must stay usable.
  }
}

template <typename Decoder>
int FuzzDecoder(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const size_t chunk_size = 1 + data[0] % 37;
  ++data;
  --size;
  PropheseeDecoderOptions options;
  options.sensor_size = SensorSize{1280, 720};
  Decoder whole_decoder(options);
  EventBuffer whole;
  DecodeOrCatch(whole_decoder, data, size, &whole);
  Decoder chunk_decoder(options);
  EventBuffer chunked;
  for (size_t offset = 0; offset < size; offset += chunk_size) {
    DecodeOrCatch(chunk_decoder, data + offset, std::min(chunk_size, size - offset), &chunked);
  }
  if (!whole.IsConsistent() || !(whole == chunked)) std::abort();
  if (whole.size() != whole_decoder.statistics().events) std::abort();
  if (whole_decoder.statistics().bytes != size) std::abort();
  for (size_t i = 0; i < whole.size(); ++i) {
    if (whole.x[i] >= 1280 || whole.y[i] >= 720) std::abort();
    if (whole.polarity[i] != 1 && whole.polarity[i] != -1) std::abort();
  }
  return 0;
}

}  // namespace evloc::fuzz
