#include "localizer/offline/track_command.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/common/cli.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/dataset/dataset.h"
#include "core/dataset/pose_text.h"
#include "core/events/event_reader.h"
#include "core/geo/geo_trajectory.h"
#include "core/trajectory/tum_io.h"
#include "localizer/offline/debug_images.h"
#include "localizer/offline/handover_track.h"
#include "localizer/offline/odometry_track.h"
#include "localizer/relocalization/event_image_hypotheses.h"
#include "localizer/tracking/event_filter.h"
#include "maps/map_directory.h"
#include "maps/site.h"

namespace evloc::tracking {
namespace {

nlohmann::json StepsToJson(const OfflineTrackingResult& result) {
  nlohmann::json steps = nlohmann::json::array();
  for (const PoseEstimate& step : result.steps) {
    steps.push_back({{"t_s", static_cast<double>(step.t_ns) * 1e-9},
                     {"status", TrackingStatusName(step.status)},
                     {"points_selected", step.quality.points_selected},
                     {"points_used", step.quality.points_used},
                     {"on_edge_fraction", step.quality.on_edge_fraction},
                     {"chance_on_edge_fraction", step.quality.chance_on_edge_fraction},
                     {"alignment", step.quality.alignment},
                     {"polarity_predictions", step.quality.polarity_predictions},
                     {"polarity_matches", step.quality.polarity_matches},
                     {"mean_residual", step.quality.mean_residual},
                     {"iterations", step.quality.iterations},
                     {"decay_time_ms", step.quality.decay_time_ms},
                     {"surface_age_ms", step.quality.surface_age_ms},
                     {"recovery_attempts", step.quality.recovery_attempts},
                     {"surface_ms", step.timings.surface_ms},
                     {"selection_ms", step.timings.selection_ms},
                     {"solve_ms", step.timings.solve_ms},
                     {"total_ms", step.timings.total_ms},
                     {"search_round", step.search.round},
                     {"search_prescored", step.search.prescored},
                     {"search_refined", step.search.refined},
                     {"search_deferred", step.search.deferred},
                     {"search_refilling", step.search.refilling},
                     {"search_followed", step.search.followed},
                     {"search_probe_replaced", step.search.probe_replaced},
                     {"search_image_hypotheses", step.search.image_hypotheses},
                     {"search_verified_steps", step.search.verified_steps},
                     {"search_best_alignment", step.search.best_alignment},
                     {"search_second_alignment", step.search.second_alignment}});
  }
  for (size_t i = 0; i < result.pose_sources.size() && i < steps.size(); ++i) {
    steps[i]["source"] = result.pose_sources[i];
  }
  // What the noise filters did between two steps (packet-granular: each packet is filtered whole
  // before the steps it completes run).
  EventFilterCounts previous;
  for (size_t i = 0; i < result.filter_counts.size() && i < steps.size(); ++i) {
    const EventFilterCounts& now = result.filter_counts[i];
    steps[i]["filter_input"] = now.input - previous.input;
    steps[i]["filter_hot_pixel"] = now.hot_pixel - previous.hot_pixel;
    steps[i]["filter_refractory"] = now.refractory - previous.refractory;
    steps[i]["filter_background_activity"] = now.background_activity - previous.background_activity;
    steps[i]["filter_masked_pixels"] = now.masked_pixels;
    previous = now;
  }
  return steps;
}

nlohmann::json RelocalizationsToJson(const OfflineTrackingResult& result) {
  nlohmann::json episodes = nlohmann::json::array();
  for (const RelocalizationEpisode& episode : result.relocalizations) {
    episodes.push_back({{"start_t_s", static_cast<double>(episode.start_t_ns) * 1e-9},
                        {"end_t_s", static_cast<double>(episode.end_t_ns) * 1e-9},
                        {"outcome", episode.outcome},
                        {"steps", episode.steps},
                        {"rounds", episode.rounds},
                        {"total_ms", episode.total_ms},
                        {"max_step_ms", episode.max_step_ms}});
  }
  return episodes;
}

nlohmann::json FilterCountsToJson(const EventFilterCounts& counts) {
  const auto fraction = [&](int64_t removed) {
    return counts.input > 0 ? static_cast<double>(removed) / static_cast<double>(counts.input)
                            : 0.0;
  };
  return {{"input", counts.input},
          {"passed", counts.passed},
          {"held", counts.held},
          {"hot_pixel", counts.hot_pixel},
          {"refractory", counts.refractory},
          {"background_activity", counts.background_activity},
          {"masked_pixels", counts.masked_pixels},
          {"hot_pixel_fraction", fraction(counts.hot_pixel)},
          {"refractory_fraction", fraction(counts.refractory)},
          {"background_activity_fraction", fraction(counts.background_activity)}};
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t middle = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + middle, values.end());
  return values[middle];
}

// Writes the trajectory, the statistics (--stats) and the summary line of a run.
void WriteTrackOutputs(const TrackCommandOptions& options, const std::string& variant,
                       const std::string& mode, const OfflineTrackingResult& result,
                       std::ostream& log, const std::optional<GeoAnchor>& anchor = std::nullopt) {
  WriteTumTrajectory(options.output_path, result.trajectory);
  if (options.geo_path) {
    const GeoReference reference(*anchor);  // RunTrackCommand checked that the map has one
    std::vector<TimedGeoPose> poses;
    poses.reserve(result.trajectory.size());
    for (const TimedPose& pose : result.trajectory.poses()) {
      poses.push_back({pose.t_ns, reference.PoseFromMap(pose.world_from_cam)});
    }
    WriteGeoTrajectory(*options.geo_path, *anchor, poses);
  }

  std::vector<double> step_ms;
  for (const PoseEstimate& step : result.steps) step_ms.push_back(step.timings.total_ms);
  if (options.stats_path) {
    nlohmann::json stats = {{"variant", variant},
                            {"mode", mode},
                            {"step_rate_hz", options.tracking.tracker.step_rate_hz},
                            {"measurements", result.measurements},
                            {"steps", result.steps.size()},
                            {"lost_steps", result.lost_steps},
                            {"relocalizations", RelocalizationsToJson(result)},
                            {"event_filter", FilterCountsToJson(result.final_filter_counts)},
                            {"wall_s", result.wall_s},
                            {"median_step_ms", Median(step_ms)},
                            {"per_step", StepsToJson(result)}};
    if (!result.reference_frames.empty()) {
      nlohmann::json frames = nlohmann::json::array();
      for (const ReferenceFrameRecord& frame : result.reference_frames) {
        frames.push_back({{"t_s", frame.t_s},
                          {"points", frame.points},
                          {"semi_dense_pixels", frame.semi_dense_pixels},
                          {"median_depth_m", frame.median_depth_m},
                          {"build_ms", frame.build_ms},
                          {"build_cpu_ms", frame.build_cpu_ms}});
      }
      stats["reference_frames"] = frames;
    }
    WriteFileAtomically(*options.stats_path, stats.dump(1) + "\n");
  }
  if (!options.quiet) {
    log << "evloc-track: " << result.steps.size() << " steps (" << result.lost_steps
        << " LOST) from " << result.measurements
        << (mode == "frames" || mode == "vo" ? " frames" : " events") << " in " << result.wall_s
        << " s wall; median step " << Median(step_ms) << " ms; trajectory written to "
        << options.output_path.string() << "\n";
    if (mode == "events" && options.tracking.tracker.event_filter.Enabled()) {
      const EventFilterCounts& counts = result.final_filter_counts;
      const double input = std::max<double>(1.0, static_cast<double>(counts.input));
      log << "evloc-track: noise filters removed " << counts.hot_pixel << " hot-pixel ("
          << 100.0 * counts.hot_pixel / input << " %), " << counts.refractory << " refractory ("
          << 100.0 * counts.refractory / input << " %), " << counts.background_activity
          << " background-activity (" << 100.0 * counts.background_activity / input << " %) of "
          << counts.input << " events; " << counts.masked_pixels << " pixels masked at the end\n";
    }
  }
}

// --gnss as the run's search prior: the fix in the map frame and its search radius.
void SetGnssPrior(const GnssPrior& prior, const GeoAnchor& anchor, OfflineTrackingOptions* run) {
  run->search_prior_center = GeoReference(anchor).MapFromGeodetic(prior.position);
  run->search_prior_radius_m = GnssSearchRadiusM(prior, anchor);
}

// evloc-track against a site (--map SITE): the tiles near the pose through a synchronous
// TiledMapSource, updated between event batches. Events only; debug pictures need a whole map.
OfflineTrackingResult RunSiteTrack(const TrackCommandOptions& options, const Dataset& dataset,
                                   const OfflineTrackingOptions& tracking,
                                   const std::optional<Rigid3d>& initial_world_from_cam,
                                   int64_t initial_t_ns, bool events_mode, std::ostream& log) {
  if (!events_mode) {
    throw InvalidArgumentError("--map " + options.map_path.string() +
                               " is a site: sites are tracked with --mode events only; give a "
                               "whole map for frames");
  }
  if (options.debug_dir) {
    throw InvalidArgumentError("--debug-dir needs a whole map; --map " + options.map_path.string() +
                               " is a site");
  }
  if (!initial_world_from_cam && !options.gnss) {
    throw InvalidArgumentError("--map " + options.map_path.string() +
                               " is a site: its tiles are chosen by the pose, so give an initial "
                               "pose, or with --init-pose none a GNSS fix (--gnss)");
  }
  if (!dataset.events_path) {
    throw InvalidArgumentError("dataset '" + options.dataset_path.string() +
                               "' has no events.evb or events.txt");
  }
  TileCacheOptions cache_options;
  cache_options.memory_budget_bytes = options.map_memory_bytes;
  auto cache = std::make_shared<TileCache>(cache_options);
  TileSelectionOptions selection = options.tiles;
  selection.synchronous = true;
  TiledMapSource source(OpenSite(options.map_path), cache, selection);
  const std::optional<GeoAnchor> anchor = SiteGeoAnchor(source.site().manifest);
  if ((options.geo_path || options.gnss) && !anchor) {
    throw InvalidArgumentError(MissingGeoAnchorMessage(options.map_path.string()));
  }
  OfflineTrackingOptions run = tracking;
  if (initial_world_from_cam) {
    source.LoadNow(*initial_world_from_cam);
  } else {
    // The tiles near the fix are composed (synchronously) when the run starts searching.
    SetGnssPrior(*options.gnss, *anchor, &run);
    source.SetSearchRegion(*run.search_prior_center, run.search_prior_radius_m);
  }
  if (!options.quiet) {
    log << "evloc-track: site " << source.site().manifest.name << " version "
        << source.site().manifest.version << " (" << source.site().manifest.tiles.size()
        << " tiles of " << source.site().manifest.grid.tile_size_m << " m), dataset "
        << options.dataset_path.string() << ", variant " << tracking.tracker.VariantName()
        << ", events at " << tracking.tracker.step_rate_hz << " Hz\n";
  }
  int64_t compositions = 0;
  const auto reader = OpenDatasetEvents(dataset);
  OfflineTrackingResult result =
      TrackEventStream(*reader, source, dataset.camera, initial_world_from_cam, initial_t_ns, run,
                       {}, [&](const Tracker& tracker) {
                         // The fix's region ends with the prior (OfflineTrackingOptions): once
                         // tracked, a later search starts from the last good pose's tiles.
                         if (tracker.status() == TrackingStatus::kTracking)
                           source.ClearSearchRegion();
                         compositions += source.Follow(tracker) ? 1 : 0;
                       });
  WriteTrackOutputs(options, tracking.tracker.VariantName(), "events", result, log, anchor);
  if (!options.quiet) {
    const TileCacheStats stats = cache->stats();
    log << "evloc-track: tiles: " << stats.loads << " loaded, " << stats.evictions << " evicted, "
        << compositions << " changes of the composed set, " << stats.resident_bytes
        << " bytes resident at the end\n";
  }
  return result;
}

}  // namespace

void TrackCommandOptions::Check() const {
  if (help) return;
  if (map_path.empty() && !odometry) {
    throw InvalidArgumentError("--map is required: a map directory or .evmap");
  }
  if (dataset_path.empty()) {
    throw InvalidArgumentError("--dataset is required: a dataset folder (docs/dataset-format.md)");
  }
  if (output_path.empty()) {
    throw InvalidArgumentError("--out is required: where to write the TUM trajectory");
  }
  if (debug_every_steps < 1) throw InvalidArgumentError("--debug-every must be at least 1");
  if (blackout_begin_s && !(std::isfinite(*blackout_begin_s) && std::isfinite(*blackout_end_s) &&
                            *blackout_begin_s >= 0 && *blackout_begin_s < *blackout_end_s)) {
    throw InvalidArgumentError("--blackout T0:T1 needs 0 <= T0 < T1");
  }
  if (start_s && (!std::isfinite(*start_s) || *start_s < 0)) {
    throw InvalidArgumentError("--start must be a number of seconds >= 0");
  }
  if (handover && (odometry || tracking.tracker.input != TrackerInput::kEvents || no_initial_pose ||
                   tracking.tracker.events_per_step)) {
    throw InvalidArgumentError(
        "--handover needs map tracking of events at a fixed rate (--mode events, no "
        "--events-per-step) from an initial pose");
  }
  if ((initial_velocity || initial_velocity_from_truth) &&
      (no_initial_pose || odometry || handover ||
       tracking.tracker.input != TrackerInput::kEvents)) {
    throw InvalidArgumentError(
        "--initial-velocity starts map tracking of events from its initial pose: not with "
        "--init-pose none, --mode frames, vo or devo, or --handover");
  }
  if (odometry && !search_flags.empty()) {
    throw InvalidArgumentError(search_flags.front() +
                               " sets the map search; --mode vo and devo search no map");
  }
  if (odometry == odometry::OdometryMode::kVo && !tracker_flags.empty()) {
    throw InvalidArgumentError(
        tracker_flags.front().first +
        " sets the event tracker; --mode vo tracks images and depth with its own settings "
        "(docs/tracking.md, \"Canny-VO\")");
  }
  if (odometry == odometry::OdometryMode::kDevo && tracking.tracker.binning != 1) {
    throw InvalidArgumentError(
        "--binning: --mode devo builds its reference frames on the sensor's pixels (use 1, not "
        "auto)");
  }
  if (odometry == odometry::OdometryMode::kDevo && tracking.tracker.events_per_step) {
    throw InvalidArgumentError("--events-per-step: --mode devo steps at a fixed rate (--rate)");
  }
  if (geo_path && odometry) {
    throw InvalidArgumentError("--geo needs a map with a geo anchor; --mode vo and devo have none");
  }
  if (gnss && !no_initial_pose) {
    throw InvalidArgumentError(
        "--gnss narrows the search of a run without a pose: give --init-pose none with it");
  }
  if (no_initial_pose && (tracking.tracker.input != TrackerInput::kEvents || odometry)) {
    throw InvalidArgumentError("--init-pose none needs --mode events (the search works on events)");
  }
  if (ecd_width <= 0 || ecd_height <= 0) {
    throw InvalidArgumentError("--ecd-size must be WIDTHxHEIGHT with positive sizes");
  }
  tiles.Check();
  handover_options.Check();
  if (map_memory_bytes == 0) throw InvalidArgumentError("--map-memory must be more than 0 bytes");
  tracking.Check();
}

std::string TrackCommandUsage() {
  return R"(Usage: evloc-track --map MAPDIR --dataset DIR --out TRAJ.txt [options]

Tracks a recorded sequence against a map, offline, with the tracker the localizer service runs
(docs/tracking.md), and writes world_from_cam at every step as a TUM trajectory.

Options:
  --map PATH             map directory (holding map.evmap), .evmap file, or site folder
                         (holding site.manifest, evloc-mapper tile; docs/map-format.md "Sites")
                         (required)
  --tile-radius M        with a site: the tiles within M metres of the camera (default: one
                         tile size), of where it will be (--tile-lookahead) and of the point
                         --tile-view-distance ahead on its optical axis are composed
  --tile-lookahead S     seconds ahead at the current velocity (default 2)
  --tile-view-distance M metres ahead on the optical axis (default 0: not used)
  --map-memory SIZE      with a site: budget of the loaded tiles, bytes with K/M/G suffix
                         (default 2G)
  --dataset DIR|FILE     dataset folder, evloc or Event Camera Dataset layout, a ROS1 bag
                         (.bag) or an AEDAT4 file (.aedat4)
                         (required)
  --out PATH             output TUM trajectory (required)
  --geo PATH             also write the trajectory in WGS84: time, latitude, longitude,
                         altitude, heading, pitch and the ENU position per pose (docs/geo.md);
                         the map needs a geo anchor (evloc-mapper georef)
  --gnss LAT,LON,ALT,SIGMA[,SIGMA_V]
                         with --init-pose none: a GNSS fix where the run starts (WGS84 degrees,
                         metres; one-sigma accuracy, horizontal and optionally vertical): the
                         search looks only within 3 sigma of it, on a site in the tiles near it,
                         until the first TRACKING step (docs/geo.md); needs a geo anchor
  --init-pose "tx ty tz qx qy qz qw" | none
                         initial world_from_cam; default: the dataset's first ground-truth pose
                         (at --start: the ground truth then; required when the dataset has no
                         ground truth); none: start without a pose, INITIALIZING, and search the
                         map until a hypothesis is verified (docs/relocalization.md, "Events")
  --start S              start S seconds after the dataset's first event (or frame) and ignore
                         everything before it (the first step is at that time)
  --initial-velocity truth | "vx vy vz wx wy wz"
                         start moving instead of at rest: the ground truth's velocity at the
                         start, or this body-frame twist of world_from_cam (m/s, rad/s, camera
                         frame), as a vehicle that knows its speed can (events, with a pose)
  --blackout T0:T1       drop the events from T0 to T1 seconds after the first event (a sensor
                         blackout, to measure the recovery)
  --relocalize-after N   LOST steps before a global search (RELOCALIZING; default 30, 0 never)
  --search-active-fraction F
                         while searching, the decay leaves this fraction of pixels active
                         (default 0.1)
  --search-grid R        hypotheses on a grid within R metres of each map viewpoint (default 0.2)
  --search-grid-step S   spacing of that grid, metres (default 0.2)
  --search-candidates N  hypotheses refined per search round (default 12)
  --search-margin A      alignment margin over the best distinct hypothesis (default 0.15)
  --give-up S            a search episode that found nothing in S seconds ends "not_found" and a
                         new one starts (default 0: never)
  --search-cpu-share F   the search may use F cores per second of event time (default 0:
                         unbounded and reproducible; the server's default is 0.5)
  --search-images on|off the search also locates images made from the events with the map's
                         local features (maps with relocalization data; default on;
                         docs/relocalization.md)
  --search-probe F       probe each round's winner from starts shifted by F of the median
                         depth it sees (default 0.03; 0: none; docs/relocalization.md)
  --search-probe-margin A
                         the winner must be aligned A better than its probes that end elsewhere
                         (default 0.05; fits elsewhere: the margin 0.15; docs/relocalization.md)
  --search-distinct-depth F
                         two refinements of a search round are one place unless farther apart
                         than F of the median depth they see (or 5 cm, or 3 degrees; default
                         0.02; 0: 5 cm at any depth; docs/relocalization.md)
  --search-verify-s-per-m S
                         a found pose is verified over at least S seconds per metre of the
                         median depth it sees, and the 10 steps (default 0.005: 0.15 s at 30 m;
                         0: the steps alone; docs/relocalization.md)
  --search-image-blur PX the Gaussian blur of that image before it is located, pixels
                         (default 0.7; 0: none)
  --mode events|frames|vo|devo
                         events (Canny-EVT, default), frames (Canny-VT on the images: a folder's
                         images.txt, a bag's --image-topic, an AEDAT4 file's frames stream), or the
                         mapless odometry without --map: vo (Canny-VO on images and depth) or
                         devo (Canny-DEVO on events and depth) (docs/tracking.md); the tracker's
                         flags below (--rate ... --max-mean-residual) reach DEVO's tracker too,
                         over its own defaults (no polarity, no occlusion culling)
  --handover             with a map and a dataset with depth: where the map is not seen, continue
                         by Canny-DEVO from the last good pose and come back to the map once it is
                         seen again and verified; --stats gives each step's source (map, odometry)
                         (docs/tracking.md, "Hand-over")
  --handover-leave-points N
                         hand over when a map step registers fewer than N map points (default
                         500, the points a return needs too)
  --rate HZ              tracking steps per second of event time (default 300)
  --events-per-step N    a step every N events instead of a fixed rate
  --variant NAME         EVT (default), EVT-PR, EVT-OH or EVT-- (docs/tracking.md, "Variants")
  --polarity on|off      polarity-aware registration (default on)
  --occlusion on|off     ANNF occlusion culling (default on)
  --max-points N         map points registered per step (default 2500)
  --binning B|auto       events: track on time surfaces of B x B sensor pixels (default 1; 2
                         makes a 1280x720 sensor track like a 640x360 one, in real time; auto:
                         the smallest B that fits the image in 640x480; docs/tracking.md,
                         "Binning")
  --informative-points N events: of the --max-points evenly selected, register only the N
                         that constrain the pose most (default 0: all of them;
                         docs/tracking.md, "Point selection")
  --informative-seed-fraction F  share of those N taken evenly, the rest by leverage (default 0.5)
  --tau SECONDS          time-surface decay time (default 0.03); with --decay-trail the longest
  --decay-trail PX       adaptive decay: tau = PX / the median image speed of the map points,
                         within [--min-tau, --tau] (default 1; 0: a fixed tau; docs/tracking.md)
  --min-tau SECONDS      the shortest adaptive decay time (default 0.005)
  --reselect-translation M
                         select the map points again when the predicted pose moved more than
                         M metres since the last selection (default 0.05; a vehicle: 0.5)
  --min-depth M          map points nearer than M metres are not selected (default 0.1)
  --max-depth M          map points farther than M metres are not selected (default 50)
  --decay-quantile Q     the adaptive decay divides the trail by this quantile of the points'
                         image speeds (default 0.5, the median; 0.9 for a vehicle's forward
                         camera, docs/tracking.md "Vehicle speed")
  --polarity-band DEG    neutral band around 90 degrees between gradient and flow (default 30)
  --min-flow PX          predicted flows per step shorter than this give no polarity (default 0.05)
  --two-stage on|off     with polarity: an unsigned solve first, then the signed one from its
                         result (default on; off = one signed solve, as the paper)
  --polarity-culling on|off
                         with polarity and occlusion: points claim edge pixels of their
                         predicted polarity (default on)
  --velocity-window S    constant-velocity window, seconds (default 0.02)
  --velocity-decay-time S
                         the step's prediction takes the velocity to decay with this time
                         constant, seconds (default 0: constant; an experiment,
                         docs/accuracy.md "DEVO on turning paths")
  --motion-prior V,W     the constant-velocity prediction as a prior in each tracking solve,
                         its velocity trusted to V m/s and W deg/s (default 0,0: none; a
                         vehicle: docs/tracking.md, "Motion prior")
)" + std::string(kEventFilterFlagsUsage) +
         R"(  --stamp-at-step-time on|off
                         move each pose forward by the age of the events it was registered to,
                         to its step time (default on, off in --mode devo; off: the
                         registered pose, which lags by 1.5-5.5 ms; docs/tracking.md,
                         "Pose time")
  --stamp-velocity-window S
                         the velocity window of that move, seconds (default 0.1)
  --min-alignment A      a step is bad below this chance-corrected alignment (docs/tracking.md)
  --max-mean-residual R  a step is bad above this mean field value at the points
  --stats PATH           per-step statistics (status: TRACKING, LOST, INITIALIZING or
                         RELOCALIZING; points, quality, timings) and the search episodes
                         ("relocalizations": start_t_s, end_t_s, outcome found / not_found /
                         ended) and what the noise filters removed ("event_filter", and per
                         step) as JSON; --mode devo adds its reference frames
                         ("reference_frames": t_s, points, build_ms, build_cpu_ms, ...)
  --debug-dir DIR        write debug pictures (time surface with the map, ON/OFF surfaces,
                         predicted gradient and flow)
  --debug-every N        one debug picture every N steps (default 30)
  --ecd-size WxH         sensor size for ECD folders with calib.txt only (default 240x180)
)" + std::string(kRecordingFlagsUsage) +
         R"(  --quiet                no progress output
  --help                 print this help

Exit codes: 0 success, 1 bad input or failure, 2 bad command line.
)";
}

namespace {

// Applies a flag of the map search (--relocalize-after, --give-up, --search-*) to `tracker`;
// false when `flag` is not one.
bool ApplySearchFlag(const std::string& flag, const std::string& value, TrackerOptions* tracker) {
  if (flag == "--relocalize-after") {
    tracker->lost_steps_before_relocalization = static_cast<int>(ParseIntegerFlag(flag, value));
  } else if (flag == "--give-up") {
    tracker->relocalization_give_up_s = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-cpu-share") {
    tracker->relocalization_cpu_share = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-probe") {
    tracker->relocalization_probe_depth_fraction = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-probe-margin") {
    tracker->relocalization_probe_margin = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-distinct-depth") {
    tracker->relocalization_distinct_depth_fraction = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-verify-s-per-m") {
    tracker->relocalization_verify_s_per_depth_m = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-image-blur") {
    tracker->relocalization_image_blur_px = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-active-fraction") {
    tracker->relocalization_active_fraction = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-grid") {
    tracker->relocalization_grid_radius_m = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-grid-step") {
    tracker->relocalization_grid_step_m = ParseDoubleFlag(flag, value);
  } else if (flag == "--search-candidates") {
    tracker->relocalization_candidates = static_cast<int>(ParseIntegerFlag(flag, value));
  } else if (flag == "--search-margin") {
    tracker->relocalization_min_alignment_margin = ParseDoubleFlag(flag, value);
  } else {
    return false;
  }
  return true;
}

// Applies a flag of the event tracker (--rate ... --max-mean-residual, the noise filters) to
// `tracker`; false when `flag` is not one. --mode devo applies the same flags to its own tracker.
bool ApplyTrackerFlag(const std::string& flag, const std::string& value, TrackerOptions* tracker) {
  if (flag == "--rate") {
    tracker->step_rate_hz = ParseDoubleFlag(flag, value);
  } else if (flag == "--events-per-step") {
    tracker->events_per_step = ParseIntegerFlag(flag, value);
  } else if (flag == "--variant") {
    tracker->SetVariant(value);
  } else if (flag == "--polarity") {
    tracker->use_polarity = ParseSwitchFlag(flag, value);
  } else if (flag == "--occlusion") {
    tracker->use_occlusion_culling = ParseSwitchFlag(flag, value);
  } else if (flag == "--max-points") {
    tracker->max_points = static_cast<int>(ParseIntegerFlag(flag, value));
  } else if (flag == "--binning") {
    ParseBinningFlag(flag, value, tracker);
  } else if (flag == "--informative-points") {
    tracker->informative_points = static_cast<int>(ParseIntegerFlag(flag, value));
  } else if (flag == "--informative-seed-fraction") {
    tracker->informative_seed_fraction = ParseDoubleFlag(flag, value);
  } else if (flag == "--tau") {
    tracker->decay_time_s = ParseDoubleFlag(flag, value);
  } else if (flag == "--decay-trail") {
    tracker->decay_trail_px = ParseDoubleFlag(flag, value);
  } else if (flag == "--min-tau") {
    tracker->min_decay_time_s = ParseDoubleFlag(flag, value);
  } else if (flag == "--decay-quantile") {
    tracker->decay_speed_quantile = ParseDoubleFlag(flag, value);
  } else if (flag == "--reselect-translation") {
    tracker->reselect_translation_m = ParseDoubleFlag(flag, value);
  } else if (flag == "--min-depth") {
    tracker->min_depth_m = ParseDoubleFlag(flag, value);
  } else if (flag == "--max-depth") {
    tracker->max_depth_m = ParseDoubleFlag(flag, value);
  } else if (flag == "--velocity-window") {
    tracker->velocity_window_s = ParseDoubleFlag(flag, value);
  } else if (flag == "--velocity-decay-time") {
    tracker->velocity_decay_time_s = ParseDoubleFlag(flag, value);
  } else if (flag == "--motion-prior") {
    ParseMotionPriorFlag(flag, value, tracker);
  } else if (flag == "--polarity-band") {
    tracker->polarity_neutral_band_deg = ParseDoubleFlag(flag, value);
  } else if (flag == "--min-flow") {
    tracker->min_flow_px = ParseDoubleFlag(flag, value);
  } else if (flag == "--stamp-at-step-time") {
    tracker->stamp_at_step_time = ParseSwitchFlag(flag, value);
  } else if (flag == "--stamp-velocity-window") {
    tracker->stamp_velocity_window_s = ParseDoubleFlag(flag, value);
  } else if (flag == "--two-stage") {
    tracker->polarity_after_unsigned_solve = ParseSwitchFlag(flag, value);
  } else if (flag == "--polarity-culling") {
    tracker->polarity_aware_culling = ParseSwitchFlag(flag, value);
  } else if (ApplyEventFilterFlag(flag, value, &tracker->event_filter)) {
  } else if (flag == "--min-alignment") {
    tracker->min_alignment = ParseDoubleFlag(flag, value);
  } else if (flag == "--max-mean-residual") {
    tracker->max_mean_residual = ParseDoubleFlag(flag, value);
  } else {
    return false;
  }
  return true;
}

}  // namespace

TrackCommandOptions ParseTrackCommandLine(const std::vector<std::string>& arguments) {
  TrackCommandOptions options;
  TrackerOptions& tracker = options.tracking.tracker;
  for (size_t i = 0; i < arguments.size(); ++i) {
    const std::string& flag = arguments[i];
    if (flag == "--help" || flag == "-h") {
      options.help = true;
      continue;
    }
    if (flag == "--quiet") {
      options.quiet = true;
      continue;
    }
    if (flag == "--handover") {
      options.handover = true;
      continue;
    }
    const std::string& value = TakeFlagValue(arguments, &i);
    if (flag == "--map") {
      options.map_path = value;
    } else if (flag == "--handover-leave-points") {
      options.handover_options.leave_map_points = ParseIntFlag(flag, value);
    } else if (flag == "--tile-radius") {
      options.tiles.radius_m = ParseDoubleFlag(flag, value);
    } else if (flag == "--tile-lookahead") {
      options.tiles.lookahead_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--tile-view-distance") {
      options.tiles.view_distance_m = ParseDoubleFlag(flag, value);
    } else if (flag == "--map-memory") {
      options.map_memory_bytes = ParseByteSizeFlag(flag, value);
    } else if (flag == "--dataset") {
      options.dataset_path = value;
    } else if (flag == "--out") {
      options.output_path = value;
    } else if (flag == "--init-pose") {
      if (value == "none") {
        options.no_initial_pose = true;
        options.initial_world_from_cam.reset();
      } else {
        options.no_initial_pose = false;
        options.initial_world_from_cam = ParsePoseText(flag, value);
      }
    } else if (flag == "--initial-velocity") {
      options.initial_velocity.reset();
      options.initial_velocity_from_truth = value == "truth";
      if (!options.initial_velocity_from_truth) {
        options.initial_velocity = ParseTwistText("--initial-velocity (truth or a twist)", value);
      }
    } else if (flag == "--blackout") {
      const size_t colon = value.find(':');
      if (colon == std::string::npos) {
        throw InvalidArgumentError("--blackout expects T0:T1 (seconds after the first event)");
      }
      options.blackout_begin_s = ParseDoubleFlag(flag, value.substr(0, colon));
      options.blackout_end_s = ParseDoubleFlag(flag, value.substr(colon + 1));
    } else if (flag == "--start") {
      options.start_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--search-images") {
      options.search_images = ParseSwitchFlag(flag, value);
      options.search_flags.push_back(flag);
    } else if (ApplySearchFlag(flag, value, &tracker)) {
      options.search_flags.push_back(flag);
    } else if (flag == "--mode") {
      if (value == "events") {
        tracker.input = TrackerInput::kEvents;
      } else if (value == "frames") {
        tracker.input = TrackerInput::kFrames;
      } else if (value == "vo" || value == "devo") {
        options.odometry =
            value == "vo" ? odometry::OdometryMode::kVo : odometry::OdometryMode::kDevo;
        tracker.input = value == "vo" ? TrackerInput::kFrames : TrackerInput::kEvents;
      } else {
        throw InvalidArgumentError("--mode expects events, frames, vo or devo, got '" + value +
                                   "'");
      }
    } else if (ApplyTrackerFlag(flag, value, &tracker)) {
      options.tracker_flags.emplace_back(flag, value);
    } else if (flag == "--stats") {
      options.stats_path = value;
    } else if (flag == "--geo") {
      options.geo_path = value;
    } else if (flag == "--gnss") {
      options.gnss = ParseGnssPrior(flag, value);
    } else if (flag == "--debug-dir") {
      options.debug_dir = value;
    } else if (flag == "--debug-every") {
      options.debug_every_steps = static_cast<int>(ParseIntegerFlag(flag, value));
    } else if (flag == "--ecd-size") {
      ParseSizeFlag(flag, value, &options.ecd_width, &options.ecd_height);
    } else if (ApplyRecordingFlag(flag, value, &options.bag_topics, &options.aedat4)) {
    } else {
      throw InvalidArgumentError("unknown flag '" + flag + "' (see --help)");
    }
  }
  options.Check();
  return options;
}

OfflineTrackingResult RunTrackCommand(const TrackCommandOptions& options, std::ostream& log) {
  options.Check();
  DatasetReaderOptions reader_options;
  reader_options.ecd_width = options.ecd_width;
  reader_options.ecd_height = options.ecd_height;
  reader_options.bag_topics = options.bag_topics;
  reader_options.aedat4 = options.aedat4;
  const Dataset dataset = ReadDataset(options.dataset_path, reader_options);
  for (const std::string& note : dataset.calibration_notes) {
    log << "evloc-track: note: " << note << "\n";
  }
  const bool events_mode = options.tracking.tracker.input == TrackerInput::kEvents;

  // The initial pose, at the ground truth's start or else at the first measurement.
  int64_t first_t_ns = 0;
  if (events_mode && dataset.events_path) {
    EventBuffer first;
    if (OpenDatasetEvents(dataset)->Read(1, &first) == 1) first_t_ns = first.t_ns[0];
  } else if (!events_mode && !dataset.images.empty()) {
    first_t_ns = dataset.images.front().t_ns;
  }
  std::optional<Rigid3d> initial_world_from_cam;
  int64_t initial_t_ns = first_t_ns;
  OfflineTrackingOptions tracking = options.tracking;
  // The statistics report each step's surface age (a diagnostic the tracker skips otherwise).
  if (options.stats_path) tracking.tracker.measure_surface_age = true;
  tracking.initial_velocity = options.initial_velocity;
  if (options.blackout_begin_s) {
    tracking.blackout_begin_ns = first_t_ns + std::llround(*options.blackout_begin_s * 1e9);
    tracking.blackout_end_ns = first_t_ns + std::llround(*options.blackout_end_s * 1e9);
  }
  if (options.start_s) {
    initial_t_ns = first_t_ns + std::llround(*options.start_s * 1e9);
    tracking.discard_events_before_start = true;
    if (options.initial_world_from_cam) {
      initial_world_from_cam = options.initial_world_from_cam;
    } else if (!options.no_initial_pose) {
      if (!dataset.ground_truth || !dataset.ground_truth->Lookup(initial_t_ns)) {
        throw InvalidArgumentError(
            "--start: the dataset has no ground truth at that time; give "
            "--init-pose (a pose, or none)");
      }
      initial_world_from_cam = *dataset.ground_truth->Lookup(initial_t_ns);
    }
  } else if (!options.no_initial_pose) {
    const TimedPose initial =
        ResolveInitialPose(dataset, options.initial_world_from_cam, first_t_ns);
    initial_world_from_cam = initial.world_from_cam;
    initial_t_ns = initial.t_ns;
  }
  if (options.initial_velocity_from_truth) {
    // Over the tracker's velocity window, as its constant-velocity model measures it.
    const std::optional<Vector6d> velocity =
        dataset.ground_truth
            ? dataset.ground_truth->Velocity(
                  initial_t_ns, std::llround(options.tracking.tracker.velocity_window_s * 1e9))
            : std::nullopt;
    if (!velocity) {
      throw InvalidArgumentError(
          "--initial-velocity truth: the dataset has no ground truth around the start time; "
          "give the velocity as six numbers");
    }
    tracking.initial_velocity = velocity;
  }

  if (options.odometry) {
    // DEVO's tracker: its own defaults with the tracker flags given.
    odometry::DevoRunOptions devo;
    for (const auto& [flag, value] : options.tracker_flags) {
      ApplyTrackerFlag(flag, value, &devo.devo.tracker);
    }
    devo.devo.tracker.measure_surface_age = tracking.tracker.measure_surface_age;
    const OfflineTrackingResult result =
        RunOdometryTrack(dataset, *options.odometry, devo, options.initial_world_from_cam,
                         initial_t_ns, options.quiet, log);
    WriteTrackOutputs(options, odometry::OdometryModeName(*options.odometry),
                      odometry::OdometryModeName(*options.odometry), result, log);
    return result;
  }
  if (IsSiteDirectory(options.map_path)) {
    if (options.handover) throw InvalidArgumentError("--handover needs a whole map, not a site");
    return RunSiteTrack(options, dataset, tracking, initial_world_from_cam, initial_t_ns,
                        events_mode, log);
  }
  const Map map = LoadMap(ResolveMapFile(options.map_path));
  if ((options.geo_path || options.gnss) && !map.geo_anchor) {
    throw InvalidArgumentError(MissingGeoAnchorMessage(options.map_path.string()));
  }
  if (options.gnss) SetGnssPrior(*options.gnss, *map.geo_anchor, &tracking);
  const VisibilityIndex visibility(map);
  if (!options.quiet) {
    log << "evloc-track: map " << options.map_path.string() << " (" << map.size() << " points, "
        << map.keyframes.size() << " keyframes), dataset " << options.dataset_path.string()
        << ", variant " << options.tracking.tracker.VariantName() << ", "
        << (events_mode ? "events" : "frames") << " at " << options.tracking.tracker.step_rate_hz
        << " Hz\n";
  }
  if (options.debug_dir) std::filesystem::create_directories(*options.debug_dir);

  int64_t step_index = 0;
  Rigid3d previous_world_from_cam = initial_world_from_cam.value_or(Rigid3d());
  const int64_t end_ns = dataset.ground_truth ? dataset.ground_truth->end_ns() : 0;
  const StepCallback on_step = [&](const PoseEstimate& step, const Tracker& tracker) {
    if (options.debug_dir && step_index % options.debug_every_steps == 0) {
      char name[64];
      std::snprintf(name, sizeof(name), "step_%06lld.png", static_cast<long long>(step_index));
      const cv::Mat picture =
          RenderTrackingDebugImage(tracker, map, &visibility, step, previous_world_from_cam);
      std::vector<uchar> png;
      cv::imencode(".png", picture, png);
      WriteFileAtomically(*options.debug_dir / name,
                          std::string_view(reinterpret_cast<const char*>(png.data()), png.size()));
    }
    if (!options.quiet && step_index % 300 == 0) {
      log << "  t=" << static_cast<double>(step.t_ns - initial_t_ns) * 1e-9 << " s";
      if (end_ns > initial_t_ns) {
        log << " of " << static_cast<double>(end_ns - initial_t_ns) * 1e-9 << " s";
      }
      log << "  " << TrackingStatusName(step.status) << "  points " << step.quality.points_used
          << "  on-edge " << step.quality.on_edge_fraction << "\n";
    }
    previous_world_from_cam = step.world_from_cam;
    ++step_index;
  };

  OfflineTrackingResult result;
  if (options.handover) {
    const HandoverTrackResult run =
        TrackWithHandover(dataset, map, &visibility, *initial_world_from_cam, initial_t_ns,
                          tracking, options.handover_options, on_step);
    result = run.result;
    if (!options.quiet) {
      log << "evloc-track: hand-over: " << run.counts.to_odometry << " to odometry, "
          << run.counts.to_map << " back to the map (verified), " << run.counts.odometry_poses
          << " poses from odometry, " << run.counts.map_probes << " map probes ("
          << run.counts.ambiguous_returns << " refused as ambiguous), " << run.counts.map_searches
          << " map searches, " << run.counts.odometry_start_failures << " failed odometry starts, "
          << run.counts.depth_frames << " depth frames\n";
    }
  } else if (events_mode) {
    if (!dataset.events_path) {
      throw InvalidArgumentError("dataset '" + options.dataset_path.string() +
                                 "' has no events.evb or events.txt (use --mode frames for "
                                 "images)");
    }
    const auto reader = OpenDatasetEvents(dataset);
    std::optional<evloc::relocalization::EventImageHypotheses> image_hypotheses;
    if (options.search_images && map.relocalization) {
      image_hypotheses.emplace(map, visibility, dataset.camera);
      tracking.image_hypotheses = &*image_hypotheses;
    }
    result = TrackEventStream(*reader, map, &visibility, dataset.camera, initial_world_from_cam,
                              initial_t_ns, tracking, on_step);
  } else {
    if (!DatasetHasImages(dataset)) {
      throw InvalidArgumentError(
          "dataset '" + options.dataset_path.string() + "' has no images (" +
          (dataset.bag
               ? "no messages on the image topic '" + dataset.bag->topics.image +
                     "'; --image-topic names another; the bag's topics: " + dataset.bag->topic_list
           : dataset.aedat4 ? "no frames stream '" + dataset.aedat4->options.frames +
                                  "'; --image-topic names another; the file's streams: " +
                                  dataset.aedat4->stream_list
                            : std::string("no images.txt")) +
          "): frames mode needs images");
    }
    result = TrackFrames([&dataset](const ImageSink& add) { ForEachDatasetImage(dataset, add); },
                         options.dataset_path.string(), map, &visibility, dataset.camera,
                         *initial_world_from_cam, initial_t_ns, tracking, on_step);
  }
  WriteTrackOutputs(options, options.tracking.tracker.VariantName(),
                    events_mode ? "events" : "frames", result, log, map.geo_anchor);
  return result;
}

}  // namespace evloc::tracking
