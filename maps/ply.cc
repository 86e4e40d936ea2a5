#include "maps/ply.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc {

void WritePly(const std::filesystem::path& path, const Map& map) {
  static_assert(std::endian::native == std::endian::little,
                "WritePly writes the host floats as little-endian");
  if (map.gradients.size() != map.positions.size()) {
    throw InvalidArgumentError("cannot write PLY '" + path.string() + "': the map has " +
                               std::to_string(map.positions.size()) + " positions but " +
                               std::to_string(map.gradients.size()) + " gradients");
  }
  const std::string header =
      "ply\n"
      "format binary_little_endian 1.0\n"
      "comment evloc map points; normal = unit 3D gradient direction, metres\n"
      "element vertex " +
      std::to_string(map.size()) +
      "\n"
      "property float x\n"
      "property float y\n"
      "property float z\n"
      "property float nx\n"
      "property float ny\n"
      "property float nz\n"
      "end_header\n";
  WriteFileAtomically(path, [&](std::ostream& stream) {
    stream.write(header.data(), static_cast<std::streamsize>(header.size()));
    constexpr size_t kPointsPerChunk = 65536;
    std::vector<float> chunk;
    chunk.reserve(6 * kPointsPerChunk);
    for (size_t begin = 0; begin < map.size(); begin += kPointsPerChunk) {
      const size_t end = std::min(map.size(), begin + kPointsPerChunk);
      chunk.clear();
      for (size_t i = begin; i < end; ++i) {
        chunk.insert(chunk.end(), map.positions[i].data(), map.positions[i].data() + 3);
        chunk.insert(chunk.end(), map.gradients[i].data(), map.gradients[i].data() + 3);
      }
      stream.write(reinterpret_cast<const char*>(chunk.data()),
                   static_cast<std::streamsize>(chunk.size() * sizeof(float)));
    }
  });
}

}  // namespace evloc
