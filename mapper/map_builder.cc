#include "mapper/map_builder.h"

#include "core/common/error.h"
#include "mapper/build_stages.h"

namespace evloc::mapper {

void MapBuilderOptions::Check() const {
  if (image_dir.empty()) throw InvalidArgumentError("the image folder (--images) is required");
  if (output_dir.empty()) throw InvalidArgumentError("the output map folder (--out) is required");
  if (camera && calibration_file) {
    throw InvalidArgumentError("give the camera either as --camera or as --calib, not both");
  }
  if (camera) camera->Check();
  if (known_poses && !camera && !calibration_file) {
    throw InvalidArgumentError(
        "known poses need fixed intrinsics: pass --camera MODEL:params or --calib FILE");
  }
  if (!(min_registered_fraction >= 0.0 && min_registered_fraction <= 1.0)) {
    throw InvalidArgumentError("min_registered_fraction must be in [0, 1]");
  }
  if (preview_keyframes < 1) throw InvalidArgumentError("preview_keyframes must be at least 1");
  colmap.Check();
  keyframes.Check();
  semidense.Check();
  merge.Check();
  relocalization_data.Check();
  alignment_limits.Check();
  geo.Check();
}

MapBuildReport BuildMap(const MapBuilderOptions& options, ProgressListener* progress) {
  options.Check();
  MapBuildReport report;
  const StageClock clock(progress, &report);
  // 1. Inputs, output directory first: never start hours of work for a directory that cannot
  // take the map.
  const BuildInputs inputs = LoadInputs(options);
  report.num_images = inputs.num_images;
  report.images_without_pose = inputs.images_without_pose;
  report.calibration_notes = inputs.calibration_notes;
  // 2. COLMAP: features, matches, model (each reused from the workspace when its inputs match).
  SparseReconstruction sparse = ReconstructSparse(options, inputs, clock, &report);
  // 3. Sim(3) onto the reference poses (--align-to).
  AlignToReference(options, inputs, clock, &sparse, &report);
  // 4. Registered views in input order.
  const RegisteredViews views = CollectViews(inputs.images, sparse.model, inputs.camera, &report);
  // 5. Keyframes, semi-dense depth, inter-keyframe consistency.
  const KeyframeDepths depths = EstimateKeyframeDepths(options, views, clock);
  // 6. 3D edge points with 3D gradients.
  LiftedKeyframes lifted = LiftKeyframes(options, views, depths, clock);
  // 7. The merged map.
  Map map = MergeKeyframePoints(options, views, std::move(lifted), sparse, clock, &report);
  // 8. Relocalization data: landmarks, keyframe features, vocabulary, global descriptors.
  AddRelocalizationData(options, clock, &map, &report);
  // 9. The geo anchor (before any output: a failed alignment writes nothing).
  if (options.geo.Any()) {
    GeoReferenceResult geo = GeoReferenceMap(map, options.image_dir, options.geo);
    map.geo_anchor = geo.anchor;
    report.geo_anchor = geo.anchor;
    report.geo_alignment = std::move(geo.alignment);
    report.geo_inputs = geo.inputs;
  }
  // 10. The map directory, staged and renamed into place.
  WriteOutputs(options, inputs, map, sparse, clock, &report);
  return report;
}

}  // namespace evloc::mapper
