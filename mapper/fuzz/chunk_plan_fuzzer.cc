// libFuzzer target: the plan of a chunked build (mapper/chunked_build.h, ParseChunkPlan;
// docs/reliability.md), which the workers, a restarted build and an Indexed Job's pods read back
// from the shared chunk workspace instead of cutting the photos by retrieval again. Any input must
// either parse or throw ParseError; a parsed plan puts every one of the photos in exactly one
// chunk's core, every core photo among its chunk's members, and names only the photos given.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/error.h"
#include "mapper/chunked_build.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  static const std::vector<std::string> names = {"a.png", "b.png", "c.png", "d/e.png", "f g.png"};
  try {
    const evloc::mapper::StoredChunkPlan stored =
        evloc::mapper::ParseChunkPlan(text, names, "fuzz/plan.json");
    std::vector<int> owners(names.size(), 0);
    for (const evloc::mapper::ChunkPlanEntry& chunk : stored.plan.chunks) {
      if (chunk.core.empty()) std::abort();
      for (const size_t i : chunk.members) {
        if (i >= names.size()) std::abort();
      }
      for (const size_t i : chunk.core) {
        if (i >= names.size()) std::abort();
        ++owners[i];
        bool member = false;
        for (const size_t j : chunk.members) member = member || j == i;
        if (!member) std::abort();
      }
    }
    for (const int count : owners) {
      if (count != 1) std::abort();
    }
  } catch (const evloc::ParseError&) {
  }
  return 0;
}
