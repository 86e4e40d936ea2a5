#include "mapper/build_stages.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <iomanip>
#include <sstream>
#include <string_view>
#include <unordered_set>

#include <opencv2/imgcodecs.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/provenance.h"
#include "mapper/build_workspace.h"
#include "mapper/map_preview.h"
#include "maps/edge_lifting.h"
#include "maps/map_directory.h"


namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;

// Keyframe indices sorted by how many sparse points they share with keyframe `k`.
std::vector<std::vector<uint32_t>> KeyframeConsistencyNeighbours(
    const std::vector<RegisteredView>& views, const std::vector<size_t>& keyframes,
    const KeyframeSelectionOptions& options) {
  std::vector<std::unordered_set<uint64_t>> point_sets;
  for (const size_t keyframe : keyframes) {
    point_sets.emplace_back(views[keyframe].observed_points.begin(),
                            views[keyframe].observed_points.end());
  }
  std::vector<std::vector<uint32_t>> neighbours(keyframes.size());
  for (size_t k = 0; k < keyframes.size(); ++k) {
    std::vector<std::pair<size_t, uint32_t>> scored;
    for (size_t j = 0; j < keyframes.size(); ++j) {
      if (j == k) continue;
      size_t shared = 0;
      for (const uint64_t id : views[keyframes[j]].observed_points) {
        shared += point_sets[k].contains(id) ? 1 : 0;
      }
      if (shared >= static_cast<size_t>(std::max(options.min_shared_points, 1))) {
        scored.emplace_back(shared, static_cast<uint32_t>(j));
      }
    }
    std::sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) {
      return a.first != b.first ? a.first > b.first : a.second < b.second;
    });
    for (size_t i = 0; i < scored.size() && i < static_cast<size_t>(options.num_neighbours); ++i) {
      neighbours[k].push_back(scored[i].second);
    }
  }
  return neighbours;
}

}  // namespace

RegisteredViews CollectViews(const std::vector<InputImage>& images, const ColmapModel& model,
                             const std::optional<Camera>& camera, MapBuildReport* report) {
  RegisteredViews result;
  for (const auto& [id, point] : model.points) result.sparse_points[id] = point.position;
  std::map<uint32_t, uint32_t> camera_index_of_id;
  for (const auto& [id, colmap_camera] : model.cameras) {
    camera_index_of_id[id] = static_cast<uint32_t>(result.cameras.size());
    result.cameras.push_back(camera ? *camera : CameraFromColmap(colmap_camera));
  }
  for (const InputImage& input : images) {
    const uint32_t id = model.FindImageId(input.name);
    if (id == 0) continue;
    const ColmapImage& image = model.images.at(id);
    RegisteredView view;
    view.image_name = image.name;
    view.t_ns = input.t_ns;
    view.cam_from_world = image.cam_from_world;
    for (const uint64_t point : image.point3d_ids) {
      if (point != kNoPoint3D) view.observed_points.push_back(point);
    }
    std::sort(view.observed_points.begin(), view.observed_points.end());
    view.observed_points.erase(
        std::unique(view.observed_points.begin(), view.observed_points.end()),
        view.observed_points.end());
    result.views.push_back(std::move(view));
    result.camera_indices.push_back(camera_index_of_id.at(image.camera_id));
    report->world_from_cams[image.name] = image.cam_from_world.Inverse();
  }
  return result;
}

KeyframeDepths EstimateKeyframeDepths(const MapBuilderOptions& options,
                                      const RegisteredViews& registered, const StageClock& clock) {
  const std::vector<RegisteredView>& views = registered.views;
  KeyframeDepths result;
  KeyframeSelection& selection = result.selection;
  clock.Run("keyframes", [&] {
    selection = SelectKeyframes(views, registered.sparse_points, options.keyframes);
    return false;
  });
  // Frames are prepared once, on first use.
  std::map<size_t, DepthFrame> frames;
  const auto frame_of = [&](size_t view) -> const DepthFrame& {
    auto found = frames.find(view);
    if (found == frames.end()) {
      const cv::Mat image =
          ReadImage(options.image_dir / views[view].image_name, cv::IMREAD_UNCHANGED);
      const Camera& view_camera = registered.cameras[registered.camera_indices[view]];
      found = frames
                  .emplace(view, MakeDepthFrame(image, view_camera, views[view].cam_from_world,
                                                options.semidense))
                  .first;
    }
    return found->second;
  };
  std::vector<KeyframeDepth>& depths = result.depths;
  depths.resize(selection.keyframes.size());
  clock.Run("semidense_depth", [&] {
    for (size_t k = 0; k < selection.keyframes.size(); ++k) {
      clock.Progress("semidense_depth", k, selection.keyframes.size());
      const size_t view = selection.keyframes[k];
      std::vector<Eigen::Vector3d> seen;
      for (const uint64_t id : views[view].observed_points) {
        seen.push_back(registered.sparse_points.at(id));
      }
      double min_depth = 0.0;
      double max_depth = 0.0;
      if (!SparseDepthRange(views[view].cam_from_world, seen, options.semidense.depth_range_margin,
                            &min_depth, &max_depth)) {
        continue;  // No sparse structure in view: nothing to bound the search with.
      }
      const DepthFrame& keyframe = frame_of(view);
      std::vector<const DepthFrame*> neighbours;
      for (const size_t neighbour : selection.neighbours[k]) {
        neighbours.push_back(&frame_of(neighbour));
      }
      if (neighbours.empty()) continue;
      depths[k] =
          EstimateKeyframeDepth(keyframe, neighbours, min_depth, max_depth, options.semidense);
    }
    return false;
  });
  clock.Run("semidense_consistency", [&] {
    std::vector<const DepthFrame*> keyframe_frames;
    for (const size_t view : selection.keyframes) keyframe_frames.push_back(&frame_of(view));
    EnforceInterKeyframeConsistency(
        keyframe_frames,
        KeyframeConsistencyNeighbours(views, selection.keyframes, options.keyframes),
        options.semidense, &depths);
    return false;
  });
  return result;
}

LiftedKeyframes LiftKeyframes(const MapBuilderOptions& options, const RegisteredViews& registered,
                              const KeyframeDepths& depths, const StageClock& clock) {
  LiftedKeyframes result;
  clock.Run("semidense_gradients", [&] {
    for (size_t k = 0; k < depths.selection.keyframes.size(); ++k) {
      const size_t view_index = depths.selection.keyframes[k];
      const RegisteredView& view = registered.views[view_index];
      Keyframe keyframe;
      keyframe.cam_from_world = view.cam_from_world;
      keyframe.camera_index = registered.camera_indices[view_index];
      keyframe.t_ns = view.t_ns;
      keyframe.image_name = view.image_name;
      result.keyframes.push_back(keyframe);
      const Camera& camera = registered.cameras[keyframe.camera_index];
      const Rigid3d world_from_cam = view.cam_from_world.Inverse();
      const std::vector<DepthPixel>& pixels = depths.depths[k].pixels;
      const std::vector<std::optional<LiftedEdgePoint>> lifted =
          LiftEdgePixels(camera, EdgeDepthPixels(depths.depths[k]), options.semidense.surface);
      for (size_t p = 0; p < pixels.size(); ++p) {
        if (!lifted[p]) continue;
        const DepthPixel& pixel = pixels[p];
        const LiftedEdgePoint& point = *lifted[p];
        CandidatePoint candidate;
        candidate.position = world_from_cam * point.point_in_cam;
        candidate.gradient = (world_from_cam.rotation * point.gradient_in_cam).normalized();
        if (point.surface_gradient) ++result.num_surface_gradients;
        const double sigma = std::sqrt(pixel.inverse_depth_variance);
        candidate.inverse_depth_sigma = sigma;
        candidate.position_sigma =
            sigma / (pixel.inverse_depth * pixel.inverse_depth) * point.ray.norm();
        candidate.pixel_footprint = point.point_in_cam.z() / camera.fx;
        candidate.gradient_magnitude = pixel.gradient_magnitude;
        candidate.source_keyframe = static_cast<uint32_t>(k);
        candidate.observing_keyframes = pixel.confirming_keyframes;
        result.points.push_back(std::move(candidate));
      }
    }
    return false;
  });
  return result;
}

Map MergeKeyframePoints(const MapBuilderOptions& options, const RegisteredViews& views,
                        LiftedKeyframes lifted, const SparseReconstruction& sparse,
                        const StageClock& clock, MapBuildReport* report) {
  report->num_keyframes = lifted.keyframes.size();
  report->num_keyframe_points = lifted.points.size();
  report->num_surface_gradients = lifted.num_surface_gradients;
  Map map;
  map.cameras = views.cameras;
  map.keyframes = std::move(lifted.keyframes);
  clock.Run("merge", [&] {
    const MergeStatistics statistics = MergePoints(lifted.points, options.merge, &map);
    report->voxel_size = statistics.voxel_size;
    return false;
  });
  report->num_points = map.size();
  if (map.size() == 0) {
    throw InvalidArgumentError(
        "the semi-dense stage found no consistent edge points (" +
        std::to_string(report->num_keyframes) + " keyframes, " +
        std::to_string(report->num_keyframe_points) +
        " keyframe points before merging); the images may lack edges or baseline, or every "
        "point lacks " +
        std::to_string(options.semidense.min_keyframe_confirmations) +
        " confirming keyframes (--min-keyframes, --min-confirmations); see the COLMAP model in " +
        sparse.text_model.string());
  }
  // Provenance is not part of the map's content checksum (docs/map-format.md): the build time
  // and the absolute input paths leave content_crc32c unchanged.
  map.provenance.tool = "evloc-mapper build";
  map.provenance.tool_version = ToolVersion();
  map.provenance.created_utc = UtcNowIso8601();
  map.provenance.command_line = options.command_line;
  map.provenance.inputs.push_back(fs::absolute(options.image_dir).string());
  for (const auto& input :
       {options.image_list, options.calibration_file, options.known_poses, options.align_to}) {
    if (input) map.provenance.inputs.push_back(fs::absolute(*input).string());
  }
  return map;
}

void WriteOutputs(const MapBuilderOptions& options, const BuildInputs& inputs, const Map& map,
                  const SparseReconstruction& sparse, const StageClock& clock,
                  MapBuildReport* report) {
  const fs::path& output_dir = inputs.output_dir;
  clock.Run("outputs", [&] {
    StagingDirectory staging(output_dir.parent_path() / ("." + output_dir.filename().string() +
                                                         ".staging-" + std::to_string(::getpid())));
    WriteMapDirectory(staging.path(), map);
    const cv::Mat preview = RenderPreview(map, options.image_dir, options.preview_keyframes);
    std::vector<uint8_t> png;
    if (!cv::imencode(".png", preview, png)) throw IoError("cannot encode preview.png");
    WriteFileAtomically(staging.path() / "preview.png",
                        std::string_view(reinterpret_cast<const char*>(png.data()), png.size()));
    const fs::path colmap_dir = staging.path() / "colmap";
    std::error_code error;
    fs::create_directories(colmap_dir / "logs", error);
    if (error) throw IoError("cannot create " + colmap_dir.string() + ": " + error.message());
    for (const char* name : {"cameras.txt", "images.txt", "points3D.txt"}) {
      CopyFileInto(sparse.text_model / name, colmap_dir);
    }
    for (const fs::directory_entry& entry : fs::directory_iterator(sparse.log_dir, error)) {
      CopyFileInto(entry.path(), colmap_dir / "logs");
    }
    // report.json holds the timings of every stage before this one.
    WriteFileAtomically(staging.path() / "report.json", MapBuildReportToJson(*report));
    staging.CommitTo(output_dir);
    return false;
  });
}

}  // namespace evloc::mapper
