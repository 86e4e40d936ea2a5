// The stages of BuildMap (docs/mapper.md, "Stages and algorithms"), each a function from typed
// inputs to a typed result: inputs -> sparse reconstruction (COLMAP, cached in its workspace) ->
// alignment -> registered views -> keyframes and semi-dense depth -> edge lifting -> merge ->
// relocalization data -> outputs. Stages that report figures or timings take the build's report and
// clock.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "mapper/build_inputs.h"
#include "mapper/build_report.h"
#include "mapper/colmap_model.h"
#include "mapper/keyframe_selection.h"
#include "mapper/map_builder.h"
#include "mapper/map_merge.h"
#include "mapper/semidense_depth.h"
#include "maps/map.h"

namespace evloc::mapper {

// Stage 1: the checked inputs.
struct BuildInputs {
  // The map directory to create (absolute; absent or empty).
  std::filesystem::path output_dir;
  // The images to map, in input order (with known poses: those that have one).
  std::vector<InputImage> images;
  // Images listed, before any was left out.
  size_t num_images = 0;
  // Images left out because a time-keyed --known-poses trajectory does not cover their times.
  std::vector<std::string> images_without_pose;
  // The fixed intrinsics (--camera or --calib); std::nullopt: COLMAP estimates them.
  std::optional<Camera> camera;
  // What the --calib reader read but did not use, one sentence each, prefixed with the file.
  std::vector<std::string> calibration_notes;
  // Known world_from_cam per image name (--known-poses).
  std::map<std::string, Rigid3d> known_world_from_cams;
  // Reference world_from_cam per image name (--align-to).
  std::map<std::string, Rigid3d> reference_world_from_cams;
};

// Checks the output directory (and creates its parent), lists and reads the images (one size),
// the camera and the pose files. Throws InvalidArgumentError / ParseError / IoError.
BuildInputs LoadInputs(const MapBuilderOptions& options);

// Stage 2: COLMAP's model of the images, in COLMAP's frame (known poses: the given frame).
struct SparseReconstruction {
  // The model (cameras, registered images, points).
  ColmapModel model;
  // Its TXT copy in the workspace (copied into the map directory's colmap/).
  std::filesystem::path text_model;
  // The COLMAP logs.
  std::filesystem::path log_dir;
};

// Runs (or reuses, per stage, by fingerprint) feature extraction, matching and the model stage
// (triangulation of the known poses, or mapping and refinement) in the workspace. Fills the
// report's COLMAP fields. Throws InvalidArgumentError when too few images are registered, IoError
// when COLMAP fails.
SparseReconstruction ReconstructSparse(const MapBuilderOptions& options, const BuildInputs& inputs,
                                       const StageClock& clock, MapBuildReport* report);

// Fits the Sim(3) from `model` to `reference` world_from_cam poses (AlignPoses), records it in
// the report (alignment figures, world_from_model) and checks it against options'
// alignment_limits: beyond them it throws InvalidArgumentError (with `likely_cause` in the
// message) unless options.accept_bad_alignment, which records the warning instead. For stage 3
// and the chunked build's merged model.
Sim3d FitAlignmentToReference(const MapBuilderOptions& options, const std::vector<Rigid3d>& model,
                              const std::vector<Rigid3d>& reference,
                              const std::string& likely_cause, MapBuildReport* report);

// Stage 3: with --align-to, fits the Sim(3) from the model to the reference poses, checks it
// against the limits and applies it to the model's poses and points (report: the alignment
// figures). Throws InvalidArgumentError when the alignment is refused.
void AlignToReference(const MapBuilderOptions& options, const BuildInputs& inputs,
                      const StageClock& clock, SparseReconstruction* sparse,
                      MapBuildReport* report);

// Stage 4: the registered views in input order with their cameras.
struct RegisteredViews {
  // Registered images in input order.
  std::vector<RegisteredView> views;
  // The map's cameras (the fixed camera, or COLMAP's converted).
  std::vector<Camera> cameras;
  // Per view: its index into `cameras`.
  std::vector<uint32_t> camera_indices;
  // Sparse points by COLMAP id.
  std::unordered_map<uint64_t, Eigen::Vector3d> sparse_points;
};

// The registered views of `model` in the order of `images` (report: world_from_cams).
RegisteredViews CollectViews(const std::vector<InputImage>& images, const ColmapModel& model,
                             const std::optional<Camera>& camera, MapBuildReport* report);

// Stage 5: keyframes and their semi-dense depth.
struct KeyframeDepths {
  // Keyframes (indices into the views) and their stereo neighbours.
  KeyframeSelection selection;
  // Per keyframe: its consistent semi-dense depth.
  std::vector<KeyframeDepth> depths;
};

// Selects keyframes, estimates each one's semi-dense depth against its neighbours and keeps the
// points confirmed across keyframes. Images are read from options.image_dir.
KeyframeDepths EstimateKeyframeDepths(const MapBuilderOptions& options,
                                      const RegisteredViews& views, const StageClock& clock);

// Stage 6: the keyframes of the map and their points lifted into the world.
struct LiftedKeyframes {
  // The map's keyframes (no visible points yet).
  std::vector<Keyframe> keyframes;
  // Every keyframe's 3D edge points with gradients, before merging.
  std::vector<CandidatePoint> points;
  // How many of them have a surface gradient (SurfaceGradients3d).
  size_t num_surface_gradients = 0;
};

// Lifts each keyframe's depth pixels into world points with 3D gradients (maps/edge_lifting.h).
LiftedKeyframes LiftKeyframes(const MapBuilderOptions& options, const RegisteredViews& views,
                              const KeyframeDepths& depths, const StageClock& clock);

// Stage 7: merges the lifted points into the map (cameras, keyframes with visibility, points)
// and sets its provenance (report: voxel size and point counts). Throws InvalidArgumentError when
// no point survives.
Map MergeKeyframePoints(const MapBuilderOptions& options, const RegisteredViews& views,
                        LiftedKeyframes lifted, const SparseReconstruction& sparse,
                        const StageClock& clock, MapBuildReport* report);

// Stage 8: unless options.relocalization is false, computes the map's relocalization data from
// the keyframe images in options.image_dir (ComputeRelocalizationData; report: its figures). When
// too few features see a landmark the map is written without it and the report says why.
void AddRelocalizationData(const MapBuilderOptions& options, const StageClock& clock, Map* map,
                           MapBuildReport* report);

// Stage 9: writes the map directory (map.evmap, map.ply, preview.png, colmap/, report.json) into
// a staging sibling of inputs.output_dir and renames it into place.
void WriteOutputs(const MapBuilderOptions& options, const BuildInputs& inputs, const Map& map,
                  const SparseReconstruction& sparse, const StageClock& clock,
                  MapBuildReport* report);

}  // namespace evloc::mapper
