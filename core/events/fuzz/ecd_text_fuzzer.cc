// libFuzzer target: the ECD text reader (docs/reliability.md). Reads the input in blocks of a
// size taken from its first byte and checks that valid output never depends on the block size.
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include "core/common/error.h"
#include "core/events/ecd_text.h"

namespace {

// Reads every event; returns false when the input is malformed.
bool ReadAll(const std::string& text, size_t block, evloc::EventBuffer* events) {
  try {
    evloc::EcdTextReader reader(std::make_unique<std::istringstream>(text), "fuzz.txt");
    while (reader.Read(block, events) > 0) {
    }
    return true;
  } catch (const evloc::ParseError&) {
    return false;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const size_t block = 1 + data[0] % 13;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  evloc::EventBuffer whole, blocked;
  const bool whole_ok = ReadAll(text, 1 << 20, &whole);
  const bool blocked_ok = ReadAll(text, block, &blocked);
  if (whole_ok != blocked_ok || !whole.IsConsistent()) std::abort();
  if (whole_ok && !(whole == blocked)) std::abort();
  for (size_t i = 0; i < whole.size(); ++i) {
    if (whole.t_ns[i] < 0 || (whole.polarity[i] != 1 && whole.polarity[i] != -1)) std::abort();
  }
  return 0;
}
