// Prints the render time per frame of the default room (docs/sim-scene.md, "Measured speed").
// Usage: evloc_sim_render_benchmark [width height frames]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>

#include "tools/sim/renderer.h"

int main(int argc, char** argv) {
  using evloc::sim::Renderer;
  const int width = argc > 2 ? std::atoi(argv[1]) : 640;
  const int height = argc > 2 ? std::atoi(argv[2]) : 480;
  const int frames = argc > 3 ? std::atoi(argv[3]) : 200;
  const evloc::sim::Scene room = evloc::sim::MakeDefaultRoom();
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
    // A slow pan around the room, slightly tilted down.
    const double yaw = 2 * M_PI * i / frames;
    const Eigen::Vector3d forward(std::sin(yaw) * std::cos(0.3), std::cos(yaw) * std::cos(0.3),
                                  -std::sin(0.3));
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    Eigen::Matrix3d rotation;
    rotation << right, forward.cross(right), forward;
    const evloc::Rigid3d pose(Eigen::Quaterniond(rotation), centre);
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
