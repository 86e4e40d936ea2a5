// End-to-end accuracy on a short simulated sequence (docs/accuracy.md, "Tracking accuracy"):
// evloc-sim renders 1 s of the default room at 240x180 (DAVIS240 preset, default noise) into a
// temporary folder, evloc-track's code tracks it against the ground-truth map, and evloc-eval's
// code scores it without alignment.
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

TEST(SimulatedSequence, TracksOneSecondOfDavis240WithinACentimetreAndAHalfAndNeverLoses) {
  const std::filesystem::path folder =
      std::filesystem::temp_directory_path() /
      ("evloc_tracking_sim_" + std::to_string(std::random_device{}()));
  sim::RenderCommandOptions render;
  render.out_dir = folder / "dataset";
  render.camera_preset = "davis240";
  render.motion = sim::MotionProfile::kMid;
  render.duration_s = 1.0;
  sim::RunRenderCommand(render);

  TrackCommandOptions track;
  track.map_path = render.out_dir / "gt_map";
  track.dataset_path = render.out_dir;
  track.output_path = folder / "estimate.txt";
  track.quiet = true;
  std::ostringstream log;
  const OfflineTrackingResult result = RunTrackCommand(track, log);
  EXPECT_EQ(result.lost_steps, 0);
  EXPECT_GE(result.steps.size(), 290u);  // 300 Hz over 1 s.
  // The polarity predictions agree with the simulator's events (brightness constancy sign).
  // Measured 0.76 here (own pixel, 240x180); the inverted sign scores 1 - that, a coin 0.5.
  int64_t predictions = 0;
  int64_t matches = 0;
  for (const PoseEstimate& step : result.steps) {
    predictions += step.quality.polarity_predictions;
    matches += step.quality.polarity_matches;
  }
  ASSERT_GT(predictions, 10000);
  const double match_fraction = static_cast<double>(matches) / predictions;
  EXPECT_GT(match_fraction, 0.65);
  std::cout << "polarity: " << matches << " of " << predictions << " confident predictions match ("
            << match_fraction << ")\n";

  EvaluationOptions evaluation;
  evaluation.alignment = Alignment::kNone;
  const EvaluationResult scores =
      EvaluateTrajectory(ReadTumTrajectory(render.out_dir / "groundtruth.txt"),
                         ReadTumTrajectory(track.output_path), evaluation);
  // Measured 0.92 cm and 0.31 deg (docs/accuracy.md); a lost or
  // drifting tracker is off by decimetres.
  EXPECT_LT(scores.ate_translation_cm.rmse, 2.5);
  EXPECT_LT(scores.ate_rotation_deg.rmse, 1.0);
  EXPECT_GT(scores.coverage, 0.95);
  std::cout << "ATE " << scores.ate_translation_cm.rmse << " cm, " << scores.ate_rotation_deg.rmse
            << " deg, coverage " << scores.coverage << "\n";
  std::filesystem::remove_all(folder);
}

}  // namespace
}  // namespace evloc::tracking
