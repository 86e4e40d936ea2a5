// libFuzzer target: the EVT 2.0 streaming decoder (docs/reliability.md).
#include "core/events/fuzz/decoder_fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return evloc::fuzz::FuzzDecoder<evloc::Evt2Decoder>(data, size);
}
