// Prints the render time per frame of the default room or of the car park site
// (docs/sim-scene.md, "Measured speed").
// Usage: evloc_sim_render_benchmark [width height frames [room|carpark|carpark-night]]
// The room: a 360 degree pan from its camera region's centre. The car park: a forward camera
// 1.5 m above the route, tilted 5 degrees down, over the first lane and its turn.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>

#include <string>

#include "tools/sim/carpark.h"
#include "tools/sim/renderer.h"

int main(int argc, char** argv) {
  using evloc::sim::Renderer;
  const int width = argc > 2 ? std::atoi(argv[1]) : 640;
  const int height = argc > 2 ? std::atoi(argv[2]) : 480;
  const int frames = argc > 3 ? std::atoi(argv[3]) : 200;
  const std::string scene_name = argc > 4 ? argv[4] : "room";
  if (scene_name != "room" && scene_name != "carpark" && scene_name != "carpark-night") {
    std::fprintf(stderr, "unknown scene '%s': expected room, carpark or carpark-night\n",
                 scene_name.c_str());
    return 2;
  }
  evloc::sim::CarPark park;
  if (scene_name != "room") {
    park = evloc::sim::MakeCarPark();
    if (scene_name == "carpark-night") {
      evloc::sim::ApplyTimeOfDay(evloc::sim::TimeOfDay::kNight, park.lamps, &park.scene);
    }
  }
  const evloc::sim::Scene room = scene_name == "room" ? evloc::sim::MakeDefaultRoom() : park.scene;
  const evloc::Camera camera = evloc::Camera::Pinhole(width, height, 0.5 * width, 0.5 * width,
                                                      0.5 * (width - 1), 0.5 * (height - 1));
  const auto construct_start = std::chrono::steady_clock::now();
  const Renderer renderer(room, camera);
  const double construct_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - construct_start)
          .count();
  cv::Mat gray;
  double total_ms = 0, supersampled = 0, candidates = 0;
  const Eigen::Vector3d centre = room.camera_region.center();
  const std::clock_t cpu_start = std::clock();
  for (int i = 0; i < frames; ++i) {
    // A slow pan around the room, slightly tilted down; or a drive along the route.
    double yaw = 2 * M_PI * i / frames, pitch = 0.3;
    Eigen::Vector3d position = centre;
    if (scene_name != "room") {
      const size_t route_index =
          std::min(park.drive_route.size() - 2, static_cast<size_t>(2000.0 * i / frames));
      const Eigen::Vector2d at = park.drive_route[route_index];
      const Eigen::Vector2d along = park.drive_route[route_index + 1] - at;
      position = Eigen::Vector3d(at.x(), at.y(), 1.5);
      yaw = std::atan2(along.x(), along.y());
      pitch = 5 * M_PI / 180;
    }
    const Eigen::Vector3d forward(std::sin(yaw) * std::cos(pitch), std::cos(yaw) * std::cos(pitch),
                                  -std::sin(pitch));
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    Eigen::Matrix3d rotation;
    rotation << right, forward.cross(right), forward;
    const evloc::Rigid3d pose(Eigen::Quaterniond(rotation), position);
    evloc::sim::RenderStats stats;
    const auto start = std::chrono::steady_clock::now();
    renderer.Render(pose, &gray, nullptr, nullptr, &stats);
    total_ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    supersampled += stats.supersampled_fraction;
    candidates += stats.mean_candidates_per_tile;
  }
  const double cpu_ms = 1000.0 * static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  std::printf(
      "%dx%d, %zu surfaces, renderer setup %.1f ms, %d frames: %.2f ms wall and %.2f ms CPU "
      "(all threads) per gray frame, %.1f%% pixels supersampled, %.1f candidate surfaces per "
      "16x16 tile\n",
      width, height, room.surfaces.size(), construct_ms, frames, total_ms / frames, cpu_ms / frames,
      100 * supersampled / frames, candidates / frames);
  return 0;
}
