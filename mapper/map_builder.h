// The offline mapper pipeline of `evloc-mapper build` (docs/mapper.md): images -> COLMAP poses
// (estimated, or known and triangulated) -> optional Sim(3) alignment to reference positions ->
// keyframes -> semi-dense edge depth -> merged map with 3D gradients and visibility -> a map
// directory (map.evmap, map.ply, preview.png, report.json, colmap/), assembled in a temporary
// sibling and renamed at the end so that a failure never leaves a half-written map.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "mapper/colmap_runner.h"
#include "mapper/keyframe_selection.h"
#include "mapper/map_merge.h"
#include "mapper/pose_alignment.h"
#include "mapper/semidense_depth.h"

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

// Options of the whole pipeline.
struct MapBuilderOptions {
  // Folder of the input images.
  std::filesystem::path image_dir;
  // The map directory to create; it must not exist or be empty.
  std::filesystem::path output_dir;
  // Optional image list, one `t_s path` line per image (ECD images.txt); paths relative to
  // image_dir or to the list's folder. Without it, every image file of image_dir, by name.
  std::optional<std::filesystem::path> image_list;
  // Fixed intrinsics; std::nullopt with no calibration_file: COLMAP estimates them.
  std::optional<Camera> camera;
  // Calibration file giving the fixed intrinsics: evloc YAML (.yaml, .yml) or ECD calib.txt
  // (size taken from the images). Exclusive with `camera`.
  std::optional<std::filesystem::path> calibration_file;
  // Known world_from_cam poses per image: TUM lines `t tx ty tz qx qy qz qw` (interpolated at
  // the image-list times) or `IMAGE_NAME tx ty tz qx qy qz qw`. Poses are kept; COLMAP only
  // triangulates. Needs fixed intrinsics.
  std::optional<std::filesystem::path> known_poses;
  // Reference world_from_cam poses (same layouts) the model is aligned to by a Sim(3) fit of the
  // camera centres and orientations (AlignPoses), giving metric scale and the user's frame.
  std::optional<std::filesystem::path> align_to;
  // With align_to: residuals beyond these mean a wrong model (or reference); the build is
  // refused (InvalidArgumentError, nothing written) unless accept_bad_alignment.
  AlignmentLimits alignment_limits;
  // Build the map anyway when the alignment exceeds alignment_limits; the report then carries
  // alignment_warning.
  bool accept_bad_alignment = false;
  // COLMAP workspace, kept between runs and reused when the inputs match; std::nullopt:
  // `<output_dir>.colmap-workspace` beside the output.
  std::optional<std::filesystem::path> colmap_workspace;
  // COLMAP runs (the camera field is filled from camera / calibration_file).
  ColmapOptions colmap;
  // Keyframe selection.
  KeyframeSelectionOptions keyframes;
  // Semi-dense depth.
  SemiDenseOptions semidense;
  // Merging.
  MapMergeOptions merge;
  // Fail when fewer than this fraction of the images are registered by COLMAP.
  double min_registered_fraction = 0.5;
  // Keyframes drawn in preview.png.
  int preview_keyframes = 4;
  // Command line recorded in the map's provenance.
  std::string command_line;

  // Throws InvalidArgumentError on a bad or inconsistent value.
  void Check() const;
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
};

// What BuildMap did, written to report.json.
struct MapBuildReport {
  // Input images.
  size_t num_images = 0;
  // Images with a pose (registered by COLMAP, or given).
  size_t num_registered = 0;
  // Images left out because a time-keyed --known-poses trajectory does not cover their times.
  std::vector<std::string> images_without_pose;
  // Keyframes of the map.
  size_t num_keyframes = 0;
  // Sparse COLMAP points.
  size_t num_sparse_points = 0;
  // Semi-dense points before merging.
  size_t num_keyframe_points = 0;
  // Semi-dense points whose 3D gradient lies in a fitted surface plane (SurfaceGradients3d);
  // the others keep the §3.4 gradient of their keyframe.
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
  // Per-stage timings, in pipeline order.
  std::vector<StageTiming> timings;
  // Registered image poses in the output frame (world_from_cam), by image name.
  std::map<std::string, Rigid3d> world_from_cams;

  // Sum of the wall timings of stages whose name starts with `prefix`, seconds.
  double TotalSeconds(const std::string& prefix) const;
  // Sum of the CPU timings of stages whose name starts with `prefix`, seconds.
  double TotalCpuSeconds(const std::string& prefix) const;
};

// Runs the pipeline and writes the map directory. Throws InvalidArgumentError for bad options or
// inputs (missing or empty image folder, unreadable or mixed-size images, poses that do not match
// the images, too few registered images, an output directory that holds a map or other files),
// IoError when COLMAP is missing or fails or a file cannot be read or written. On any error the
// output directory is left as it was.
MapBuildReport BuildMap(const MapBuilderOptions& options, ProgressListener* progress = nullptr);

// The report as the JSON text of report.json.
std::string MapBuildReportToJson(const MapBuildReport& report);

// One input image.
struct InputImage {
  // Name relative to the image folder (COLMAP's image name).
  std::string name;
  // Capture time, nanoseconds (0 without an image list).
  int64_t t_ns = 0;
  // Whether t_ns came from an image list.
  bool has_time = false;
};

// The input images: from the list (`t_s path` lines, read by core/dataset's ReadTimedFileList;
// a path relative to the folder or to the list's folder) or all image files of the folder, sorted
// by name. Throws InvalidArgumentError when the folder is missing or holds no images, or a listed
// file is outside the folder; IoError when a listed file is missing; ParseError naming the line
// for a malformed list or a time that does not increase.
std::vector<InputImage> ListInputImages(const std::filesystem::path& image_dir,
                                        const std::optional<std::filesystem::path>& image_list);

// world_from_cam poses for the images from a pose file (TUM lines interpolated at the image
// times, or `IMAGE_NAME tx ty tz qx qy qz qw` lines); images without a pose are absent from the
// result. Throws IoError / ParseError for unreadable or malformed files, InvalidArgumentError for
// TUM files when the images have no times.
std::map<std::string, Rigid3d> ReadPosesForImages(const std::filesystem::path& path,
                                                  const std::vector<InputImage>& images);

// True when the pose file's first data line starts with a time (TUM layout `t tx ty tz qx qy qz
// qw`) rather than an image name. Throws IoError when it cannot be read.
bool IsTimeKeyedPoseFile(const std::filesystem::path& path);

// The images that have a pose in `poses`, in input order. Images without one are an error
// (InvalidArgumentError naming them and `source`), except when the poses come from a time-keyed
// trajectory (`time_keyed`) that starts after or ends before some images: those are left out and
// named in `*left_out` (may be null), provided at least `min_fraction` of the images (and at
// least one) keep a pose.
std::vector<InputImage> ImagesWithKnownPoses(const std::vector<InputImage>& images,
                                             const std::map<std::string, Rigid3d>& poses,
                                             bool time_keyed, double min_fraction,
                                             const std::string& source,
                                             std::vector<std::string>* left_out);

}  // namespace evloc::mapper
