// evloc-sim: the event camera simulator's command line (docs/simulator.md). Parses flags into
// the options of tools/sim/render_command.h and reports errors; all work is in the library.
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "core/camera/calibration_file.h"
#include "core/common/cli.h"
#include "core/common/cli_app.h"
#include "core/common/error.h"
#include "tools/sim/render_command.h"

namespace {

using evloc::CommandLine;
using evloc::InvalidArgumentError;
using evloc::ParseSizeFlag;
using evloc::ParseUnsignedFlag;
using evloc::UsageError;

// The flags `render` and `survey` share: the camera and the car park.
void DeclareCameraAndSiteFlags(CommandLine& line, std::string* camera_preset,
                               std::optional<std::filesystem::path>* camera_yaml,
                               evloc::sim::CarParkOptions* site,
                               std::optional<evloc::sim::TimeOfDay>* time_of_day) {
  line.Add("--camera", "NAME",
           "default (640x480 pinhole, f=500 px) | davis240 (ECD DAVIS240C); default: default",
           camera_preset)
      .Add("--camera-yaml", "FILE",
           "a camera file (evloc YAML, Kalibr, ROS, OpenCV, COLMAP: docs/camera.md), overrides "
           "--camera",
           camera_yaml)
      .Add("--site-seed", "N", "seed of the car park's layout; default 1", &site->seed)
      .Add("--ground-marks", "D",
           "stains and small repairs on the car park's asphalt per square metre (the fine texture "
           "of real asphalt), 0-20; default 0",
           &site->ground_marks_per_m2)
      .Add("--time-of-day", "NAME",
           "car park lighting: day | dusk | night (street lamps on at dusk and night); default: "
           "day",
           [time_of_day](const std::string&, const std::string& value) {
             *time_of_day = evloc::sim::ParseTimeOfDay(value);
           });
}

// The depth camera's flags of `render`, applied once every flag is read (they need
// --depth-camera).
struct DepthCameraFlags {
  bool enabled = false;
  std::optional<double> fps;
  std::optional<double> noise_at_1m_m;
  std::optional<std::string> camera_yaml;
};

// The flags of `render` over `options` and `depth`.
void DeclareRender(CommandLine& line, evloc::sim::RenderCommandOptions* options,
                   DepthCameraFlags* depth) {
  line.Add("--out", "DIR", "output dataset folder (written as DIR.partial, renamed when complete)",
           &options->out_dir);
  DeclareCameraAndSiteFlags(line, &options->camera_preset, &options->camera_yaml, &options->site,
                            &options->time_of_day);
  line.Add("--scene", "FILE|carpark",
           "scene JSON (docs/sim-scene.md), or carpark: the generated 200 m x 200 m car park "
           "site; default: the built-in room",
           [options](const std::string&, const std::string& value) {
             if (value == "carpark") {
               options->carpark = true;
             } else {
               options->scene_json = value;
             }
           })
      .Add("--path", "NAME",
           "car park path instead of --motion: vehicle (forward camera 1.5 m up along the "
           "serpentine route through the lanes) | pedestrian (hand-held, 1.4 m/s)",
           &options->path)
      .Add("--speed", "M/S", "vehicle speed along the route; default 5", &options->speed_m_per_s)
      .Add("--path-start", "M", "where along the route the path starts, metres; default 0",
           &options->path_start_m)
      .Add("--map-spacing", "M",
           "spacing of the ground-truth map's points along edges; default 0.01",
           &options->map_spacing_m)
      .Add("--map-until", "S",
           "the ground-truth map from the path's first S seconds only (a map of the part of the "
           "scene seen then); default: the whole path",
           [options](const std::string& flag, const std::string& value) {
             options->map_until_s = evloc::ParseDoubleFlag(flag, value);
           })
      .Add("--motion", "NAME", "slow | mid | fast | aggressive; default: mid",
           [options](const std::string&, const std::string& value) {
             options->motion = evloc::sim::ParseMotionProfile(value);
           })
      .Add("--trajectory", "FILE",
           "TUM trajectory replayed relative to its first pose instead of --motion",
           &options->trajectory_file)
      .Add("--duration", "S", "seconds; default 10 for --motion, the whole file for --trajectory",
           &options->duration_s)
      .Add("--fps", "F", "frame camera rate, Hz; default 30", &options->fps)
      .Add("--lighting", "NAME", "bright | dim | dark | hdr; default: bright",
           [options](const std::string&, const std::string& value) {
             options->lighting = evloc::sim::ParseLightingCondition(value);
           })
      .Add("--seed", "N", "seed of motion and noise (same seed, same bytes); default 1",
           &options->seed)
      .Add("--render-motion", "PX",
           "largest image motion between two renders; images in between are interpolated along "
           "the depth-based flow (0.5 = render every image); default 3",
           &options->max_render_motion_px)
      .Group("Event pixel")
      .Add("--sensor", "NAME",
           "event pixel: ideal | davis240 | davis346 | gen3 | gen4 (docs/simulator.md, \"Sensor "
           "presets\"); default: ideal (the ESIM pixel)",
           [options](const std::string&, const std::string& value) {
             evloc::sim::SensorPreset(value);
             options->sensor = value;
           })
      .Add("--noise-rate", "HZ",
           "shot-noise rate per pixel at the darkest level (falls as light rises with a "
           "realistic sensor; uniform with ideal); default: the sensor's",
           &options->noise_rate_hz)
      .Add("--hot-pixels", "F",
           "fraction of hot pixels (each fires ~1 kHz whatever the light), e.g. 0.001; default: "
           "the sensor's (0)",
           &options->hot_pixel_fraction)
      .Add("--cutoff", "HZ",
           "photoreceptor cutoff at intensity 1 (white paper, bright light); it falls with the "
           "light; 0 = no low-pass; default: the sensor's",
           &options->photoreceptor_cutoff_hz)
      .Switch("--clean",
              "perfect event pixel: no threshold mismatch, refractory period, noise, leak, hot "
              "pixels, low-pass or read-out limit",
              &options->clean)
      .Group("Depth camera")
      .Switch("--depth-camera",
              "also a depth camera beside the event camera (docs/simulator.md, \"Depth camera\"): "
              "VGA, f = 525, 5 cm to the right, its own frames in depth_camera.txt with "
              "depth_camchain.yaml",
              &depth->enabled)
      .Add("--depth-fps", "F", "the depth camera's rate, Hz; default 30",
           [depth](const std::string& flag, const std::string& value) {
             depth->fps = evloc::ParseDoubleFlag(flag, value);
           })
      .Add("--depth-noise", "M",
           "its depth noise at 1 m (growing with depth squared), metres; default 0.0015",
           [depth](const std::string& flag, const std::string& value) {
             depth->noise_at_1m_m = evloc::ParseDoubleFlag(flag, value);
           })
      .Add("--depth-camera-yaml", "FILE", "its intrinsics instead of the VGA preset",
           [depth](const std::string&, const std::string& value) { depth->camera_yaml = value; })
      .Group("Output")
      .Switch("--events-txt", "also write events.txt (ECD text format)", &options->events_txt)
      .Switch("--force", "replace an existing non-empty output folder", &options->force);
}

// The flags of `survey` over `options`.
void DeclareSurvey(CommandLine& line, evloc::sim::SurveyCommandOptions* options) {
  line.Add("--out", "DIR", "output dataset folder (images, depth, groundtruth.txt, calib.yaml)",
           &options->out_dir)
      .Add("--survey", "NAME",
           "walk (hand-held, 1.4 m up, loops along every lane, looking left, ahead and right in "
           "turn) | car (a mapping car's forward camera, 2 m up, along the vehicle route); "
           "default: walk",
           &options->survey)
      .Add("--spacing", "M", "metres between two photos along the path; default 2",
           &options->spacing_m)
      .Add("--path-start", "M", "where along the path the survey starts, metres; default 0",
           &options->start_m)
      .Add("--max-photos", "N", "at most N photos; default: the whole path",
           [options](const std::string& flag, const std::string& value) {
             options->max_photos = static_cast<int>(std::min<uint64_t>(
                 ParseUnsignedFlag(flag, value), static_cast<uint64_t>(1) << 30));
           });
  DeclareCameraAndSiteFlags(line, &options->camera_preset, &options->camera_yaml, &options->site,
                            &options->time_of_day);
  line.Add("--seed", "N", "seed of the walk's gait and the car's vibrations; default 1",
           &options->seed)
      .Switch("--force", "replace an existing non-empty output folder", &options->force);
}

// The flags of `events-from-frames` over `options`; --clean sets `*clean` (applied after every
// other flag, as it replaces the pixel's options).
void DeclareEventsFromFrames(CommandLine& line, evloc::sim::EventsFromFramesCommandOptions* options,
                             bool* clean) {
  line.Add("--in", "DATASET", "input folder with images.txt (evloc-sim output or ECD)",
           &options->in_dir)
      .Add("--out", "DIR", "output dataset folder", &options->out_dir)
      .Add("--ecd-size", "WxH", "sensor size for an ECD calib.txt input; default 240x180",
           [options](const std::string& flag, const std::string& value) {
             ParseSizeFlag(flag, value, &options->ecd_width, &options->ecd_height);
           })
      .Add("--contrast", "C", "ESIM contrast threshold (ON and OFF); default 0.2",
           [options](const std::string& flag, const std::string& value) {
             auto& esim = options->conversion.esim;
             esim.contrast_threshold_on = evloc::ParseDoubleFlag(flag, value);
             esim.contrast_threshold_off = esim.contrast_threshold_on;
           })
      .Add("--gamma", "G", "input frames are raised to G to get linear intensity; default 1",
           &options->conversion.input_gamma)
      .Add("--seed", "N", "seed of mismatch and noise; default 1", &options->conversion.esim.seed)
      .Switch("--clean", "perfect event pixel (as for render)", clean)
      .Switch("--events-txt", "also write events.txt (ECD text format)", &options->events_txt)
      .Switch("--force", "replace an existing non-empty output folder", &options->force);
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

int RunRender(const CommandLine& line, evloc::sim::RenderCommandOptions& options,
              const DepthCameraFlags& depth) {
  const bool depth_flags = line.Count("--depth-fps") > 0 || line.Count("--depth-noise") > 0 ||
                           line.Count("--depth-camera-yaml") > 0;
  if (depth_flags && !depth.enabled) {
    throw UsageError("--depth-fps, --depth-noise and --depth-camera-yaml need --depth-camera.");
  }
  if (depth.enabled) {
    options.depth_camera.emplace();
    if (depth.fps) options.depth_camera->fps = *depth.fps;
    if (depth.noise_at_1m_m) options.depth_camera->noise_at_1m_m = *depth.noise_at_1m_m;
    if (depth.camera_yaml) {
      std::vector<std::string> notes;
      options.depth_camera->camera = evloc::ReadCalibrationFile(*depth.camera_yaml, 0, 0, &notes);
      for (const std::string& note : notes) std::cerr << "evloc-sim render: note: " << note << "\n";
    }
  }
  if (line.Count("--out") == 0) throw UsageError("render needs --out DIR.");
  if (line.Count("--motion") > 0 && line.Count("--trajectory") > 0) {
    throw UsageError("--motion and --trajectory exclude each other.");
  }
  if (line.Count("--motion") > 0 && line.Count("--path") > 0) {
    throw UsageError("--motion and --path exclude each other.");
  }
  RequireKnownCamera(options.camera_yaml.has_value(), options.camera_preset);
  options.Check();
  const auto info = evloc::sim::RunRenderCommand(options);
  if (info.contains("calibration_notes")) {
    for (const auto& note : info["calibration_notes"]) {
      std::cerr << "evloc-sim render: note: " << note.get<std::string>() << "\n";
    }
  }
  std::cout << "evloc-sim render: wrote " << options.out_dir.string() << ": "
            << info["counts"]["events"] << " events (" << info["counts"]["event_rate_per_s"]
            << " /s; noise " << info["counts"]["noise_events"] << ", leak "
            << info["counts"]["leak_events"] << ", hot pixels "
            << info["counts"]["hot_pixel_events"] << "), " << info["counts"]["frames"]
            << " frames, " << info["counts"]["renders"] << " renders in "
            << info["timings_s"]["total"] << " s\n";
  return 0;
}

int RunSurvey(const CommandLine& line, evloc::sim::SurveyCommandOptions& options) {
  if (line.Count("--out") == 0) throw UsageError("survey needs --out DIR.");
  RequireKnownCamera(options.camera_yaml.has_value(), options.camera_preset);
  options.Check();
  const auto info = evloc::sim::RunSurveyCommand(options);
  std::cout << "evloc-sim survey: wrote " << options.out_dir.string() << ": "
            << info["counts"]["photos"] << " photos in " << info["timings_s"]["total"] << " s\n";
  return 0;
}

int RunEventsFromFrames(const CommandLine& line,
                        evloc::sim::EventsFromFramesCommandOptions& options, bool clean) {
  if (line.Count("--in") == 0 || line.Count("--out") == 0) {
    throw UsageError("events-from-frames needs --in DATASET and --out DIR.");
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
    evloc::sim::RenderCommandOptions render_options;
    DepthCameraFlags depth_flags;
    evloc::sim::SurveyCommandOptions survey_options;
    evloc::sim::EventsFromFramesCommandOptions events_options;
    bool clean_events = false;
    CommandLine line("evloc-sim",
                     "render --out DIR [options]\n"
                     "events-from-frames --in DATASET --out DIR [options]\n"
                     "survey --out DIR [options]\n"
                     "--help",
                     "Simulates an event camera dataset (docs/simulator.md).");
    CommandLine& render =
        line.Subcommand("render", "--out DIR [options]",
                        "Renders a scene along a motion into a dataset: events, frames, depth, "
                        "ground truth and the exact ground-truth map.");
    DeclareRender(render, &render_options, &depth_flags);
    CommandLine& survey = line.Subcommand(
        "survey", "--out DIR [options]",
        "Photos of the car park with exact poses, for evloc-mapper build --known-poses.");
    DeclareSurvey(survey, &survey_options);
    CommandLine& events_from_frames =
        line.Subcommand("events-from-frames", "--in DATASET --out DIR [options]",
                        "Events from a dataset's frames (ESIM between interpolated frames).");
    DeclareEventsFromFrames(events_from_frames, &events_options, &clean_events);
    line.Footer("Exit codes: 0 success, 2 bad command line, 1 failure while running.");

    const bool known_command = !args.empty() && (args[0] == "render" || args[0] == "survey" ||
                                                 args[0] == "events-from-frames");
    if (args.empty() || (!known_command && (args[0] == "--help" || args[0] == "-h"))) {
      std::cout << line.Help(/*expand_subcommands=*/true);
      return args.empty() ? evloc::kExitUsage : evloc::kExitSuccess;
    }
    if (!known_command) {
      throw UsageError("unknown command '" + args[0] +
                       "'; expected render, survey or events-from-frames.");
    }
    try {
      line.Parse(args);
      CommandLine* chosen = line.chosen_subcommand();
      if (chosen->help_requested()) {
        std::cout << chosen->Help();
        return evloc::kExitSuccess;
      }
      if (chosen == &render) return RunRender(render, render_options, depth_flags);
      if (chosen == &survey) return RunSurvey(survey, survey_options);
      return RunEventsFromFrames(events_from_frames, events_options, clean_events);
    } catch (const UsageError&) {
      throw;
    } catch (const InvalidArgumentError& error) {
      // An option value found invalid while running (an option's Check(), an existing --out
      // without --force) is a bad command line too (docs/simulator.md).
      throw UsageError(error.what());
    }
  });
}
