#include <algorithm>
#include <fstream>
#include <functional>
#include <tuple>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "mapper/build_stages.h"
#include "mapper/build_workspace.h"
#include "mapper/colmap_runner.h"
#include "mapper/pose_alignment.h"

namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;

// The count that opens a COLMAP binary model file (images.bin: registered images, points3D.bin:
// points); 0 when it cannot be read.
uint64_t BinaryModelCount(const fs::path& path) {
  std::ifstream stream(path, std::ios::binary);
  uint64_t count = 0;
  if (!stream.read(reinterpret_cast<char*>(&count), sizeof(count))) return 0;
  return count;
}

// The model of `sparse` (folders 0, 1, ...) with the most registered images, then the most
// points, then the smallest folder name: the same choice in every run. Empty when there is none.
fs::path LargestModel(const fs::path& sparse) {
  std::vector<std::tuple<uint64_t, uint64_t, std::string>> models;
  std::error_code error;
  for (const fs::directory_entry& entry : fs::directory_iterator(sparse, error)) {
    const fs::path images_bin = entry.path() / "images.bin";
    if (!fs::exists(images_bin, error)) continue;
    models.emplace_back(BinaryModelCount(images_bin),
                        BinaryModelCount(entry.path() / "points3D.bin"),
                        entry.path().filename().string());
  }
  if (models.empty()) return {};
  const auto best =
      std::min_element(models.begin(), models.end(), [](const auto& a, const auto& b) {
        if (std::get<0>(a) != std::get<0>(b)) return std::get<0>(a) > std::get<0>(b);
        if (std::get<1>(a) != std::get<1>(b)) return std::get<1>(a) > std::get<1>(b);
        return std::get<2>(a) < std::get<2>(b);
      });
  return sparse / std::get<2>(*best);
}

}  // namespace

SparseReconstruction ReconstructSparse(const MapBuilderOptions& options, const BuildInputs& inputs,
                                       const StageClock& clock, MapBuildReport* report) {
  const std::vector<InputImage>& images = inputs.images;
  const std::optional<Camera>& camera = inputs.camera;
  const std::map<std::string, Rigid3d>& known_world_from_cams = inputs.known_world_from_cams;
  std::error_code error;
  const fs::path workspace = options.colmap_workspace
                                 ? fs::absolute(*options.colmap_workspace)
                                 : fs::path(inputs.output_dir.string() + ".colmap-workspace");
  // A timed image list is a time-ordered video: sequential matching (each image with the next
  // sequential_overlap ones) instead of all pairs, whatever the number of images.
  const bool timed_sequence = std::all_of(images.begin(), images.end(),
                                          [](const InputImage& image) { return image.has_time; });
  ColmapOptions colmap_options = options.colmap;
  colmap_options.camera = camera;
  if (colmap_options.matcher == MatcherType::kAuto && timed_sequence) {
    colmap_options.matcher = MatcherType::kSequential;
  }
  ColmapRunner runner(colmap_options, workspace, options.image_dir);
  report->colmap_version = ColmapVersion(colmap_options);
  const MatcherType matcher = runner.EffectiveMatcher(images.size());
  report->matcher = MatcherTypeName(matcher);
  report->pose_source = options.known_poses ? "known" : "estimated";
  const std::string fingerprint =
      WorkspaceFingerprint(options, images, camera, matcher, report->colmap_version);
  const std::string model_fingerprint = ModelFingerprint(options, fingerprint);
  PrepareWorkspace(workspace, fingerprint);
  std::vector<std::string> image_names;
  for (const InputImage& image : images) image_names.push_back(image.name);

  const auto cached_stage = [&](const std::string& stage, const std::string& stage_fingerprint,
                                const std::function<void()>& body) {
    const fs::path marker = workspace / (stage + ".done");
    clock.Run(stage, [&] {
      if (MarkerMatches(marker, stage_fingerprint)) return true;
      body();
      WriteFileAtomically(marker, stage_fingerprint);
      return false;
    });
  };
  cached_stage("colmap_features", fingerprint, [&] {
    fs::remove(runner.DatabasePath(), error);
    runner.ExtractFeatures(image_names);
  });
  cached_stage("colmap_matching", fingerprint, [&] { runner.MatchFeatures(images.size()); });
  const fs::path text_model = workspace / (options.known_poses ? "triangulated_txt" : "sparse_txt");
  if (options.known_poses) {
    cached_stage("colmap_triangulation", model_fingerprint, [&] {
      const std::map<std::string, uint32_t> ids = ReadDatabaseImageIds(runner.DatabasePath());
      const std::vector<uint32_t> camera_ids = ReadDatabaseCameraIds(runner.DatabasePath());
      if (camera_ids.size() != 1) {
        throw IoError("the COLMAP database holds " + std::to_string(camera_ids.size()) +
                      " cameras; expected exactly one");
      }
      ColmapModel known;
      known.cameras[camera_ids[0]] = ColmapCameraFromCamera(*camera, camera_ids[0]);
      for (const InputImage& image : images) {
        const auto id = ids.find(image.name);
        if (id == ids.end()) {
          throw IoError("image " + image.name + " is missing from the COLMAP database " +
                        runner.DatabasePath().string());
        }
        ColmapImage colmap_image;
        colmap_image.image_id = id->second;
        colmap_image.camera_id = camera_ids[0];
        colmap_image.name = image.name;
        colmap_image.cam_from_world = known_world_from_cams.at(image.name).Inverse();
        known.images[id->second] = colmap_image;
      }
      const fs::path known_model = workspace / "known_model";
      const fs::path triangulated = workspace / "triangulated";
      fs::remove_all(known_model, error);
      fs::remove_all(triangulated, error);
      WriteColmapTextModel(known_model, known);
      runner.Triangulate(known_model, triangulated);
      fs::remove_all(text_model, error);
      runner.ConvertToText(triangulated, text_model);
    });
  } else {
    cached_stage("colmap_mapper", model_fingerprint, [&] {
      const fs::path sparse = workspace / "sparse";
      fs::remove_all(sparse, error);
      runner.Map(sparse);
      const fs::path best = LargestModel(sparse);
      if (best.empty()) {
        throw InvalidArgumentError(
            "COLMAP could not reconstruct any image pair (no model written); the images may "
            "lack texture or overlap; see " +
            (runner.LogDir() / "mapper.log").string());
      }
      fs::path model_path = best;
      if (camera) {
        // Calibrated intrinsics: drop the observations COLMAP's 4 px kept, adjust again, per
        // bound. The previous run's refined* folders go first.
        const fs::path refined = workspace / "refined";
        std::vector<fs::path> previous;
        for (const fs::directory_entry& entry : fs::directory_iterator(workspace, error)) {
          if (entry.path().filename().string().rfind("refined", 0) == 0) {
            previous.push_back(entry.path());
          }
        }
        for (const fs::path& path : previous) fs::remove_all(path, error);
        runner.RefineModel(model_path, refined);
        model_path = refined;
      }
      fs::remove_all(text_model, error);
      runner.ConvertToText(model_path, text_model);
    });
  }
  SparseReconstruction sparse;
  sparse.text_model = text_model;
  sparse.log_dir = runner.LogDir();
  sparse.model = ReadColmapTextModel(text_model);
  const ColmapModel& model = sparse.model;
  report->num_registered = model.images.size();
  report->num_sparse_points = model.points.size();
  report->colmap_mean_reprojection_error_px = model.MeanReprojectionError();
  if (static_cast<double>(model.images.size()) <
      options.min_registered_fraction * static_cast<double>(images.size())) {
    throw InvalidArgumentError(
        "COLMAP registered only " + std::to_string(model.images.size()) + " of " +
        std::to_string(images.size()) + " images (fewer than " +
        std::to_string(static_cast<int>(options.min_registered_fraction * 100)) +
        " %); check overlap and texture, or give the camera");
  }
  if (model.cameras.empty()) throw IoError("the COLMAP model has no camera");
  return sparse;
}

Sim3d FitAlignmentToReference(const MapBuilderOptions& options, const std::vector<Rigid3d>& model,
                              const std::vector<Rigid3d>& reference,
                              const std::string& likely_cause, MapBuildReport* report) {
  const PoseAlignment alignment = AlignPoses(model, reference);
  const Sim3d& world_from_model = alignment.reference_from_model;
  report->alignment_num_images = alignment.num_poses;
  report->alignment_rms_m = alignment.centre_rms;
  report->alignment_max_m = alignment.centre_max;
  report->alignment_rotation_rms_deg = alignment.rotation_rms_deg;
  report->alignment_rotation_max_deg = alignment.rotation_max_deg;
  report->alignment_scale = world_from_model.scale;
  report->alignment_reference_spread_m = alignment.reference_spread;
  report->world_from_model = world_from_model;
  if (const std::optional<std::string> violation =
          AlignmentLimitViolation(alignment, options.alignment_limits)) {
    if (!options.accept_bad_alignment) {
      throw InvalidArgumentError(
          "--align-to " + options.align_to->string() + ": " + *violation + ". " + likely_cause +
          " or the reference poses belong to other images; no map was written. To build it "
          "anyway pass --accept-bad-alignment, or raise --max-alignment-residual / "
          "--max-alignment-rotation");
    }
    report->alignment_warning = *violation;
  }
  return world_from_model;
}

void AlignToReference(const MapBuilderOptions& options, const BuildInputs& inputs,
                      const StageClock& clock, SparseReconstruction* sparse,
                      MapBuildReport* report) {
  clock.Run("alignment", [&] {
    if (!options.align_to) return false;
    std::vector<Rigid3d> model_poses;
    std::vector<Rigid3d> reference_poses;
    for (const auto& [id, image] : sparse->model.images) {
      const auto reference = inputs.reference_world_from_cams.find(image.name);
      if (reference == inputs.reference_world_from_cams.end()) continue;
      model_poses.push_back(image.cam_from_world.Inverse());
      reference_poses.push_back(reference->second);
    }
    if (model_poses.size() < 3) {
      throw InvalidArgumentError("only " + std::to_string(model_poses.size()) +
                                 " registered images have a reference pose in " +
                                 options.align_to->string() + "; the alignment needs 3");
    }
    const Sim3d world_from_model = FitAlignmentToReference(
        options, model_poses, reference_poses,
        "The COLMAP reconstruction is probably wrong (see the COLMAP logs in " +
            sparse->log_dir.string() + ")",
        report);
    for (auto& [id, image] : sparse->model.images) {
      image.cam_from_world =
          world_from_model.TransformPose(image.cam_from_world.Inverse()).Inverse();
    }
    for (auto& [id, point] : sparse->model.points)
      point.position = world_from_model * point.position;
    return false;
  });
}

}  // namespace evloc::mapper
