// The edge kinds of an evloc-sim dataset's exact scene, for the gradient measures of
// map_accuracy.h: the one part of the map-accuracy tool that needs the simulator's world
// (library evloc_map_accuracy_scene), kept apart so that evloc_map_accuracy does not link it.
#pragma once

#include <filesystem>
#include <vector>

#include "maps/map.h"

namespace evloc::mapper {

// Per point of an evloc-sim dataset's gt_map: whether its gradient is defined by the scene
// (texture edges and concave creases) or not (convex creases). The edges are sampled again from
// the dataset's scene (info.json "scene": the default room or a scene JSON) with the options the
// simulator uses, and must match the reference map point for point. Throws IoError / ParseError
// when info.json or the scene cannot be read, InvalidArgumentError when the points differ.
std::vector<bool> ReferenceGradientDefined(const std::filesystem::path& dataset,
                                           const Map& reference);

}  // namespace evloc::mapper
