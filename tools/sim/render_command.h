// The two commands of evloc-sim as library functions (the CLI only parses flags):
// `render` (scene + motion -> dataset) and `events-from-frames` (dataset -> dataset with events).
// See docs/simulator.md and docs/dataset-format.md.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "core/camera/camera.h"
#include "tools/sim/carpark.h"
#include "tools/sim/depth_sensor.h"
#include "tools/sim/events_from_frames.h"
#include "tools/sim/frame_sensor.h"
#include "tools/sim/motion.h"

namespace evloc::sim {

// The `--camera` presets: "default" (640 x 480 pinhole, Prophesee Gen3-like) and "davis240"
// (240 x 180, the Event Camera Dataset DAVIS240C calibration). Throws InvalidArgumentError for
// other names.
Camera CameraPreset(const std::string& name);

// Options of `evloc-sim render`.
struct RenderCommandOptions {
  // Output dataset folder.
  std::filesystem::path out_dir;
  // Camera preset name (ignored when camera_yaml is set).
  std::string camera_preset = "default";
  // Camera YAML file overriding the preset.
  std::optional<std::filesystem::path> camera_yaml;
  // Scene JSON; the default room when unset (and no built-in site is asked for).
  std::optional<std::filesystem::path> scene_json;
  // The built-in car park site (`--scene carpark`, docs/sim-scene.md) instead of a room or JSON.
  bool carpark = false;
  // The car park's layout: its seed (`--site-seed`: the same site for every run with it) and,
  // for tests, a smaller site (fewer modules and bays).
  CarParkOptions site;
  // Time of day of the car park (`--time-of-day`): daylight, sky and street lamps.
  std::optional<TimeOfDay> time_of_day;
  // Path through the car park instead of --motion (`--path vehicle|pedestrian`).
  std::optional<std::string> path;
  // Vehicle speed along the route, m/s (`--speed`).
  double speed_m_per_s = 5;
  // Where along the route the path starts, metres (`--path-start`).
  double path_start_m = 0;
  // Spacing of the ground-truth map's points along every edge, metres (`--map-spacing`).
  double map_spacing_m = 0.01;
  // Motion preset (used when no trajectory file is given).
  MotionProfile motion = MotionProfile::kMid;
  // TUM trajectory replayed instead of the preset motion.
  std::optional<std::filesystem::path> trajectory_file;
  // Duration in seconds; unset: 10 s for presets, the whole file for a trajectory.
  std::optional<double> duration_s;
  // Frame rate of the frame camera, Hz.
  double fps = 30;
  // Lighting preset.
  LightingCondition lighting = LightingCondition::kBright;
  // Seed of motion, sensor noise and event noise.
  uint64_t seed = 1;
  // Event pixel preset (`--sensor`): ideal, davis240, davis346, gen3 or gen4 (SensorPreset).
  std::string sensor = "ideal";
  // Shot-noise rate per pixel at the darkest level, Hz, overriding the preset's (`--noise-rate`).
  std::optional<double> noise_rate_hz;
  // Fraction of hot pixels, overriding the preset's (`--hot-pixels`).
  std::optional<double> hot_pixel_fraction;
  // Photoreceptor cutoff at intensity 1, Hz, overriding the preset's (`--cutoff`; 0: none).
  std::optional<double> photoreceptor_cutoff_hz;
  // Event pixel without mismatch, refractory period, noise, leak, hot pixels, low-pass and
  // read-out limit.
  bool clean = false;
  // Also write events.txt (ECD text).
  bool events_txt = false;
  // The depth camera beside the event camera (`--depth-camera`; its frames in depth_camera.txt,
  // docs/simulator.md "Depth camera"); its first frame is taken with the frame camera's first
  // frame and its noise seed is `seed`. Unset: no depth camera.
  std::optional<DepthSensorOptions> depth_camera;
  // Replace an existing non-empty output folder.
  bool force = false;
  // Ground-truth rate, Hz (>= 200).
  double ground_truth_rate_hz = 1000;
  // Interval between ground-truth map keyframes along the path, seconds.
  double keyframe_interval_s = 0.5;
  // The ground-truth map from the keyframes of the first this many seconds only (a map of the
  // part of the scene seen then, `--map-until`); unset: the whole path.
  std::optional<double> map_until_s;
  // Largest image motion between consecutive ESIM images, pixels.
  double max_pixel_motion_px = 0.5;
  // Largest image motion between two renders, pixels (images in between are interpolated along
  // the flow from the rendered depth; equal to max_pixel_motion_px to render every image).
  double max_render_motion_px = 3.0;

  // The event pixel's options: the sensor preset with the overrides, the seed, and --clean.
  EsimOptions PixelOptions() const;

  // Throws InvalidArgumentError for an empty output path, non-positive duration, fps, rates or
  // intervals, a scene JSON with the car park, a time of day or path without the car park, a path
  // with --trajectory, an unknown path, a non-positive speed or map spacing or a negative path
  // start, a ground-truth rate below 200 Hz, an unknown sensor, a bad noise rate or hot-pixel
  // fraction or cutoff, or --clean with a noise, hot-pixel or cutoff override.
  void Check() const;
};

// Runs `render`; returns the info.json written. Throws the library's typed errors.
nlohmann::json RunRenderCommand(const RenderCommandOptions& options);

// Options of `evloc-sim survey`: the photos a mapping team takes of the car park, with their
// exact poses, as a dataset the mapper builds from (`evloc-mapper build --known-poses`).
struct SurveyCommandOptions {
  // Output dataset folder.
  std::filesystem::path out_dir;
  // Camera preset name (ignored when camera_yaml is set).
  std::string camera_preset = "default";
  // Camera YAML file overriding the preset.
  std::optional<std::filesystem::path> camera_yaml;
  // The car park's layout (its seed: `--site-seed`).
  CarParkOptions site;
  // Time of day (`--time-of-day`); day when unset.
  std::optional<TimeOfDay> time_of_day;
  // "walk": hand-held photos 1.4 m up along the survey loops (one per lane), alternately looking
  // 40 degrees left, ahead and 40 degrees right; "car": a mapping car's forward camera 2 m up
  // along the vehicle route (`--survey`).
  std::string survey = "walk";
  // Distance between two photos along the path, metres (`--spacing`).
  double spacing_m = 2.0;
  // Where along the path the survey starts, metres (`--path-start`).
  double start_m = 0;
  // At most this many photos (`--max-photos`); the whole path when unset.
  std::optional<int> max_photos;
  // Seed of the walk's gait and the car's vibrations.
  uint64_t seed = 1;
  // Replace an existing non-empty output folder.
  bool force = false;

  // Throws InvalidArgumentError for an empty output path, an unknown survey, a non-positive
  // spacing or photo count, or a negative start.
  void Check() const;
};

// Runs `survey`; returns the info.json written.
nlohmann::json RunSurveyCommand(const SurveyCommandOptions& options);

// Options of `evloc-sim events-from-frames`.
struct EventsFromFramesCommandOptions {
  // Input dataset folder (evloc-sim output or an ECD folder with images.txt).
  std::filesystem::path in_dir;
  // Output dataset folder.
  std::filesystem::path out_dir;
  // Sensor size for an ECD calib.txt input.
  int ecd_width = 240;
  // Sensor height for an ECD calib.txt input.
  int ecd_height = 180;
  // Conversion options (ESIM, interpolation).
  EventsFromFramesOptions conversion;
  // Also write events.txt (ECD text).
  bool events_txt = false;
  // Replace an existing non-empty output folder.
  bool force = false;

  // Throws InvalidArgumentError for empty paths, equal in and out, bad sizes or conversion options.
  void Check() const;
};

// Runs `events-from-frames`; returns the info.json written.
nlohmann::json RunEventsFromFramesCommand(const EventsFromFramesCommandOptions& options);

}  // namespace evloc::sim
