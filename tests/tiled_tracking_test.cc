// Border crossing end to end (docs/tracking.md, "Tiled map source"): evloc-sim renders 1.5 s of
// the default room (DAVIS240), its exact map is tiled into 0.5 m squares (evloc-mapper tile's
// code), and the sequence is tracked through the tiles (the TiledMapSource following the pose,
// as evloc-track --map SITE does) and through the whole map. The tiles come and go as the camera
// moves and turns; the tiled run must never be LOST, must score an ATE close to the whole map's,
// and must not jump when the set of tiles changes. Then the same through evloc-track's command.
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <random>
#include <set>
#include <sstream>

#include <gtest/gtest.h>

#include "core/dataset/dataset.h"
#include "core/trajectory/tum_io.h"
#include "localizer/offline/offline_tracking.h"
#include "localizer/offline/track_command.h"
#include "localizer/tracking/tiled_map_source.h"
#include "maps/map_directory.h"
#include "maps/site.h"
#include "tools/eval/evaluation.h"
#include "tools/sim/render_command.h"

namespace evloc::tracking {
namespace {

// Position error of each step of `result` against the ground truth, metres.
std::vector<double> StepErrors(const OfflineTrackingResult& result, const Trajectory& truth) {
  std::vector<double> errors;
  for (const PoseEstimate& step : result.steps) {
    const auto expected = truth.Lookup(step.t_ns);
    errors.push_back(expected ? (step.world_from_cam.translation - expected->translation).norm()
                              : 0.0);
  }
  return errors;
}

double Rmse(const std::vector<double>& errors) {
  double sum = 0;
  for (const double error : errors) sum += error * error;
  return std::sqrt(sum / std::max<size_t>(1, errors.size()));
}

TEST(TiledTracking, CrossesTileBordersWithoutAJumpOrALostStep) {
  const std::filesystem::path folder =
      std::filesystem::temp_directory_path() /
      ("evloc_tiled_tracking_" + std::to_string(std::random_device{}()));
  sim::RenderCommandOptions render;
  render.out_dir = folder / "dataset";
  render.camera_preset = "davis240";
  render.motion = sim::MotionProfile::kMid;
  render.duration_s = 1.5;
  sim::RunRenderCommand(render);
  const Map map = LoadMap(ResolveMapFile(render.out_dir / "gt_map"));
  TilingOptions tiling;
  tiling.tile_size_m = 0.5;
  tiling.overlap_m = 0.1;
  const SiteManifest manifest = TileMap(map, folder / "site", tiling);
  ASSERT_GE(manifest.tiles.size(), 40u);  // The 4 m x 4 m room.

  const Dataset dataset = ReadDataset(render.out_dir);
  const Trajectory& truth = *dataset.ground_truth;
  const int64_t start_ns = truth.start_ns();
  const Rigid3d start_pose = *truth.Lookup(start_ns);
  OfflineTrackingOptions options;
  options.read_batch_events = 4096;  // The tiles follow the pose every ~3 ms of events.

  const VisibilityIndex visibility(map);
  auto whole_reader = OpenDatasetEvents(dataset);
  const OfflineTrackingResult whole = TrackEventStream(
      *whole_reader, map, &visibility, dataset.camera, start_pose, start_ns, options);

  TileSelectionOptions selection;
  selection.radius_m = 1.5;
  selection.view_distance_m = 2.0;
  selection.synchronous = true;
  TiledMapSource source(OpenSite(folder / "site"), std::make_shared<TileCache>(), selection);
  source.LoadNow(start_pose);
  std::vector<size_t> change_steps;
  size_t steps = 0;
  std::set<std::pair<int, int>> camera_tiles;
  auto tiled_reader = OpenDatasetEvents(dataset);
  const OfflineTrackingResult tiled = TrackEventStream(
      *tiled_reader, source, dataset.camera, start_pose, start_ns, options,
      [&](const PoseEstimate& step, const Tracker&) {
        ++steps;
        const TileIndex index = manifest.grid.IndexOf(step.world_from_cam.translation.x(),
                                                      step.world_from_cam.translation.y());
        camera_tiles.insert({index.ix, index.iy});
      },
      [&](const Tracker& tracker) {
        if (source.Follow(tracker)) change_steps.push_back(steps);
      });

  EXPECT_EQ(whole.lost_steps, 0);
  EXPECT_EQ(tiled.lost_steps, 0);
  ASSERT_EQ(tiled.steps.size(), whole.steps.size());
  ASSERT_GE(tiled.steps.size(), 400u);
  // The composed tiles changed many times, and the camera itself crossed a border.
  EXPECT_GE(change_steps.size(), 5u);
  EXPECT_GE(camera_tiles.size(), 2u);

  const std::vector<double> whole_errors = StepErrors(whole, truth);
  const std::vector<double> tiled_errors = StepErrors(tiled, truth);
  const double whole_rmse = Rmse(whole_errors);
  const double tiled_rmse = Rmse(tiled_errors);
  std::cout << "ATE whole " << whole_rmse * 100 << " cm, tiled " << tiled_rmse * 100 << " cm; "
            << change_steps.size() << " changes of the composed tiles; camera in "
            << camera_tiles.size() << " tiles\n";
  // The tiles compose their points in tile order and query each tile's keyframes, so the
  // tracker selects other points than on the whole map: measured 0.626 against 0.619 cm here
  // (0.677 before a change of tiles selected its points before the surfaces were built;
  // docs/accuracy.md, "Tiles"); a lost or drifting run is off by far more.
  EXPECT_LT(tiled_rmse, 1.2 * whole_rmse);
  // No jump at a change: across every change of the tiles (the steps before and after it) the
  // error moves no more than the whole map's own error moves between two steps anywhere.
  double whole_largest_m = 0;
  for (size_t step = 1; step + 1 < whole_errors.size(); ++step) {
    whole_largest_m =
        std::max(whole_largest_m, std::abs(whole_errors[step + 1] - whole_errors[step - 1]));
  }
  double worst_jump_m = 0;
  for (const size_t step : change_steps) {
    if (step == 0 || step + 1 >= tiled_errors.size()) continue;
    worst_jump_m =
        std::max(worst_jump_m, std::abs(tiled_errors[step + 1] - tiled_errors[step - 1]));
  }
  std::cout << "largest error change across a tile change " << worst_jump_m * 1000
            << " mm; the whole map's largest over two steps " << whole_largest_m * 1000 << " mm\n";
  EXPECT_LT(worst_jump_m, 1.25 * whole_largest_m);
  EXPECT_LT(worst_jump_m, 0.02);

  // evloc-track --map SITE gives the same poses as the library run above.
  TrackCommandOptions track;
  track.map_path = folder / "site";
  track.dataset_path = render.out_dir;
  track.output_path = folder / "tiled.txt";
  track.tiles = selection;
  track.tracking.read_batch_events = 4096;
  track.quiet = true;
  std::ostringstream log;
  const OfflineTrackingResult command = RunTrackCommand(track, log);
  ASSERT_EQ(command.steps.size(), tiled.steps.size());
  for (size_t i = 0; i < command.steps.size(); ++i) {
    ASSERT_EQ(command.steps[i].world_from_cam.translation,
              tiled.steps[i].world_from_cam.translation)
        << "step " << i;
  }
  std::filesystem::remove_all(folder);
}

}  // namespace
}  // namespace evloc::tracking
