// evloc-track: offline tracking of a dataset against a map, with the code the service runs.
#pragma once

#include <filesystem>
#include <optional>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "core/dataset/dataset.h"
#include "core/geo/gnss_prior.h"
#include "core/geometry/rigid3.h"
#include "localizer/odometry/handover.h"
#include "localizer/odometry/odometry_run.h"
#include "localizer/offline/offline_tracking.h"
#include "localizer/tracking/tiled_map_source.h"

namespace evloc::tracking {

// Everything evloc-track's command line sets.
struct TrackCommandOptions {
  // Map directory or .evmap file (--map).
  std::filesystem::path map_path;
  // When map_path is a site (a folder with site.manifest): which tiles a pose needs (--tile-radius,
  // --tile-lookahead, --tile-view-distance; always synchronous here, so runs are reproducible)
  // and the tile cache's budget (--map-memory).
  TileSelectionOptions tiles;
  // Budget of the loaded tiles, bytes (--map-memory SIZE).
  uint64_t map_memory_bytes = TileCacheOptions{}.memory_budget_bytes;
  // Dataset folder in the evloc/ECD layout, a ROS1 bag or an AEDAT4 file (--dataset).
  std::filesystem::path dataset_path;
  // The topics when the dataset is a bag (--events-topic, --image-topic, --camera-info-topic,
  // --groundtruth-topic).
  RosbagTopics bag_topics;
  // The streams, calibration and ground truth when the dataset is an AEDAT4 file
  // (--events-topic, --image-topic, --calib, --groundtruth).
  Aedat4DatasetOptions aedat4;
  // Output TUM trajectory, world_from_cam at every step (--out).
  std::filesystem::path output_path;
  // Initial pose (--init-pose "tx ty tz qx qy qz qw"); defaults to the first ground-truth pose
  // (at --start: the ground truth at that time).
  std::optional<Rigid3d> initial_world_from_cam;
  // Start without a pose and search the map (--init-pose none).
  bool no_initial_pose = false;
  // Start moving (--initial-velocity "vx vy vz wx wy wz": the body-frame twist of world_from_cam,
  // m/s and rad/s in the camera frame) instead of at rest...
  std::optional<Vector6d> initial_velocity;
  // ... or with the ground truth's velocity at the start (--initial-velocity truth).
  bool initial_velocity_from_truth = false;
  // A GNSS fix where the run starts (--gnss LAT,LON,ALT,SIGMA[,SIGMA_V]): with --init-pose none
  // the search looks only near it (on a site, in the tiles near it) until the first TRACKING
  // step. Needs a map or site with a geo anchor.
  std::optional<GnssPrior> gnss;
  // The search also locates images of the events in the map's relocalization data (--search-images
  // on|off; used when the map has that data).
  bool search_images = true;
  // Start this many seconds after the dataset's first event (or frame), ignoring everything
  // before (--start S).
  std::optional<double> start_s;
  // Drop the events from this many seconds after the first event... (--blackout T0:T1)
  std::optional<double> blackout_begin_s;
  // ...to this many seconds after it.
  std::optional<double> blackout_end_s;
  // The trajectory in WGS84 (--geo FILE; docs/geo.md): needs a map with a geo anchor.
  std::optional<std::filesystem::path> geo_path;
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
  // Mapless odometry instead of map tracking (--mode vo | devo; no --map).
  std::optional<odometry::OdometryMode> odometry;
  // Map tracking with the hand-over to Canny-DEVO where the map is not seen (--handover; events
  // mode, a whole map and a dataset with depth).
  bool handover = false;
  // The hand-over's own options (--handover-leave-points).
  odometry::HandoverOptions handover_options;
  // The offline run's options (--mode, --rate, --events-per-step, --polarity, --occlusion,
  // --variant, --max-points, --tau).
  OfflineTrackingOptions tracking;
  // The event tracker's flags given (--rate ... --max-mean-residual, the noise filters), with
  // their values, in order: --mode devo applies them to its own tracker, over its defaults
  // (CannyDevoOptions::DefaultTrackerOptions); --mode vo, which has no event tracker, refuses them.
  std::vector<std::pair<std::string, std::string>> tracker_flags;
  // The map search's flags given (--relocalize-after, --give-up, --search-*): odometry, which
  // searches no map, refuses them.
  std::vector<std::string> search_flags;

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
