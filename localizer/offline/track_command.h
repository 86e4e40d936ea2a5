// evloc-track: offline tracking of a dataset against a map, with the code the service runs.
#pragma once

#include <filesystem>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "core/geometry/rigid3.h"
#include "localizer/offline/offline_tracking.h"

namespace evloc::tracking {

// Everything evloc-track's command line sets.
struct TrackCommandOptions {
  // Map directory or .evmap file (--map).
  std::filesystem::path map_path;
  // Dataset folder in the evloc/ECD layout (--dataset).
  std::filesystem::path dataset_path;
  // Output TUM trajectory, world_from_cam at every step (--out).
  std::filesystem::path output_path;
  // Initial pose (--init-pose "tx ty tz qx qy qz qw"); defaults to the first ground-truth pose.
  std::optional<Rigid3d> initial_world_from_cam;
  // Per-step statistics as JSON (--stats).
  std::optional<std::filesystem::path> stats_path;
  // Folder for debug pictures (--debug-dir).
  std::optional<std::filesystem::path> debug_dir;
  // Write a debug picture every this many steps (--debug-every).
  int debug_every_steps = 30;
  // Sensor size for ECD datasets with only calib.txt (--ecd-size WxH).
  int ecd_width = 240;
  // Height for --ecd-size.
  int ecd_height = 180;
  // No progress output (--quiet).
  bool quiet = false;
  // Print the usage (--help).
  bool help = false;
  // The offline run's options (--mode, --rate, --events-per-step, --polarity, --occlusion,
  // --variant, --max-points, --tau).
  OfflineTrackingOptions tracking;

  // Throws InvalidArgumentError when a required flag is missing or a value is out of range.
  void Check() const;
};

// The usage text.
std::string TrackCommandUsage();

// Parses the arguments after the program name. Throws InvalidArgumentError.
TrackCommandOptions ParseTrackCommandLine(const std::vector<std::string>& arguments);

// Runs evloc-track; progress and the summary go to `log`. Throws the library's errors.
OfflineTrackingResult RunTrackCommand(const TrackCommandOptions& options, std::ostream& log);

}  // namespace evloc::tracking
