// What `evloc-mapper build` reports (docs/mapper.md, report.json): progress of the stages while
// they run, their wall and CPU times, and the build's figures.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/geo/geo_alignment.h"
#include "core/geometry/rigid3.h"
#include "mapper/relocalization_data.h"

namespace evloc::mapper {

// Progress of one pipeline stage.
struct ProgressUpdate {
  // Stage name, e.g. "colmap_features" or "semidense_depth".
  std::string stage;
  // Work items done in this stage.
  size_t done = 0;
  // Work items of this stage (1 for stages that are a single step).
  size_t total = 1;
  // Seconds since the build started.
  double elapsed_seconds = 0.0;
};

// Receives progress from BuildMap; the CLI renders it.
class ProgressListener {
 public:
  virtual ~ProgressListener() = default;
  // Called at the start of each stage (done = 0) and after each work item.
  virtual void OnProgress(const ProgressUpdate& update) = 0;
};

// Wall and CPU time of one stage.
struct StageTiming {
  // Stage name.
  std::string stage;
  // Wall seconds.
  double seconds = 0.0;
  // CPU seconds (user + system) of the mapper's threads and of the child processes (COLMAP) that
  // ended during the stage: unlike wall time, not inflated by other programs' load.
  double cpu_seconds = 0.0;
  // True when the stage's result was reused from the COLMAP workspace.
  bool reused = false;
  // Peak resident memory at the end of the stage, bytes: the larger of this process's peak and
  // the largest peak of its waited-for children (COLMAP, chunk workers), since the process began
  // (getrusage ru_maxrss). The stage that raised it is the first whose value reaches it.
  uint64_t peak_rss_bytes = 0;
};

// PeakResidentBytes of StageTiming: max(ru_maxrss of this process, of its waited-for children),
// bytes.
uint64_t PeakResidentBytes();

// What BuildMap did, written to report.json.
struct MapBuildReport {
  // Input images.
  size_t num_images = 0;
  // Images with a pose (registered by COLMAP, or given).
  size_t num_registered = 0;
  // Images left out because a time-keyed --known-poses trajectory does not cover their times.
  std::vector<std::string> images_without_pose;
  // What the --calib reader read but did not use (e.g. a Kalibr camchain's imu fields).
  std::vector<std::string> calibration_notes;
  // Keyframes of the map.
  size_t num_keyframes = 0;
  // Sparse COLMAP points.
  size_t num_sparse_points = 0;
  // Semi-dense points before merging.
  size_t num_keyframe_points = 0;
  // Semi-dense points whose 3D gradient lies in a fitted surface plane (SurfaceGradients3d);
  // the others keep the ray–plane gradient of their keyframe.
  size_t num_surface_gradients = 0;
  // Map points.
  size_t num_points = 0;
  // Voxel edge used for merging, metres (model units when not aligned).
  double voxel_size = 0.0;
  // Mean reprojection error of the COLMAP points, pixels.
  double colmap_mean_reprojection_error_px = 0.0;
  // "estimated" or "known".
  std::string pose_source;
  // The matcher COLMAP used.
  std::string matcher;
  // COLMAP version line.
  std::string colmap_version;
  // Images used for the alignment (0 without --align-to).
  size_t alignment_num_images = 0;
  // RMS of the aligned camera-centre residuals, metres.
  std::optional<double> alignment_rms_m;
  // Largest aligned camera-centre residual, metres.
  std::optional<double> alignment_max_m;
  // RMS of the aligned camera-orientation residuals, degrees.
  std::optional<double> alignment_rotation_rms_deg;
  // Largest aligned camera-orientation residual, degrees.
  std::optional<double> alignment_rotation_max_deg;
  // Scale of the alignment.
  std::optional<double> alignment_scale;
  // RMS distance of the reference camera centres from their mean, metres.
  std::optional<double> alignment_reference_spread_m;
  // The AlignmentLimitViolation text when the alignment exceeded the limits and the map was
  // built anyway (accept_bad_alignment); empty otherwise.
  std::string alignment_warning;
  // The model-to-world similarity applied (identity without --align-to).
  Sim3d world_from_model;
  // Figures of the relocalization data; nullopt when it was not computed.
  std::optional<RelocalizationDataStatistics> relocalization;
  // Why the map has no relocalization data although it was asked for; empty otherwise.
  std::string relocalization_warning;
  // The map's geo anchor (--geo-anchor, --geo-points, --geo-exif); nullopt without one.
  std::optional<GeoAnchor> geo_anchor;
  // The alignment behind it (--geo-points, --geo-exif).
  std::optional<GeoAlignment> geo_alignment;
  // What the anchor was computed from ("12 of 12 keyframe images with GNSS tags").
  std::string geo_inputs;
  // Per-stage timings, in pipeline order.
  std::vector<StageTiming> timings;
  // Registered image poses in the output frame (world_from_cam), by image name.
  std::map<std::string, Rigid3d> world_from_cams;

  // Sum of the wall timings of stages whose name starts with `prefix`, seconds.
  double TotalSeconds(const std::string& prefix) const;
  // Sum of the CPU timings of stages whose name starts with `prefix`, seconds.
  double TotalCpuSeconds(const std::string& prefix) const;
};

// The report as the JSON text of report.json.
std::string MapBuildReportToJson(const MapBuildReport& report);

// Times the stages of a build into a report and tells a listener about their progress.
class StageClock {
 public:
  // `listener` may be null; `report` receives one StageTiming per Run and must outlive the clock.
  StageClock(ProgressListener* listener, MapBuildReport* report);

  // Seconds since the clock was made.
  double Elapsed() const;
  // Tells the listener that `done` of `total` items of `stage` are done.
  void Progress(const std::string& stage, size_t done, size_t total) const;
  // Runs and times `body`, which returns true when it reused a cached result.
  void Run(const std::string& stage, const std::function<bool()>& body) const;

 private:
  ProgressListener* listener_;
  MapBuildReport* report_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace evloc::mapper
