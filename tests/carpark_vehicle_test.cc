// Vehicle speed end to end (docs/accuracy.md, "Vehicle speed"): evloc-sim renders a small car park
// (one module of 16 bays; the full 200 m x 200 m site is scripts/accuracy/vehicle.sh) from a
// forward camera 1.5 m up at 10 m/s, by day, at 240x180 (DAVIS240 preset, default noise), and
// evloc-track's code tracks it against the exact map with the vehicle settings (poses stamped at
// the step time); evloc-eval's code scores it without alignment.
#include <filesystem>
#include <iostream>
#include <random>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "core/trajectory/tum_io.h"
#include "localizer/offline/track_command.h"
#include "tools/eval/evaluation.h"
#include "tools/sim/render_command.h"

namespace evloc::tracking {
namespace {

TEST(CarParkVehicle, TracksTenMetresPerSecondWithinTenCentimetresAndNeverLoses) {
  const std::filesystem::path folder =
      std::filesystem::temp_directory_path() /
      ("evloc_carpark_vehicle_" + std::to_string(std::random_device{}()));
  sim::RenderCommandOptions render;
  render.out_dir = folder / "dataset";
  render.camera_preset = "davis240";
  render.carpark = true;
  render.site.modules = 1;
  render.site.bays_per_row = 16;
  render.path = "vehicle";
  render.speed_m_per_s = 10;
  render.path_start_m = 5;  // the route starts 5 m before the bays
  render.duration_s = 0.4;
  render.map_spacing_m = 0.05;
  const nlohmann::json info = sim::RunRenderCommand(render);
  EXPECT_NEAR(info["motion_measured"]["peak_linear_m_per_s"].get<double>(), 10.0, 0.3);
  std::cout << "render: " << info["timings_s"].dump() << ", " << info["counts"]["map_points"]
            << " map points\n";

  TrackCommandOptions track;
  track.map_path = render.out_dir / "gt_map";
  track.dataset_path = render.out_dir;
  track.output_path = folder / "estimate.txt";
  track.quiet = true;
  track.tracking.tracker.stamp_at_step_time = true;
  std::ostringstream log;
  const OfflineTrackingResult result = RunTrackCommand(track, log);
  EXPECT_EQ(result.lost_steps, 0);
  EXPECT_GE(result.steps.size(), 115u);  // 300 Hz over 0.4 s.

  EvaluationOptions evaluation;
  evaluation.alignment = Alignment::kNone;
  evaluation.delta_s = 0.1;
  const EvaluationResult scores =
      EvaluateTrajectory(ReadTumTrajectory(render.out_dir / "groundtruth.txt"),
                         ReadTumTrajectory(track.output_path), evaluation);
  // The target at vehicle speed; a tracker that stalls falls 4 cm behind per step.
  EXPECT_LT(scores.ate_translation_cm.rmse, 10.0);
  EXPECT_LT(scores.ate_rotation_deg.rmse, 1.0);
  EXPECT_GT(scores.coverage, 0.95);
  std::cout << "ATE " << scores.ate_translation_cm.rmse << " cm (max "
            << scores.ate_translation_cm.max << "), " << scores.ate_rotation_deg.rmse
            << " deg, coverage " << scores.coverage << ", " << result.steps.size() << " steps\n";
  std::filesystem::remove_all(folder);
}

}  // namespace
}  // namespace evloc::tracking
