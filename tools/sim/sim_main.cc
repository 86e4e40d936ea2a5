// evloc-sim: the event camera simulator's command line (docs/simulator.md). Parses flags into
// the options of tools/sim/render_command.h and reports errors; all work is in the library.
#include <algorithm>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include "core/camera/calibration_file.h"
#include "core/common/cli.h"
#include "core/common/error.h"
#include "tools/sim/render_command.h"

namespace {

using evloc::InvalidArgumentError;
using evloc::ParseDoubleFlag;
using evloc::ParseSizeFlag;
using evloc::ParseUnsignedFlag;
using evloc::TakeFlagValue;
using evloc::UsageError;

constexpr char kUsage[] = R"(evloc-sim: simulate an event camera dataset (docs/simulator.md).

Usage:
  evloc-sim render --out DIR [options]
  evloc-sim events-from-frames --in DATASET --out DIR [options]
  evloc-sim survey --out DIR [options]
  evloc-sim --help

render options:
  --out DIR             output dataset folder (written as DIR.partial, renamed when complete)
  --camera NAME         default (640x480 pinhole, f=500 px) | davis240 (ECD DAVIS240C); default: default
  --camera-yaml FILE    a camera file (evloc YAML, Kalibr, ROS, OpenCV, COLMAP: docs/camera.md),
                        overrides --camera
  --scene FILE|carpark  scene JSON (docs/sim-scene.md), or carpark: the generated 200 m x 200 m
                        car park site; default: the built-in room
  --site-seed N         seed of the car park's layout; default 1
  --time-of-day NAME    car park lighting: day | dusk | night (street lamps on at dusk and night);
                        default: day
  --path NAME           car park path instead of --motion: vehicle (forward camera 1.5 m up along
                        the serpentine route through the lanes) | pedestrian (hand-held, 1.4 m/s)
  --speed M/S           vehicle speed along the route; default 5
  --path-start M        where along the route the path starts, metres; default 0
  --map-spacing M       spacing of the ground-truth map's points along edges; default 0.01
  --map-until S         the ground-truth map from the path's first S seconds only (a map of the
                        part of the scene seen then); default: the whole path
  --motion NAME         slow | mid | fast | aggressive; default: mid
  --trajectory FILE     TUM trajectory replayed relative to its first pose instead of --motion
  --duration S          seconds; default 10 for --motion, the whole file for --trajectory
  --fps F               frame camera rate, Hz; default 30
  --lighting NAME       bright | dim | dark | hdr; default: bright
  --seed N              seed of motion and noise (same seed, same bytes); default 1
  --render-motion PX    largest image motion between two renders; images in between are
                        interpolated along the depth-based flow (0.5 = render every image); default 3
  --sensor NAME         event pixel: ideal | davis240 | davis346 | gen3 | gen4 (docs/simulator.md,
                        "Sensor presets"); default: ideal (the ESIM pixel)
  --noise-rate HZ       shot-noise rate per pixel at the darkest level (falls as light rises with
                        a realistic sensor; uniform with ideal); default: the sensor's
  --hot-pixels F        fraction of hot pixels (each fires ~1 kHz whatever the light), e.g. 0.001;
                        default: the sensor's (0)
  --cutoff HZ           photoreceptor cutoff at intensity 1 (white paper, bright light); it falls
                        with the light; 0 = no low-pass; default: the sensor's
  --clean               perfect event pixel: no threshold mismatch, refractory period, noise, leak,
                        hot pixels, low-pass or read-out limit
  --events-txt          also write events.txt (ECD text format)
  --depth-camera        also a depth camera beside the event camera (docs/simulator.md, "Depth
                        camera"): VGA, f = 525, 5 cm to the right, its own frames in
                        depth_camera.txt with depth_camchain.yaml
  --depth-fps F         the depth camera's rate, Hz; default 30
  --depth-noise M       its depth noise at 1 m (growing with depth squared), metres; default 0.0015
  --depth-camera-yaml FILE  its intrinsics instead of the VGA preset
  --force               replace an existing non-empty output folder

survey options (photos of the car park with exact poses, for evloc-mapper build --known-poses):
  --out DIR             output dataset folder (images, depth, groundtruth.txt, calib.yaml)
  --survey NAME         walk (hand-held, 1.4 m up, loops along every lane, looking left, ahead and
                        right in turn) | car (a mapping car's forward camera, 2 m up, along the
                        vehicle route); default: walk
  --spacing M           metres between two photos along the path; default 2
  --path-start M        where along the path the survey starts, metres; default 0
  --max-photos N        at most N photos; default: the whole path
  --camera, --camera-yaml, --site-seed, --time-of-day, --seed, --force   as for render

events-from-frames options:
  --in DATASET          input folder with images.txt (evloc-sim output or ECD)
  --out DIR             output dataset folder
  --ecd-size WxH        sensor size for an ECD calib.txt input; default 240x180
  --contrast C          ESIM contrast threshold (ON and OFF); default 0.2
  --gamma G             input frames are raised to G to get linear intensity; default 1
  --seed N              seed of mismatch and noise; default 1
  --clean, --events-txt, --force   as for render

Exit codes: 0 success, 2 bad command line, 1 failure while running.
)";

// Flags as name -> value ("" for switches), checked against the allowed names.
std::map<std::string, std::string> ParseFlags(const std::vector<std::string>& args,
                                              const std::vector<std::string>& valued,
                                              const std::vector<std::string>& switches) {
  std::map<std::string, std::string> flags;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    const auto contains = [&](const std::vector<std::string>& names) {
      return std::find(names.begin(), names.end(), arg) != names.end();
    };
    if (contains(switches)) {
      flags[arg] = "";
    } else if (contains(valued)) {
      flags[arg] = TakeFlagValue(args, &i);
    } else {
      throw UsageError("unknown argument '" + arg + "'.");
    }
  }
  return flags;
}

// Calls `apply(flag, value)` for every flag; an invalid value becomes a UsageError naming the flag.
template <typename Apply>
void ForEachFlag(const std::map<std::string, std::string>& flags, const Apply& apply) {
  for (const auto& [flag, value] : flags) {
    try {
      apply(flag, value);
    } catch (const UsageError&) {
      throw;
    } catch (const InvalidArgumentError& error) {
      throw UsageError(flag + ": " + error.what());
    }
  }
}

// Throws a UsageError for an unknown --camera preset (unless a camera YAML replaces it).
void RequireKnownCamera(bool has_camera_yaml, const std::string& preset) {
  if (has_camera_yaml) return;
  try {
    evloc::sim::CameraPreset(preset);
  } catch (const InvalidArgumentError& error) {
    throw UsageError(std::string("--camera: ") + error.what());
  }
}

int RunRender(const std::vector<std::string>& args) {
  const auto flags = ParseFlags(
      args,
      {"--out",           "--camera",      "--camera-yaml", "--scene",       "--motion",
       "--trajectory",    "--duration",    "--fps",         "--lighting",    "--seed",
       "--render-motion", "--sensor",      "--noise-rate",  "--hot-pixels",  "--cutoff",
       "--site-seed",     "--time-of-day", "--path",        "--speed",       "--path-start",
       "--map-spacing",   "--map-until",   "--depth-fps",   "--depth-noise", "--depth-camera-yaml"},
      {"--clean", "--events-txt", "--force", "--depth-camera"});
  evloc::sim::RenderCommandOptions options;
  const bool depth_flags = flags.contains("--depth-fps") || flags.contains("--depth-noise") ||
                           flags.contains("--depth-camera-yaml");
  if (depth_flags && !flags.contains("--depth-camera")) {
    throw UsageError("--depth-fps, --depth-noise and --depth-camera-yaml need --depth-camera.");
  }
  if (flags.contains("--depth-camera")) options.depth_camera.emplace();
  if (!flags.contains("--out")) throw UsageError("render needs --out DIR.");
  if (flags.contains("--motion") && flags.contains("--trajectory")) {
    throw UsageError("--motion and --trajectory exclude each other.");
  }
  if (flags.contains("--motion") && flags.contains("--path")) {
    throw UsageError("--motion and --path exclude each other.");
  }
  ForEachFlag(flags, [&](const std::string& flag, const std::string& value) {
    if (flag == "--out") options.out_dir = value;
    if (flag == "--camera") options.camera_preset = value;
    if (flag == "--camera-yaml") options.camera_yaml = value;
    if (flag == "--scene") {
      if (value == "carpark") {
        options.carpark = true;
      } else {
        options.scene_json = value;
      }
    }
    if (flag == "--site-seed") options.site.seed = ParseUnsignedFlag(flag, value);
    if (flag == "--time-of-day") options.time_of_day = evloc::sim::ParseTimeOfDay(value);
    if (flag == "--path") options.path = value;
    if (flag == "--speed") options.speed_m_per_s = ParseDoubleFlag(flag, value);
    if (flag == "--path-start") options.path_start_m = ParseDoubleFlag(flag, value);
    if (flag == "--map-spacing") options.map_spacing_m = ParseDoubleFlag(flag, value);
    if (flag == "--map-until") options.map_until_s = ParseDoubleFlag(flag, value);
    if (flag == "--motion") options.motion = evloc::sim::ParseMotionProfile(value);
    if (flag == "--trajectory") options.trajectory_file = value;
    if (flag == "--duration") options.duration_s = ParseDoubleFlag(flag, value);
    if (flag == "--fps") options.fps = ParseDoubleFlag(flag, value);
    if (flag == "--lighting") options.lighting = evloc::sim::ParseLightingCondition(value);
    if (flag == "--seed") options.seed = ParseUnsignedFlag(flag, value);
    if (flag == "--render-motion") options.max_render_motion_px = ParseDoubleFlag(flag, value);
    if (flag == "--sensor") {
      evloc::sim::SensorPreset(value);
      options.sensor = value;
    }
    if (flag == "--noise-rate") options.noise_rate_hz = ParseDoubleFlag(flag, value);
    if (flag == "--hot-pixels") options.hot_pixel_fraction = ParseDoubleFlag(flag, value);
    if (flag == "--cutoff") options.photoreceptor_cutoff_hz = ParseDoubleFlag(flag, value);
    if (flag == "--clean") options.clean = true;
    if (flag == "--events-txt") options.events_txt = true;
    if (flag == "--depth-fps") options.depth_camera->fps = ParseDoubleFlag(flag, value);
    if (flag == "--depth-noise") options.depth_camera->noise_at_1m_m = ParseDoubleFlag(flag, value);
    if (flag == "--depth-camera-yaml") {
      options.depth_camera->camera = evloc::ReadCalibrationFile(value, 0, 0);
    }
    if (flag == "--force") options.force = true;
  });
  RequireKnownCamera(options.camera_yaml.has_value(), options.camera_preset);
  options.Check();
  const auto info = evloc::sim::RunRenderCommand(options);
  std::cout << "evloc-sim render: wrote " << options.out_dir.string() << ": "
            << info["counts"]["events"] << " events (" << info["counts"]["event_rate_per_s"]
            << " /s; noise " << info["counts"]["noise_events"] << ", leak "
            << info["counts"]["leak_events"] << ", hot pixels "
            << info["counts"]["hot_pixel_events"] << "), " << info["counts"]["frames"]
            << " frames, " << info["counts"]["renders"] << " renders in "
            << info["timings_s"]["total"] << " s\n";
  return 0;
}

int RunSurvey(const std::vector<std::string>& args) {
  const auto flags =
      ParseFlags(args,
                 {"--out", "--survey", "--spacing", "--path-start", "--max-photos", "--camera",
                  "--camera-yaml", "--site-seed", "--time-of-day", "--seed"},
                 {"--force"});
  if (!flags.contains("--out")) throw UsageError("survey needs --out DIR.");
  evloc::sim::SurveyCommandOptions options;
  ForEachFlag(flags, [&](const std::string& flag, const std::string& value) {
    if (flag == "--out") options.out_dir = value;
    if (flag == "--survey") options.survey = value;
    if (flag == "--spacing") options.spacing_m = ParseDoubleFlag(flag, value);
    if (flag == "--path-start") options.start_m = ParseDoubleFlag(flag, value);
    if (flag == "--max-photos") {
      options.max_photos = static_cast<int>(
          std::min<uint64_t>(ParseUnsignedFlag(flag, value), static_cast<uint64_t>(1) << 30));
    }
    if (flag == "--camera") options.camera_preset = value;
    if (flag == "--camera-yaml") options.camera_yaml = value;
    if (flag == "--site-seed") options.site.seed = ParseUnsignedFlag(flag, value);
    if (flag == "--time-of-day") options.time_of_day = evloc::sim::ParseTimeOfDay(value);
    if (flag == "--seed") options.seed = ParseUnsignedFlag(flag, value);
    if (flag == "--force") options.force = true;
  });
  RequireKnownCamera(options.camera_yaml.has_value(), options.camera_preset);
  options.Check();
  const auto info = evloc::sim::RunSurveyCommand(options);
  std::cout << "evloc-sim survey: wrote " << options.out_dir.string() << ": "
            << info["counts"]["photos"] << " photos in " << info["timings_s"]["total"] << " s\n";
  return 0;
}

int RunEventsFromFrames(const std::vector<std::string>& args) {
  const auto flags =
      ParseFlags(args, {"--in", "--out", "--ecd-size", "--contrast", "--gamma", "--seed"},
                 {"--clean", "--events-txt", "--force"});
  evloc::sim::EventsFromFramesCommandOptions options;
  if (!flags.contains("--in") || !flags.contains("--out")) {
    throw UsageError("events-from-frames needs --in DATASET and --out DIR.");
  }
  bool clean = false;
  for (const auto& [flag, value] : flags) {
    if (flag == "--in") options.in_dir = value;
    if (flag == "--out") options.out_dir = value;
    if (flag == "--ecd-size") ParseSizeFlag(flag, value, &options.ecd_width, &options.ecd_height);
    if (flag == "--contrast") {
      options.conversion.esim.contrast_threshold_on = ParseDoubleFlag(flag, value);
      options.conversion.esim.contrast_threshold_off =
          options.conversion.esim.contrast_threshold_on;
    }
    if (flag == "--gamma") options.conversion.input_gamma = ParseDoubleFlag(flag, value);
    if (flag == "--seed") options.conversion.esim.seed = ParseUnsignedFlag(flag, value);
    if (flag == "--clean") clean = true;
    if (flag == "--events-txt") options.events_txt = true;
    if (flag == "--force") options.force = true;
  }
  if (clean) options.conversion.esim = options.conversion.esim.Clean();
  options.Check();
  const auto info = evloc::sim::RunEventsFromFramesCommand(options);
  std::cout << "evloc-sim events-from-frames: wrote " << options.out_dir.string() << ": "
            << info["counts"]["events"] << " events (" << info["counts"]["event_rate_per_s"]
            << " /s) from " << info["counts"]["input_frames"] << " frames and "
            << info["counts"]["interpolated_frames"] << " interpolated frames in "
            << info["timings_s"]["total"] << " s\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return evloc::RunTool("evloc-sim", argc, argv, [](const std::vector<std::string>& args) {
    if (args.empty() || args[0] == "--help" || args[0] == "-h" ||
        std::find(args.begin(), args.end(), "--help") != args.end()) {
      std::cout << kUsage;
      return args.empty() ? evloc::kExitUsage : evloc::kExitSuccess;
    }
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    try {
      if (args[0] == "render") return RunRender(rest);
      if (args[0] == "events-from-frames") return RunEventsFromFrames(rest);
      if (args[0] == "survey") return RunSurvey(rest);
    } catch (const UsageError&) {
      throw;
    } catch (const InvalidArgumentError& error) {
      // An option value found invalid while running (an option's Check(), an existing --out
      // without --force) is a bad command line too (docs/simulator.md).
      throw UsageError(error.what());
    }
    throw UsageError("unknown command '" + args[0] +
                     "'; expected render, survey or events-from-frames.");
  });
}
