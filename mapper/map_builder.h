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
#include "mapper/build_inputs.h"
#include "mapper/build_report.h"
#include "mapper/colmap_runner.h"
#include "mapper/georeference.h"
#include "mapper/keyframe_selection.h"
#include "mapper/map_merge.h"
#include "mapper/pose_alignment.h"
#include "mapper/relocalization_data.h"
#include "mapper/semidense_depth.h"

namespace evloc::mapper {

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
  // Compute the relocalization data (format v2) of the map (false: --no-relocalization).
  bool relocalization = true;
  // How the relocalization data is computed.
  RelocalizationDataOptions relocalization_data;
  // Fail when fewer than this fraction of the images are registered by COLMAP.
  double min_registered_fraction = 0.5;
  // Keyframes drawn in preview.png.
  int preview_keyframes = 4;
  // Command line recorded in the map's provenance.
  std::string command_line;
  // The map's geo anchor: none, or one source (docs/geo.md).
  GeoReferenceOptions geo;

  // Throws InvalidArgumentError on a bad or inconsistent value.
  void Check() const;
};

// Runs the pipeline and writes the map directory. Throws InvalidArgumentError for bad options or
// inputs (missing or empty image folder, unreadable or mixed-size images, poses that do not match
// the images, too few registered images, an output directory that holds a map or other files),
// IoError when COLMAP is missing or fails or a file cannot be read or written. On any error the
// output directory is left as it was.
MapBuildReport BuildMap(const MapBuilderOptions& options, ProgressListener* progress = nullptr);

}  // namespace evloc::mapper
