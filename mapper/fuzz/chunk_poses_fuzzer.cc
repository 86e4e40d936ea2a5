// libFuzzer target: the poses file of a finished chunk (mapper/chunked_build.h, ParseChunkPoses;
// docs/reliability.md), which a resumed or merging build reads back from the shared chunk
// workspace. Any input must either parse or throw ParseError; every parsed pose has a finite
// translation and a unit quaternion, and its name is one token without white space.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "core/common/error.h"
#include "mapper/chunked_build.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const auto poses = evloc::mapper::ParseChunkPoses(text, "fuzz/poses.txt");
    for (const auto& [name, pose] : poses) {
      if (name.empty() || name.find_first_of(" \t\n") != std::string::npos) std::abort();
      if (!pose.translation.allFinite()) std::abort();
      if (std::abs(pose.rotation.norm() - 1.0) > 1e-9) std::abort();
    }
  } catch (const evloc::ParseError&) {
  }
  return 0;
}
