// Makes a large map and site for the serving benchmark (docs/benchmarks.md, "Sites") from a
// small map: COLUMNS x ROWS copies of MAP, copy (c, r) moved by (c * PITCH, r * PITCH, 0) metres,
// written whole as OUT/whole/map.evmap and tiled (TILE metres, OVERLAP metres) as OUT/site. The
// sessions of `evloc-load --spread COLUMNSxROWS:PITCH` then start in every copy, each on its own
// tiles; the grid origin is (0, 0), so tile corners lie at the centre of every copy whose
// position is a multiple of the tile size. Usage: evloc_replicated_site MAP OUT COLUMNS ROWS PITCH
// TILE OVERLAP
#include <cstdlib>
#include <iostream>
#include <string>

#include "maps/map_directory.h"
#include "maps/site.h"

int main(int argc, char** argv) {
  if (argc != 8) {
    std::cerr << "usage: evloc_replicated_site MAP OUT COLUMNS ROWS PITCH TILE OVERLAP\n";
    return 2;
  }
  try {
    const evloc::Map source = evloc::LoadMap(evloc::ResolveMapFile(argv[1]));
    const std::filesystem::path out = argv[2];
    const int columns = std::stoi(argv[3]);
    const int rows = std::stoi(argv[4]);
    const double pitch = std::stod(argv[5]);
    evloc::Map map;
    map.cameras = source.cameras;
    map.provenance = source.provenance;
    map.provenance.tool = "evloc_replicated_site";
    map.Reserve(source.size() * static_cast<size_t>(columns * rows));
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < columns; ++c) {
        const Eigen::Vector3f offset(static_cast<float>(c * pitch), static_cast<float>(r * pitch),
                                     0.0f);
        const auto first_point = static_cast<uint32_t>(map.size());
        const auto first_keyframe = static_cast<uint32_t>(map.keyframes.size());
        for (const evloc::Keyframe& keyframe : source.keyframes) {
          evloc::Keyframe moved = keyframe;
          evloc::Rigid3d world_from_cam = keyframe.cam_from_world.Inverse();
          world_from_cam.translation += offset.cast<double>();
          moved.cam_from_world = world_from_cam.Inverse();
          for (uint32_t& point : moved.visible_points) point += first_point;
          map.keyframes.push_back(std::move(moved));
        }
        for (size_t i = 0; i < source.size(); ++i) {
          const uint32_t keyframe = source.source_keyframe[i];
          map.AddPoint(source.positions[i] + offset, source.gradients[i],
                       source.inverse_depth_sigma[i], source.gradient_magnitude[i],
                       keyframe == evloc::kNoKeyframe ? keyframe : keyframe + first_keyframe);
        }
      }
    }
    evloc::MapDirectoryWriteOptions write;
    write.overwrite = true;
    write.write_ply = false;
    evloc::WriteMapDirectory(out / "whole", map, write);
    evloc::TilingOptions tiling;
    tiling.tile_size_m = std::stod(argv[6]);
    tiling.overlap_m = std::stod(argv[7]);
    tiling.origin = Eigen::Vector2d(0.0, 0.0);  // Tile corners at the copies' centres.
    tiling.overwrite = true;
    const evloc::SiteManifest manifest = evloc::TileMap(map, out / "site", tiling);
    std::cout << map.size() << " points, " << map.keyframes.size() << " keyframes; "
              << manifest.tiles.size() << " tiles, version " << manifest.version << "\n";
  } catch (const std::exception& error) {
    std::cerr << "evloc_replicated_site: error: " << error.what() << "\n";
    return 1;
  }
  return 0;
}
