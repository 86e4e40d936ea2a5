// End-to-end accuracy on a short simulated sequence (docs/accuracy.md, "Tracking accuracy"):
// evloc-sim renders 1 s of the default room at 240x180 (DAVIS240 preset, default noise) into a
// temporary folder, evloc-track's code tracks it against the ground-truth map, and evloc-eval's
// code scores it without alignment. The noise filters (docs/tracking.md, "Noise filters";
// docs/accuracy.md, "Noise filters") end to end: a helper here adds shot noise (uniform in pixels
// and time) and hot pixels (each firing at a fixed rate with a little jitter) to the rendered
// events, and the noisy events are tracked with the filters off and on.
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <random>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "core/dataset/dataset.h"
#include "core/events/evb.h"
#include "core/trajectory/tum_io.h"
#include "localizer/offline/track_command.h"
#include "tools/eval/evaluation.h"
#include "tools/sim/render_command.h"

namespace evloc::tracking {
namespace {

// Renders 1 s of the mid motion at 240x180 (DAVIS240 preset, default noise) into a new
// temporary folder; returns its options (out_dir: the dataset).
sim::RenderCommandOptions RenderOneSecondOfMid(const std::string& prefix) {
  const std::filesystem::path folder =
      std::filesystem::temp_directory_path() / (prefix + std::to_string(std::random_device{}()));
  sim::RenderCommandOptions render;
  render.out_dir = folder / "dataset";
  render.camera_preset = "davis240";
  render.motion = sim::MotionProfile::kMid;
  render.duration_s = 1.0;
  sim::RunRenderCommand(render);
  return render;
}

TEST(SimulatedSequence, TracksOneSecondOfDavis240WithinACentimetreAndAHalfAndNeverLoses) {
  const sim::RenderCommandOptions render = RenderOneSecondOfMid("evloc_tracking_sim_");
  const std::filesystem::path folder = render.out_dir.parent_path();

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

// Noise added to a recording.
struct InjectedNoise {
  // Shot-noise events per pixel per second, uniform in time and over the sensor, random
  // polarity.
  double shot_noise_hz = 0;
  // Fraction of the pixels that are hot.
  double hot_pixel_fraction = 0;
  // Rate of each hot pixel, events per second (periodic, each event jittered by up to a tenth of
  // the period).
  double hot_pixel_rate_hz = 0;
};

// `events` (time-ordered) with the noise added, time-ordered; the noise spans the events' time
// range.
EventBuffer AddNoise(const EventBuffer& events, SensorSize sensor, const InjectedNoise& noise,
                     uint32_t seed) {
  std::mt19937_64 random(seed);
  const int64_t begin_ns = events.t_ns.front();
  const int64_t end_ns = events.t_ns.back();
  const double duration_s = static_cast<double>(end_ns - begin_ns) * 1e-9;
  std::vector<Event> added;
  std::uniform_int_distribution<int> x(0, sensor.width - 1);
  std::uniform_int_distribution<int> y(0, sensor.height - 1);
  std::uniform_int_distribution<int64_t> time(begin_ns, end_ns);
  std::poisson_distribution<int64_t> shots(noise.shot_noise_hz * sensor.width * sensor.height *
                                           duration_s);
  const int64_t shot_count = shots(random);
  for (int64_t i = 0; i < shot_count; ++i) {
    added.push_back({time(random), static_cast<uint16_t>(x(random)),
                     static_cast<uint16_t>(y(random)), static_cast<int8_t>(random() % 2 ? 1 : -1)});
  }
  const int hot_count =
      static_cast<int>(std::lround(noise.hot_pixel_fraction * sensor.width * sensor.height));
  if (hot_count > 0 && noise.hot_pixel_rate_hz > 0) {
    const auto period_ns = static_cast<int64_t>(1e9 / noise.hot_pixel_rate_hz);
    std::uniform_int_distribution<int64_t> jitter(0, period_ns / 10);
    std::uniform_int_distribution<int64_t> phase(0, period_ns - 1);
    for (int pixel = 0; pixel < hot_count; ++pixel) {
      const auto hot_x = static_cast<uint16_t>(x(random));
      const auto hot_y = static_cast<uint16_t>(y(random));
      for (int64_t t = begin_ns + phase(random); t <= end_ns; t += period_ns) {
        added.push_back({std::min(end_ns, t + jitter(random)), hot_x, hot_y,
                         static_cast<int8_t>(random() % 2 ? 1 : -1)});
      }
    }
  }
  std::sort(added.begin(), added.end(),
            [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; });
  // Merge: at equal times the recording's event comes first.
  EventBuffer merged;
  merged.reserve(events.size() + added.size());
  size_t next = 0;
  for (size_t i = 0; i < events.size(); ++i) {
    while (next < added.size() && added[next].t_ns < events.t_ns[i])
      merged.push_back(added[next++]);
    merged.push_back(events[i]);
  }
  while (next < added.size()) merged.push_back(added[next++]);
  return merged;
}

struct FilteredRun {
  double ate_cm = 0;
  int64_t lost_steps = 0;
  double coverage = 0;
  EventFilterCounts counts;
};

FilteredRun Track(const std::filesystem::path& dataset, const std::filesystem::path& output,
                  const EventFilterOptions& filters) {
  TrackCommandOptions track;
  track.map_path = dataset / "gt_map";
  track.dataset_path = dataset;
  track.output_path = output;
  track.quiet = true;
  track.tracking.tracker.event_filter = filters;
  std::ostringstream log;
  const OfflineTrackingResult result = RunTrackCommand(track, log);
  EvaluationOptions evaluation;
  evaluation.alignment = Alignment::kNone;
  const EvaluationResult scores = EvaluateTrajectory(ReadTumTrajectory(dataset / "groundtruth.txt"),
                                                     ReadTumTrajectory(output), evaluation);
  return {scores.ate_translation_cm.rmse, result.lost_steps, scores.coverage,
          result.final_filter_counts};
}

TEST(NoiseFilters, TrackingNoisyEventsIsBetterWithTheFiltersOn) {
  const sim::RenderCommandOptions render = RenderOneSecondOfMid("evloc_noise_filters_");
  const std::filesystem::path folder = render.out_dir.parent_path();

  // Replace the events by noisy ones (written atomically under the same name).
  const Dataset dataset = ReadDataset(render.out_dir);
  ASSERT_TRUE(dataset.events_path);
  ASSERT_EQ(dataset.events_path->extension(), ".evb");
  EventBuffer clean;
  const auto reader = OpenDatasetEvents(dataset);
  while (reader->Read(1 << 20, &clean) > 0) {
  }
  const SensorSize sensor{dataset.camera.width, dataset.camera.height};
  InjectedNoise noise;
  noise.shot_noise_hz = 10;
  noise.hot_pixel_fraction = 0.01;
  noise.hot_pixel_rate_hz = 2000;
  const EventBuffer noisy = AddNoise(clean, sensor, noise, 11);
  {
    EvbWriter writer(*dataset.events_path, sensor);
    writer.Write(noisy);
    writer.Close();
  }
  std::cout << "events: " << clean.size() << " rendered, " << noisy.size() - clean.size()
            << " noise added\n";

  EventFilterOptions hot_pixels;
  hot_pixels.hot_pixels = true;
  EventFilterOptions on = hot_pixels;
  on.background_activity_window_s = 0.005;
  const FilteredRun unfiltered = Track(render.out_dir, folder / "unfiltered.txt", {});
  const FilteredRun hot_only = Track(render.out_dir, folder / "hot.txt", hot_pixels);
  const FilteredRun filtered = Track(render.out_dir, folder / "filtered.txt", on);
  for (const auto& [name, run] : {std::pair{"filters off", unfiltered},
                                  {"hot pixels", hot_only},
                                  {"hot pixels + background activity 5 ms", filtered}}) {
    std::cout << name << ": ATE " << run.ate_cm << " cm, " << run.lost_steps << " LOST, coverage "
              << run.coverage << "; removed " << run.counts.hot_pixel << " hot-pixel and "
              << run.counts.background_activity << " background-activity events of "
              << run.counts.input << ", " << run.counts.masked_pixels << " pixels masked\n";
  }
  // The hot pixels are found (a few edge pixels may be masked for a window too).
  const auto hot_count = std::lround(noise.hot_pixel_fraction * 240 * 180);
  EXPECT_GE(hot_only.counts.masked_pixels, hot_count * 9 / 10);
  EXPECT_LE(hot_only.counts.masked_pixels, hot_count * 2);
  EXPECT_EQ(filtered.lost_steps, 0);
  EXPECT_GT(filtered.coverage, 0.95);
  // Masking the hot pixels alone helped while a DAVIS240's surface had holes (0.629 against
  // 0.653 cm); since the holes are filled (TimeSurface::FillHoles) the tracker without filters
  // is as good on this scene (0.5133 against 0.5131 cm, docs/accuracy.md "Noise filters"): the
  // mask must not hurt, and the two filters together must help.
  EXPECT_LT(hot_only.ate_cm, unfiltered.ate_cm * 1.01);
  EXPECT_LT(filtered.ate_cm, unfiltered.ate_cm);
  std::filesystem::remove_all(folder);
}

}  // namespace
}  // namespace evloc::tracking
