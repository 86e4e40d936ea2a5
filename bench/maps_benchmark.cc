// Map storage and visibility benchmarks (docs/map-format.md, "Performance"): save and load of a
// 1,000,000-point map with 300 keyframes, and visibility queries on keyframe and voxel indices.
#include <benchmark/benchmark.h>

#include <filesystem>

#include "maps/map.h"
#include "maps/synthetic_map.h"
#include "maps/visibility.h"

namespace evloc {
namespace {

constexpr size_t kNumPoints = 1'000'000;
constexpr size_t kNumKeyframes = 300;

// The benchmark map, built once: 1M points on a 60 m corridor, 300 keyframes.
const Map& BenchmarkMap() {
  static const Map map = [] {
    CorridorMapOptions options;
    options.num_points = kNumPoints;
    options.num_keyframes = kNumKeyframes;
    options.length_m = 60.0;
    options.keyframe_visibility_depth_m = 3.0;
    return MakeCorridorMap(options);
  }();
  return map;
}

std::filesystem::path BenchmarkFile() {
  return std::filesystem::temp_directory_path() / "evloc_maps_benchmark.evmap";
}

void BM_SaveMap(benchmark::State& state) {
  const Map& map = BenchmarkMap();
  for (auto _ : state) SaveMap(BenchmarkFile(), map);
  state.counters["bytes"] = static_cast<double>(std::filesystem::file_size(BenchmarkFile()));
  state.counters["points"] = static_cast<double>(map.size());
  size_t entries = 0;
  for (const Keyframe& keyframe : map.keyframes) entries += keyframe.visible_points.size();
  state.counters["visibility_entries"] = static_cast<double>(entries);
}
BENCHMARK(BM_SaveMap)->Unit(benchmark::kMillisecond)->Iterations(3);

void BM_LoadMap(benchmark::State& state) {
  SaveMap(BenchmarkFile(), BenchmarkMap());
  for (auto _ : state) {
    const Map map = LoadMap(BenchmarkFile());
    benchmark::DoNotOptimize(map.positions.data());
  }
  std::filesystem::remove(BenchmarkFile());
}
BENCHMARK(BM_LoadMap)->Unit(benchmark::kMillisecond)->Iterations(5);

void BM_VisibilityQuery(benchmark::State& state) {
  const bool use_keyframes = state.range(0) != 0;
  static const Map voxel_map = [] {
    Map map = BenchmarkMap();
    map.keyframes.clear();
    map.cameras.clear();
    std::fill(map.source_keyframe.begin(), map.source_keyframe.end(), kNoKeyframe);
    return map;
  }();
  const Map& map = use_keyframes ? BenchmarkMap() : voxel_map;
  const VisibilityIndex index(map);
  const Camera camera = Camera::Pinhole(640, 480, 320.0, 320.0, 319.5, 239.5);
  VisibilityQueryOptions options;
  options.max_depth_m = 5.0;
  size_t visible = 0;
  double x = 5.0;
  for (auto _ : state) {
    visible = index.Query(camera, CorridorCameraPose(x), options).size();
    x = x > 50.0 ? 5.0 : x + 0.37;
  }
  state.counters["visible_points"] = static_cast<double>(visible);
  state.SetLabel(use_keyframes ? "5 nearest keyframes" : "voxel grid 0.25 m");
}
BENCHMARK(BM_VisibilityQuery)->Arg(1)->Arg(0)->Unit(benchmark::kMicrosecond);

void BM_BuildVoxelIndex(benchmark::State& state) {
  Map map = BenchmarkMap();
  map.keyframes.clear();
  std::fill(map.source_keyframe.begin(), map.source_keyframe.end(), kNoKeyframe);
  for (auto _ : state) {
    const VisibilityIndex index(map);
    benchmark::DoNotOptimize(index.num_voxels());
  }
}
BENCHMARK(BM_BuildVoxelIndex)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace
}  // namespace evloc

BENCHMARK_MAIN();
