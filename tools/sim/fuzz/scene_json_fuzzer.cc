// libFuzzer target: the simulator's scene JSON reader (docs/sim-scene.md, "Scene JSON";
// docs/reliability.md), with the lighting fields of the car park site (daylight, sky,
// point_lights). Any input must either parse or throw ParseError; a parsed scene passes
// Scene::Check(), and what SceneToJson writes of it parses again to the same surfaces and lights.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "core/common/error.h"
#include "tools/sim/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  evloc::sim::Scene scene;
  try {
    scene = evloc::sim::ParseSceneJson(text, "fuzz.json");
  } catch (const evloc::ParseError&) {
    return 0;
  }
  try {
    scene.Check();
  } catch (const evloc::InvalidArgumentError&) {
    std::abort();  // The reader returned a scene that fails its own checks.
  }
  const std::string written = evloc::sim::SceneToJson(scene);
  try {
    const evloc::sim::Scene again = evloc::sim::ParseSceneJson(written, "written.json");
    if (again.surfaces.size() != scene.surfaces.size() ||
        again.point_lights.size() != scene.point_lights.size() ||
        again.daylight != scene.daylight || again.sky != scene.sky) {
      std::abort();  // The writer lost or changed something.
    }
  } catch (const evloc::ParseError&) {
    std::abort();  // The reader refused what the writer wrote.
  }
  return 0;
}
