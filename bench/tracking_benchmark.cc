// Tracking benchmarks (docs/tracking.md, "Performance"; docs/benchmarks.md, "Tracking"): one
// tracking step, broken down into surface upkeep, selection and solve, for lazy and dense fields
// and the ablation variants; the event ingestion rate of the time surface and the cost of the
// noise filters before it.
//
// BM_TrackingStep replays the steps of a real run when EVLOC_BENCH_DATASET names a dataset folder
// (events, calibration, ground truth for the initial pose, gt_map/ or EVLOC_BENCH_MAP): the first
// EVLOC_BENCH_SECONDS (default 2) of its events, cut into the packets of the 300 Hz steps, fed to
// a tracker with evloc-track's defaults (visibility index, 2500 points) from the pose evloc-track
// starts from. The tracker is deterministic, so the steps timed are the steps of the run: the
// same events, the same predicted poses, the same selections (scripts/bench-tracking-replay.sh
// prints them beside the `evloc-track --stats` median of the same seconds). Without it the
// benchmark steps through a synthetic 640x480 rectangle scene (2000 points), as before.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "core/common/error.h"
#include "core/dataset/dataset.h"
#include "localizer/tracking/event_filter.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "localizer/tracking/time_surface.h"
#include "localizer/tracking/tracker.h"
#include "maps/map.h"
#include "maps/map_directory.h"
#include "maps/visibility.h"

namespace evloc::tracking {
namespace {

constexpr int64_t kStepNs = 3'333'333;  // 300 Hz
constexpr int64_t kStartNs = 50'000'000;
constexpr int64_t kEndNs = 450'000'000;

struct Scene {
  Camera camera = Camera::Pinhole(640, 480, 500.0, 500.0, 319.5, 239.5);
  Map map;
  // Built for a replayed dataset (as evloc-track does).
  std::unique_ptr<VisibilityIndex> visibility;
  // The pose and time the run starts from.
  Rigid3d start_world_from_cam;
  int64_t start_t_ns = kStartNs;
  // Events up to the start time, then one packet per step.
  EventBuffer warm_up;
  std::vector<EventBuffer> packets;
  // Empty for the synthetic scene, else the dataset folder.
  std::string replayed;
};

// Cuts `events` (from `reader` when given) into the warm-up (t <= start) and one packet per
// step period after it, up to `end_t_ns`.
void CutIntoSteps(EventReader* reader, const EventBuffer* events, int64_t end_t_ns, Scene* scene) {
  int64_t boundary = scene->start_t_ns;
  EventBuffer* current = &scene->warm_up;
  EventBuffer batch;
  size_t offset = 0;
  for (;;) {
    if (reader != nullptr) {
      batch.clear();
      if (reader->Read(1 << 20, &batch) == 0) return;
      events = &batch;
    } else if (offset++ > 0) {
      return;
    }
    for (size_t i = 0; i < events->size(); ++i) {
      const int64_t t_ns = events->t_ns[i];
      if (t_ns > end_t_ns) return;
      while (t_ns > boundary) {
        scene->packets.emplace_back();
        current = &scene->packets.back();
        boundary += kStepNs;
      }
      current->push_back((*events)[i]);
    }
  }
}

std::unique_ptr<Scene> LoadReplayedScene(const std::string& folder) {
  auto scene = std::make_unique<Scene>();
  scene->replayed = folder;
  const Dataset dataset = ReadDataset(folder);
  scene->camera = dataset.camera;
  const char* map_path = std::getenv("EVLOC_BENCH_MAP");
  scene->map = LoadMap(ResolveMapFile(map_path != nullptr ? std::filesystem::path(map_path)
                                                          : std::filesystem::path(folder) /
                                                                dataset_files::kGroundTruthMap));
  scene->visibility = std::make_unique<VisibilityIndex>(scene->map);
  int64_t first_t_ns = 0;
  {
    EventBuffer first;
    if (OpenDatasetEvents(dataset)->Read(1, &first) == 1) first_t_ns = first.t_ns[0];
  }
  const TimedPose start = ResolveInitialPose(dataset, std::nullopt, first_t_ns);
  scene->start_world_from_cam = start.world_from_cam;
  scene->start_t_ns = start.t_ns;
  const char* seconds_text = std::getenv("EVLOC_BENCH_SECONDS");
  const double seconds = seconds_text != nullptr ? std::atof(seconds_text) : 2.0;
  if (!(seconds > 0)) throw InvalidArgumentError("EVLOC_BENCH_SECONDS must be positive.");
  const auto reader = OpenDatasetEvents(dataset);
  // One step more than asked: the last step runs when the next packet's first event arrives.
  CutIntoSteps(reader.get(), nullptr, start.t_ns + static_cast<int64_t>(seconds * 1e9) + kStepNs,
               scene.get());
  if (scene->packets.size() < 2) {
    throw InvalidArgumentError("EVLOC_BENCH_DATASET " + folder +
                               ": fewer than two steps of events after the initial pose.");
  }
  scene->packets.pop_back();  // Its step would need the packet after it.
  return scene;
}

std::unique_ptr<Scene> MakeSyntheticScene() {
  auto scene = std::make_unique<Scene>();
  scene->map = testing::MakeRectangleMap(testing::DefaultRectangles(), 0.003);
  scene->start_world_from_cam = testing::SmoothMotion(kStartNs);
  const EventBuffer events = testing::SimulateEdgeEvents(
      scene->map, scene->camera, [](int64_t t_ns) { return testing::SmoothMotion(t_ns); }, 0,
      kEndNs + kStepNs, 50'000);
  CutIntoSteps(nullptr, &events, std::numeric_limits<int64_t>::max(), scene.get());
  return scene;
}

// The synthetic scene (BM_TrackingSequence, BM_Ingestion, and BM_TrackingStep without a dataset).
const Scene& GetScene() {
  static const std::unique_ptr<Scene> scene = MakeSyntheticScene();
  return *scene;
}

// The scene BM_TrackingStep steps through: the replayed dataset when EVLOC_BENCH_DATASET is set.
const Scene& GetStepScene() {
  static const std::unique_ptr<Scene> scene = [] {
    const char* folder = std::getenv("EVLOC_BENCH_DATASET");
    return folder != nullptr && *folder != 0 ? LoadReplayedScene(folder) : nullptr;
  }();
  return scene ? *scene : GetScene();
}

// Steps a tracker (`scene`'s map, visibility index and camera, `options`, warmed up and started as
// evloc-track starts it) through the scene's packets, one per iteration, and starts again
// (untimed) after the last; `on_step(packet, estimates)` after each.
template <typename OnStep>
void StepThrough(benchmark::State& state, const Scene& scene, const TrackerOptions& options,
                 const OnStep& on_step) {
  std::unique_ptr<Tracker> tracker;
  size_t next_packet = 0;
  auto restart = [&] {
    tracker = std::make_unique<Tracker>(scene.map, scene.visibility.get(), scene.camera, options);
    tracker->AddEvents(scene.warm_up);
    tracker->Reset(scene.start_world_from_cam, scene.start_t_ns);
    next_packet = 0;
  };
  restart();
  for (auto _ : state) {
    if (next_packet == scene.packets.size()) {
      state.PauseTiming();
      restart();
      state.ResumeTiming();
    }
    const EventBuffer& packet = scene.packets[next_packet++];
    on_step(packet, tracker->AddEvents(packet));
  }
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

double Mean(const std::vector<double>& values) {
  double sum = 0;
  for (const double value : values) sum += value;
  return values.empty() ? 0.0 : sum / static_cast<double>(values.size());
}

// The per-step figures of a benchmark's steps, as its counters.
struct StepFigures {
  std::vector<double> step_ms, surface_ms, selection_ms, solve_ms, points, iterations;
  int64_t lost = 0;

  void Add(const std::vector<PoseEstimate>& estimates) {
    for (const PoseEstimate& estimate : estimates) {
      step_ms.push_back(estimate.timings.total_ms);
      surface_ms.push_back(estimate.timings.surface_ms);
      selection_ms.push_back(estimate.timings.selection_ms);
      solve_ms.push_back(estimate.timings.solve_ms);
      points.push_back(estimate.quality.points_used);
      iterations.push_back(estimate.quality.iterations);
      lost += estimate.status == TrackingStatus::kLost ? 1 : 0;
    }
  }
  void SetCounters(benchmark::State& state) const {
    state.counters["step_median_ms"] = Median(step_ms);
    state.counters["surface_median_ms"] = Median(surface_ms);
    state.counters["selection_mean_ms"] = Mean(selection_ms);
    state.counters["solve_median_ms"] = Median(solve_ms);
    state.counters["points_used"] = Mean(points);
    state.counters["lm_iterations"] = Mean(iterations);
    state.counters["lost_steps"] = static_cast<double>(lost);
  }
};

// One tracking step per iteration: the packet of one step period (the step itself runs when the
// next packet's first event arrives, so each AddEvents call runs exactly one step).
void BM_TrackingStep(benchmark::State& state) {
  const Scene& scene = GetStepScene();
  TrackerOptions options;
  // evloc-track's defaults for a replayed run; the synthetic scene's budget as before.
  if (scene.replayed.empty()) options.max_points = 2000;
  options.field_evaluation = state.range(0) == 0 ? FieldEvaluation::kLazy : FieldEvaluation::kDense;
  options.use_polarity = state.range(1) != 0;
  options.use_occlusion_culling = state.range(2) != 0;
  options.smooth_field = state.range(3) != 0;
  options.polarity_after_unsigned_solve = state.range(4) != 0;
  StepFigures figures;
  StepThrough(state, scene, options,
              [&](const EventBuffer&, const std::vector<PoseEstimate>& estimates) {
                figures.Add(estimates);
              });
  figures.SetCounters(state);
  state.SetLabel(
      (scene.replayed.empty()
           ? std::string("synthetic ")
           : "replay " + std::filesystem::path(scene.replayed).filename().string() + " (" +
                 std::to_string(scene.packets.size()) + " steps) ") +
      std::string(state.range(0) == 0 ? "lazy" : "dense") + " " + options.VariantName() +
      (options.smooth_field ? " smoothed" : "") +
      (options.use_polarity && !options.polarity_after_unsigned_solve ? " one-stage" : ""));
}
// Args: dense field, polarity, occlusion, smoothing, two-stage polarity (an unsigned solve
// before the signed one; the default). The last row is the paper's one-stage EVT, to show what
// the two-stage polarity costs.
BENCHMARK(BM_TrackingStep)
    ->Args({0, 1, 1, 0, 1})
    ->Args({0, 0, 0, 0, 1})
    ->Args({0, 1, 0, 0, 1})
    ->Args({0, 0, 1, 0, 1})
    ->Args({1, 1, 1, 0, 1})
    ->Args({0, 1, 1, 1, 1})
    ->Args({1, 1, 1, 1, 1})
    ->Args({0, 1, 1, 0, 0})
    ->Unit(benchmark::kMicrosecond);

// How a step's cost grows with the map and with the event rate (issue 16, target 6;
// docs/benchmarks.md, "Tracking: cost growth"). The synthetic scene's motion and steps; what
// changes is one of:
// - the map: the rectangles' outlines sampled densely enough for `state.range(0)` points (all of
//   them in view), tracked with evloc-track's budget of 2500 points (`state.range(1)` == 0) or
//   with every point selected (1); the events stay those of the usual scene;
// - the event rate: the usual scene's events, each repeated (or a share of them kept) so that
//   they arrive at `state.range(0)` million events per second, the usual map and budget.
// One step per iteration as BM_TrackingStep; the CPU time per iteration includes the ingestion
// of the step's packet, step_median_ms does not.
// The usual scene's events over its whole span, in one buffer.
EventBuffer AllSceneEvents() {
  EventBuffer events;
  events.Append(GetScene().warm_up);
  for (const EventBuffer& packet : GetScene().packets) events.Append(packet);
  return events;
}

// Events per second over the span of `events` (time-sorted, at least two time stamps).
double EventsPerSecond(const EventBuffer& events) {
  return static_cast<double>(events.size()) /
         (static_cast<double>(events.t_ns.back() - events.t_ns.front()) * 1e-9);
}

// The usual scene with its map or its event rate changed (0: as usual).
std::unique_ptr<Scene> MakeGrowthScene(int64_t map_points, double million_events_per_s) {
  auto growth = std::make_unique<Scene>();
  const Scene& usual = GetScene();
  growth->start_world_from_cam = usual.start_world_from_cam;
  if (map_points > 0) {
    // Spacing for the asked count: the outlines' length from the usual map (3 mm spacing).
    const double length_m = static_cast<double>(usual.map.size()) * 0.003;
    growth->map = testing::MakeRectangleMap(testing::DefaultRectangles(),
                                            length_m / static_cast<double>(map_points));
  } else {
    growth->map = usual.map;
  }
  const EventBuffer events = AllSceneEvents();
  EventBuffer scaled;
  if (million_events_per_s > 0) {
    // Each event repeated floor or ceil of the factor times (a running remainder), or kept with
    // that probability below 1: the same edges at the asked rate.
    const double factor = million_events_per_s * 1e6 / EventsPerSecond(events);
    double owed = 0;
    for (size_t i = 0; i < events.size(); ++i) {
      owed += factor;
      for (; owed >= 1; owed -= 1) scaled.push_back(events[i]);
    }
  } else {
    scaled = events;
  }
  CutIntoSteps(nullptr, &scaled, std::numeric_limits<int64_t>::max(), growth.get());
  return growth;
}

void RunGrowthSteps(benchmark::State& state, const Scene& scene, const TrackerOptions& options) {
  StepFigures figures;
  int64_t events = 0;
  StepThrough(state, scene, options,
              [&](const EventBuffer& packet, const std::vector<PoseEstimate>& estimates) {
                events += static_cast<int64_t>(packet.size());
                figures.Add(estimates);
              });
  figures.SetCounters(state);
  size_t scene_events = scene.warm_up.size();
  for (const EventBuffer& packet : scene.packets) scene_events += packet.size();
  const int64_t span_ns = scene.packets.back().t_ns.back() - scene.warm_up.t_ns.front();
  state.counters["map_points"] = static_cast<double>(scene.map.size());
  state.counters["events_per_s"] =
      static_cast<double>(scene_events) / (static_cast<double>(span_ns) * 1e-9);
  state.counters["events_per_step"] =
      static_cast<double>(events) / static_cast<double>(std::max<int64_t>(1, state.iterations()));
}

// The scene for (map points, events per second), kept while the next run asks for the same.
const Scene& GetGrowthScene(int64_t map_points, double million_events_per_s) {
  static std::pair<int64_t, double> key{-1, -1};
  static std::unique_ptr<Scene> scene;
  if (!scene || key != std::make_pair(map_points, million_events_per_s)) {
    scene.reset();
    scene = MakeGrowthScene(map_points, million_events_per_s);
    key = {map_points, million_events_per_s};
  }
  return *scene;
}

void BM_StepCostMapPoints(benchmark::State& state) {
  const Scene& scene = GetGrowthScene(state.range(0), 0);
  TrackerOptions options;
  if (state.range(1) != 0) options.max_points = static_cast<int>(scene.map.size());
  RunGrowthSteps(state, scene, options);
  state.SetLabel(state.range(1) != 0 ? "every point selected" : "budget 2500");
}
BENCHMARK(BM_StepCostMapPoints)
    ->ArgsProduct({{1000, 3000, 10000, 30000, 100000}, {0, 1}})
    ->Unit(benchmark::kMicrosecond);

void BM_StepCostEventRate(benchmark::State& state) {
  RunGrowthSteps(state, GetGrowthScene(0, static_cast<double>(state.range(0))), TrackerOptions());
  state.SetLabel("budget 2500");
}
BENCHMARK(BM_StepCostEventRate)
    ->Arg(1)
    ->Arg(2)
    ->Arg(5)
    ->Arg(10)
    ->Arg(20)
    ->Arg(50)
    ->Unit(benchmark::kMicrosecond);

// The whole 400 ms sequence (120 steps) per iteration, from a fresh tracker: a fixed amount of
// work, so that instruction counts (valgrind --tool=callgrind --toggle-collect='*Tracker::Step*')
// compare before and after a change independently of the machine's load. items_per_second is
// steps per second of CPU time.
void BM_TrackingSequence(benchmark::State& state) {
  const Scene& scene = GetScene();
  TrackerOptions options;
  options.max_points = 2000;
  options.use_polarity = state.range(0) != 0;
  options.use_occlusion_culling = state.range(1) != 0;
  int64_t steps = 0;
  for (auto _ : state) {
    state.PauseTiming();
    Tracker tracker(scene.map, nullptr, scene.camera, options);
    tracker.AddEvents(scene.warm_up);
    tracker.Reset(testing::SmoothMotion(kStartNs), kStartNs);
    state.ResumeTiming();
    for (const EventBuffer& packet : scene.packets) {
      steps += static_cast<int64_t>(tracker.AddEvents(packet).size());
    }
  }
  state.SetItemsProcessed(steps);
  state.SetLabel(options.VariantName());
}
// Args: polarity, occlusion.
BENCHMARK(BM_TrackingSequence)->Args({1, 1})->Args({0, 0})->Unit(benchmark::kMillisecond);

// Event ingestion: one look-up and two stores per event, 640x480, events on a moving edge
// pattern (realistic locality) or uniformly random pixels (worst case).
void BM_Ingestion(benchmark::State& state) {
  const Camera camera = Camera::Pinhole(640, 480, 500.0, 500.0, 319.5, 239.5);
  const UndistortionTable table(camera);
  TimeSurface surface(table);
  EventBuffer events;
  const size_t count = 1 << 20;
  std::mt19937 random(5);
  if (state.range(0) == 0) {
    const EventBuffer& scene_events = GetScene().warm_up;
    for (size_t i = 0; i < count; ++i) events.push_back(scene_events[i % scene_events.size()]);
  } else {
    std::uniform_int_distribution<int> x(0, 639), y(0, 479);
    for (size_t i = 0; i < count; ++i) {
      events.push_back({static_cast<int64_t>(i) * 100, static_cast<uint16_t>(x(random)),
                        static_cast<uint16_t>(y(random)), static_cast<int8_t>(i % 2 ? 1 : -1)});
    }
  }
  for (auto _ : state) {
    surface.Insert(events, 0, events.size());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations()) * count);
  state.SetLabel(state.range(0) == 0 ? "edge events" : "uniform random pixels");
}
BENCHMARK(BM_Ingestion)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

// The noise filters before the surfaces (event_filter.h), in steady state (after the hot-pixel
// learning period): every event of the scene (640x480, 450 ms of edge events) or 2^20 events on
// uniformly random pixels at 10 M events/s, per iteration, shifted in time from one iteration to
// the next. Args: filters (1 hot pixels, 2 refractory 1 ms, 4 background activity 10 ms; a
// sum: several), events (0 edge, 1 uniform random). Items per second: events filtered.
void BM_EventFilter(benchmark::State& state) {
  const int filters = static_cast<int>(state.range(0));
  EventBuffer events;
  if (state.range(1) == 0) {
    events = AllSceneEvents();
  } else {
    std::mt19937 random(5);
    std::uniform_int_distribution<int> x(0, 639), y(0, 479);
    for (size_t i = 0; i < (1u << 20); ++i) {
      events.push_back({static_cast<int64_t>(i) * 100, static_cast<uint16_t>(x(random)),
                        static_cast<uint16_t>(y(random)), static_cast<int8_t>(i % 2 ? 1 : -1)});
    }
  }
  const int64_t span_ns = events.t_ns.back() - events.t_ns.front() + 1;
  EventFilterOptions options;
  options.hot_pixels = (filters & 1) != 0;
  options.refractory_period_s = (filters & 2) != 0 ? 0.001 : 0.0;
  options.background_activity_window_s = (filters & 4) != 0 ? 0.01 : 0.0;
  EventFilter filter(SensorSize{640, 480}, options);
  filter.Process(events);  // The learning period.
  int64_t passed = 0;
  for (auto _ : state) {
    state.PauseTiming();
    for (int64_t& t : events.t_ns) t += span_ns;
    state.ResumeTiming();
    passed += static_cast<int64_t>(filter.Process(events).size());
  }
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations() * events.size()));
  state.counters["passed_fraction"] =
      static_cast<double>(passed) / static_cast<double>(state.iterations() * events.size());
  state.SetLabel(state.range(1) == 0 ? "edge events" : "uniform random pixels");
}
BENCHMARK(BM_EventFilter)->ArgsProduct({{1, 2, 4, 7}, {0, 1}})->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace evloc::tracking

BENCHMARK_MAIN();
