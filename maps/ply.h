// PLY export of a map for viewers (MeshLab, CloudCompare, PCL): binary little-endian, one vertex
// per point with `float x y z nx ny nz`, the normal being the unit 3D gradient direction.
#pragma once

#include <filesystem>

#include "maps/map.h"

namespace evloc {

// Writes the points of `map` as a binary little-endian PLY file, atomically. Throws
// InvalidArgumentError when positions and gradients differ in size, IoError when the file
// cannot be written.
void WritePly(const std::filesystem::path& path, const Map& map);

}  // namespace evloc
