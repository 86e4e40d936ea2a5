#include "mapper/chunked_build.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <mutex>
#include <numeric>
#include <queue>
#include <set>
#include <sstream>
#include <thread>

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/provenance.h"
#include "core/common/text_lines.h"
#include "core/dataset/pose_text.h"
#include "core/features/features.h"
#include "core/features/vocabulary.h"
#include "core/geometry/rigid3.h"
#include "mapper/build_stages.h"
#include "mapper/build_workspace.h"
#include "mapper/colmap_runner.h"
#include "mapper/map_preview.h"
#include "mapper/parallel_for.h"
#include "mapper/pose_alignment.h"
#include "maps/crc32c.h"
#include "maps/site.h"

namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;

constexpr const char* kChunkMapFile = "map.evmap";
constexpr const char* kChunkPosesFile = "poses.txt";
constexpr const char* kChunkInputsFile = "inputs.txt";
constexpr const char* kChunkReportFile = "report.json";
constexpr const char* kPlanFile = "plan.json";

// Splits `indices` (into positions) recursively at the median of the widest axis.
void SplitByPosition(std::vector<size_t> indices, const std::vector<Eigen::Vector3d>& positions,
                     size_t chunk_size, std::vector<std::vector<size_t>>* parts) {
  if (indices.size() <= chunk_size) {
    std::sort(indices.begin(), indices.end());
    parts->push_back(std::move(indices));
    return;
  }
  Eigen::Vector3d low = positions[indices[0]];
  Eigen::Vector3d high = low;
  for (const size_t index : indices) {
    low = low.cwiseMin(positions[index]);
    high = high.cwiseMax(positions[index]);
  }
  int axis = 0;
  (high - low).maxCoeff(&axis);
  std::stable_sort(indices.begin(), indices.end(), [&](size_t a, size_t b) {
    return positions[a][axis] != positions[b][axis] ? positions[a][axis] < positions[b][axis]
                                                    : a < b;
  });
  const size_t half = indices.size() / 2;
  SplitByPosition(std::vector<size_t>(indices.begin(), indices.begin() + half), positions,
                  chunk_size, parts);
  SplitByPosition(std::vector<size_t>(indices.begin() + half, indices.end()), positions, chunk_size,
                  parts);
}

Sim3d Compose(const Sim3d& c_from_b, const Sim3d& b_from_a) {
  Sim3d result;
  result.scale = c_from_b.scale * b_from_a.scale;
  result.rotation = (c_from_b.rotation * b_from_a.rotation).normalized();
  result.translation = c_from_b * b_from_a.translation;
  return result;
}

std::string Hex32(uint32_t value) {
  std::ostringstream text;
  text << std::hex << std::setw(8) << std::setfill('0') << value;
  return text.str();
}

// The pose text of poses.txt: `IMAGE_NAME tx ty tz qx qy qz qw`, 17 significant digits.
std::string PoseLines(const std::map<std::string, Rigid3d>& poses) {
  std::ostringstream text;
  text << "# world_from_cam in the chunk's frame: IMAGE_NAME tx ty tz qx qy qz qw\n";
  text << std::setprecision(17);
  for (const auto& [name, pose] : poses) {
    const Eigen::Quaterniond q = pose.rotation.normalized();
    text << name << " " << pose.translation.x() << " " << pose.translation.y() << " "
         << pose.translation.z() << " " << q.x() << " " << q.y() << " " << q.z() << " " << q.w()
         << "\n";
  }
  return text.str();
}

// The fingerprint of a chunk's inputs: its photos (names, sizes, content hashes), camera, COLMAP
// options and known poses (ModelFingerprint), the options of the semi-dense stages and the core.
std::string ChunkFingerprint(const MapBuilderOptions& chunk_options,
                             const std::vector<InputImage>& members,
                             const std::vector<InputImage>& core,
                             const std::optional<Camera>& camera,
                             const std::string& colmap_version) {
  std::ostringstream text;
  text << "evloc-mapper chunk v1\n";
  text << ModelFingerprint(chunk_options,
                           WorkspaceFingerprint(chunk_options, members, camera,
                                                chunk_options.colmap.matcher, colmap_version));
  const KeyframeSelectionOptions& keyframes = chunk_options.keyframes;
  text << "keyframes " << keyframes.max_keyframes.value_or(-1) << " " << keyframes.min_keyframes
       << " " << keyframes.num_neighbours << " " << keyframes.min_shared_points << "\n";
  text << "semidense confirmations " << chunk_options.semidense.min_keyframe_confirmations << "\n";
  text << "merge voxel "
       << (chunk_options.merge.voxel_size ? std::to_string(*chunk_options.merge.voxel_size)
                                          : std::string("auto"))
       << " " << chunk_options.merge.voxel_size_px << " "
       << chunk_options.merge.max_gradient_angle_deg << " "
       << chunk_options.merge.outlier_neighbours << " " << chunk_options.merge.outlier_std_ratio
       << "\n";
  text << "core";
  for (const InputImage& image : core) text << " " << image.name;
  text << "\n";
  return Hex32(Crc32c(text.str()));
}

// The chunk's own build options: no alignment, no geo-reference, no relocalization data (those
// are made once on the merged map), its own COLMAP workspace.
MapBuilderOptions ChunkBuildOptions(const ChunkedBuildOptions& options, const ChunkPlan& plan,
                                    const fs::path& workspace, size_t index) {
  MapBuilderOptions chunk = options.build;
  // A chunk cut by retrieval is unordered: each photo is matched with its most similar ones (the
  // automatic choice would match neighbours in name order). COLMAP's own matchers
  // (--fast-nondeterministic) keep theirs. Chunks cut by position keep the automatic choice
  // (sequential for a timed list): on the car park's walking survey, retrieval pairs (which
  // favour look-alike parked cars) did not mend a 305-photo chunk that sequential pairs left
  // 7.4 m from the truth (13.4 m; docs/mapper.md, "Estimated poses").
  if (plan.method == "retrieval" && chunk.colmap.matcher == MatcherType::kAuto &&
      chunk.colmap.deterministic) {
    chunk.colmap.matcher = MatcherType::kRetrieval;
  }
  chunk.align_to.reset();
  chunk.geo = {};
  chunk.relocalization = false;
  chunk.colmap_workspace = workspace / ("colmap_" + ChunkFolderName(index).substr(6));
  chunk.output_dir = workspace / ChunkFolderName(index);
  return chunk;
}

struct ChunkInputs {
  BuildInputs inputs;
  std::vector<InputImage> core;
};

ChunkInputs SelectChunkInputs(const BuildInputs& all, const ChunkPlanEntry& entry,
                              const fs::path& output_dir) {
  ChunkInputs chunk;
  chunk.inputs.output_dir = output_dir;
  chunk.inputs.camera = all.camera;
  for (const size_t index : entry.members) {
    const InputImage& image = all.images[index];
    chunk.inputs.images.push_back(image);
    const auto pose = all.known_world_from_cams.find(image.name);
    if (pose != all.known_world_from_cams.end()) {
      chunk.inputs.known_world_from_cams.emplace(image.name, pose->second);
    }
  }
  chunk.inputs.num_images = chunk.inputs.images.size();
  for (const size_t index : entry.core) chunk.core.push_back(all.images[index]);
  return chunk;
}

// Keeps the keyframes of core photos and the points they are the source of.
void KeepCoreKeyframes(const std::set<std::string>& core_names, LiftedKeyframes* lifted) {
  std::vector<uint32_t> new_index(lifted->keyframes.size(), kNoKeyframe);
  std::vector<Keyframe> kept;
  for (size_t k = 0; k < lifted->keyframes.size(); ++k) {
    if (!core_names.contains(lifted->keyframes[k].image_name)) continue;
    new_index[k] = static_cast<uint32_t>(kept.size());
    kept.push_back(std::move(lifted->keyframes[k]));
  }
  std::vector<CandidatePoint> points;
  for (CandidatePoint& point : lifted->points) {
    if (new_index[point.source_keyframe] == kNoKeyframe) continue;
    point.source_keyframe = new_index[point.source_keyframe];
    std::vector<uint32_t> observers;
    for (const uint32_t observer : point.observing_keyframes) {
      if (new_index[observer] != kNoKeyframe) observers.push_back(new_index[observer]);
    }
    point.observing_keyframes = std::move(observers);
    points.push_back(std::move(point));
  }
  lifted->keyframes = std::move(kept);
  lifted->points = std::move(points);
}

// Computes chunk `index` into its folder of the chunk workspace (staged, renamed into place).
void ComputeChunk(const ChunkedBuildOptions& options, const BuildInputs& all, const ChunkPlan& plan,
                  size_t index, const fs::path& workspace, const std::string& fingerprint,
                  ProgressListener* progress) {
  const MapBuilderOptions chunk_options = ChunkBuildOptions(options, plan, workspace, index);
  const ChunkInputs chunk = SelectChunkInputs(all, plan.chunks[index], chunk_options.output_dir);
  MapBuildReport report;
  report.num_images = chunk.inputs.images.size();
  const StageClock clock(progress, &report);
  SparseReconstruction sparse = ReconstructSparse(chunk_options, chunk.inputs, clock, &report);
  const RegisteredViews views =
      CollectViews(chunk.inputs.images, sparse.model, chunk.inputs.camera, &report);
  const KeyframeDepths depths = EstimateKeyframeDepths(chunk_options, views, clock);
  LiftedKeyframes lifted = LiftKeyframes(chunk_options, views, depths, clock);
  std::set<std::string> core_names;
  for (const InputImage& image : chunk.core) core_names.insert(image.name);
  KeepCoreKeyframes(core_names, &lifted);
  Map map = MergeKeyframePoints(chunk_options, views, std::move(lifted), sparse, clock, &report);
  clock.Run("chunk_outputs", [&] {
    const fs::path target = workspace / ChunkFolderName(index);
    StagingDirectory staging(
        workspace / ("." + ChunkFolderName(index) + ".staging-" + std::to_string(::getpid())));
    SaveMap(staging.path() / kChunkMapFile, map);
    WriteFileAtomically(staging.path() / kChunkPosesFile, PoseLines(report.world_from_cams));
    WriteFileAtomically(staging.path() / kChunkReportFile, MapBuildReportToJson(report));
    // The fingerprint last: a folder is a finished chunk only with it.
    WriteFileAtomically(staging.path() / kChunkInputsFile, fingerprint + "\n");
    std::error_code error;
    fs::remove_all(target, error);  // A stale chunk of other inputs.
    staging.CommitTo(target);
    return false;
  });
}

// The fingerprint recorded in a chunk folder, or empty when it is not a finished chunk.
std::string RecordedFingerprint(const fs::path& directory) {
  std::error_code error;
  if (!fs::exists(directory / kChunkInputsFile, error)) return {};
  std::string text = ReadFileToString(directory / kChunkInputsFile);
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
  return text;
}

// Peak RSS and wall seconds from a chunk's report.json (0 when absent or unreadable).
std::pair<uint64_t, double> ChunkReportFigures(const fs::path& directory) {
  try {
    const nlohmann::json json =
        nlohmann::json::parse(ReadFileToString(directory / kChunkReportFile));
    double peak_mb = 0.0;
    double seconds = 0.0;
    for (const auto& timing : json.at("timings")) {
      peak_mb = std::max(peak_mb, timing.at("peak_rss_mb").get<double>());
      seconds += timing.at("seconds").get<double>();
    }
    return {static_cast<uint64_t>(peak_mb * (1 << 20)), seconds};
  } catch (const std::exception&) {
    return {0, 0.0};
  }
}

// Ceres residual: the disagreement of one photo seen by chunks a and b, in the common frame.
struct SharedPhotoResidual {
  SharedPhotoResidual(const Eigen::Vector3d& centre_a, const Eigen::Quaterniond& rotation_a,
                      const Eigen::Vector3d& centre_b, const Eigen::Quaterniond& rotation_b,
                      double rotation_weight)
      : centre_a_(centre_a),
        centre_b_(centre_b),
        rotation_a_(rotation_a.toRotationMatrix()),
        rotation_b_(rotation_b.toRotationMatrix()),
        rotation_weight_(rotation_weight) {}

  // Parameters per chunk: angle-axis (3), translation (3), log scale (1).
  template <typename T>
  bool operator()(const T* const sim_a, const T* const sim_b, T* residuals) const {
    T centre_a[3] = {T(centre_a_.x()), T(centre_a_.y()), T(centre_a_.z())};
    T centre_b[3] = {T(centre_b_.x()), T(centre_b_.y()), T(centre_b_.z())};
    T rotated_a[3];
    T rotated_b[3];
    ceres::AngleAxisRotatePoint(sim_a, centre_a, rotated_a);
    ceres::AngleAxisRotatePoint(sim_b, centre_b, rotated_b);
    const T scale_a = ceres::exp(sim_a[6]);
    const T scale_b = ceres::exp(sim_b[6]);
    for (int i = 0; i < 3; ++i) {
      residuals[i] =
          (scale_a * rotated_a[i] + sim_a[3 + i]) - (scale_b * rotated_b[i] + sim_b[3 + i]);
    }
    // Orientations: R_a * R_a,i against R_b * R_b,i, as the rotation vector between them.
    T chunk_a[9];
    T chunk_b[9];
    ceres::AngleAxisToRotationMatrix(sim_a, ceres::ColumnMajorAdapter3x3(chunk_a));
    ceres::AngleAxisToRotationMatrix(sim_b, ceres::ColumnMajorAdapter3x3(chunk_b));
    Eigen::Map<const Eigen::Matrix<T, 3, 3>> matrix_a(chunk_a);
    Eigen::Map<const Eigen::Matrix<T, 3, 3>> matrix_b(chunk_b);
    const Eigen::Matrix<T, 3, 3> world_a = matrix_a * rotation_a_.cast<T>();
    const Eigen::Matrix<T, 3, 3> world_b = matrix_b * rotation_b_.cast<T>();
    const Eigen::Matrix<T, 3, 3> difference = world_a.transpose() * world_b;
    T angle_axis[3];
    ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(difference.data()), angle_axis);
    for (int i = 0; i < 3; ++i) residuals[3 + i] = T(rotation_weight_) * angle_axis[i];
    return true;
  }

  Eigen::Vector3d centre_a_;
  Eigen::Vector3d centre_b_;
  Eigen::Matrix3d rotation_a_;
  Eigen::Matrix3d rotation_b_;
  double rotation_weight_;
};

Sim3d SimFromParameters(const std::array<double, 7>& parameters) {
  Sim3d sim;
  const Eigen::Vector3d omega(parameters[0], parameters[1], parameters[2]);
  sim.rotation = ExpSO3(omega);
  sim.translation = Eigen::Vector3d(parameters[3], parameters[4], parameters[5]);
  sim.scale = std::exp(parameters[6]);
  return sim;
}

std::array<double, 7> ParametersFromSim(const Sim3d& sim) {
  const Eigen::Vector3d omega = LogSO3(sim.rotation);
  return {omega.x(),           omega.y(),           omega.z(),          sim.translation.x(),
          sim.translation.y(), sim.translation.z(), std::log(sim.scale)};
}

// Centre RMS and max of the photos seen by two chunks under `common_from_chunk`.
std::pair<double, double> SharedPhotoSpread(
    const std::vector<std::map<std::string, Rigid3d>>& chunk_poses,
    const std::vector<Sim3d>& common_from_chunk) {
  std::map<std::string, std::vector<Eigen::Vector3d>> centres;
  for (size_t c = 0; c < chunk_poses.size(); ++c) {
    for (const auto& [name, pose] : chunk_poses[c]) {
      centres[name].push_back(common_from_chunk[c] * pose.translation);
    }
  }
  double sum = 0.0;
  double largest = 0.0;
  size_t count = 0;
  for (const auto& [name, list] : centres) {
    for (size_t i = 1; i < list.size(); ++i) {
      const double distance = (list[i] - list[0]).norm();
      sum += distance * distance;
      largest = std::max(largest, distance);
      ++count;
    }
  }
  return {count ? std::sqrt(sum / count) : 0.0, largest};
}

// The common-frame map of one chunk: points, gradients, keyframe poses transformed, cameras and
// keyframe indices offset; appended as candidate points for the final merge.
void AppendChunk(const Map& chunk, const Sim3d& common_from_chunk, Map* merged,
                 std::vector<CandidatePoint>* candidates) {
  const uint32_t camera_offset = static_cast<uint32_t>(merged->cameras.size());
  const uint32_t keyframe_offset = static_cast<uint32_t>(merged->keyframes.size());
  merged->cameras.insert(merged->cameras.end(), chunk.cameras.begin(), chunk.cameras.end());
  std::vector<std::vector<uint32_t>> observers(chunk.size());
  for (size_t k = 0; k < chunk.keyframes.size(); ++k) {
    Keyframe keyframe = chunk.keyframes[k];
    for (const uint32_t point : keyframe.visible_points) {
      observers[point].push_back(keyframe_offset + static_cast<uint32_t>(k));
    }
    keyframe.visible_points.clear();
    keyframe.camera_index += camera_offset;
    keyframe.cam_from_world =
        common_from_chunk.TransformPose(keyframe.cam_from_world.Inverse()).Inverse();
    merged->keyframes.push_back(std::move(keyframe));
  }
  const double scale = common_from_chunk.scale;
  for (size_t p = 0; p < chunk.size(); ++p) {
    CandidatePoint point;
    point.position = common_from_chunk * chunk.positions[p].cast<double>();
    point.gradient = (common_from_chunk.rotation * chunk.gradients[p].cast<double>()).normalized();
    point.inverse_depth_sigma = chunk.inverse_depth_sigma[p] / scale;
    point.gradient_magnitude = chunk.gradient_magnitude[p];
    const uint32_t source = chunk.source_keyframe[p];
    if (source == kNoKeyframe) continue;
    point.source_keyframe = keyframe_offset + source;
    const Keyframe& keyframe = merged->keyframes[point.source_keyframe];
    const double depth = (keyframe.cam_from_world * point.position).z();
    const Camera& camera = merged->cameras[keyframe.camera_index];
    point.pixel_footprint = depth > 0.0 ? depth / camera.fx : 0.0;
    point.position_sigma = point.inverse_depth_sigma * depth * depth;
    point.observing_keyframes = std::move(observers[p]);
    candidates->push_back(std::move(point));
  }
}

// The chunk workspace folder.
fs::path ChunkWorkspace(const ChunkedBuildOptions& options) {
  return options.chunk_workspace
             ? fs::absolute(*options.chunk_workspace).lexically_normal()
             : fs::path(fs::absolute(options.build.output_dir).lexically_normal().string() +
                        ".chunks");
}

// Camera centres to cut the photos by: the known poses, else the reference poses; nullopt when
// some photo has neither.
std::optional<std::vector<Eigen::Vector3d>> PlanPositions(const BuildInputs& inputs) {
  std::vector<Eigen::Vector3d> positions;
  for (const InputImage& image : inputs.images) {
    auto found = inputs.known_world_from_cams.find(image.name);
    if (found == inputs.known_world_from_cams.end()) {
      found = inputs.reference_world_from_cams.find(image.name);
      if (found == inputs.reference_world_from_cams.end()) return std::nullopt;
    }
    positions.push_back(found->second.translation);
  }
  return positions;
}

// Photos wider than this are halved (repeatedly) before their retrieval features are taken.
constexpr int kRetrievalMaxWidth = 800;

// One global descriptor per photo for PlanChunksByRetrieval: the VLAD vector (core/features) of
// its SIFT features over a vocabulary trained on the photos themselves. Deterministic: the same
// photos give the same descriptors in every process that has no stored plan to read. Throws
// InvalidArgumentError when the photos hold too few features to train the vocabulary.
std::vector<std::vector<float>> RetrievalDescriptors(const ChunkedBuildOptions& options,
                                                     const BuildInputs& inputs) {
  features::FeatureOptions feature_options;
  feature_options.max_features = 1000;
  std::vector<features::Features> photo_features(inputs.images.size());
  ParallelFor(
      inputs.images.size(), options.build.colmap.num_threads,
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
          cv::Mat image =
              ReadImage(options.build.image_dir / inputs.images[i].name, cv::IMREAD_GRAYSCALE);
          while (image.cols > kRetrievalMaxWidth) {
            cv::Mat half;
            cv::resize(image, half, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
            image = half;
          }
          photo_features[i] = features::ExtractFeatures(image, feature_options);
        }
      },
      1);
  features::Vocabulary vocabulary;
  try {
    vocabulary = features::Vocabulary::Train(photo_features, features::VocabularyOptions{});
  } catch (const InvalidArgumentError& error) {
    throw InvalidArgumentError(
        std::string("cannot cut the photos into chunks by image retrieval: ") + error.what() +
        " (photos without texture?); give their positions (--known-poses or --align-to) or "
        "times (--images-list)");
  }
  std::vector<std::vector<float>> descriptors(inputs.images.size());
  for (size_t i = 0; i < inputs.images.size(); ++i) {
    descriptors[i] = vocabulary.EncodeVlad(photo_features[i]);
  }
  return descriptors;
}

// What a plan is cut from, as plan.json records it: the photos (names and file sizes, in input
// order) and the chunking options. A photo whose content changes at the same size keeps its plan
// (any plan is valid; the chunks' own fingerprints cover the content).
std::string PlanInputsFingerprint(const ChunkedBuildOptions& options, const BuildInputs& inputs) {
  std::ostringstream text;
  text << "plan-v1 " << ChunkMethodName(options.chunking.method) << " "
       << options.chunking.chunk_size << " " << options.chunking.overlap_m << " "
       << options.chunking.overlap_photos << " " << options.chunking.retrieval_neighbours << "\n";
  for (const InputImage& image : inputs.images) {
    std::error_code error;
    const uintmax_t size = fs::file_size(options.build.image_dir / image.name, error);
    text << image.name << " " << (error ? 0 : size) << "\n";
  }
  std::ostringstream hex;
  hex << std::hex << std::setw(8) << std::setfill('0') << Crc32c(text.str());
  return hex.str();
}

// The retrieval plan stored at `path` when it records `inputs`; nullopt when there is none, it is
// broken, or it was cut from other photos or options.
std::optional<ChunkPlan> StoredRetrievalPlan(const fs::path& path,
                                             const std::vector<std::string>& names,
                                             const std::string& inputs) {
  std::error_code error;
  if (!fs::is_regular_file(path, error)) return std::nullopt;
  try {
    StoredChunkPlan stored = ParseChunkPlan(ReadFileToString(path), names, path.string());
    if (stored.inputs != inputs || stored.plan.method != "retrieval") return std::nullopt;
    return std::move(stored.plan);
  } catch (const Error&) {
    return std::nullopt;  // computed again, and written over
  }
}

// The poses of `poses` that have a reference pose of the same name, and those reference poses, in
// name order.
struct PosesWithReference {
  std::vector<Rigid3d> model;
  std::vector<Rigid3d> reference;
};
PosesWithReference MatchReference(const std::map<std::string, Rigid3d>& poses,
                                  const std::map<std::string, Rigid3d>& reference) {
  PosesWithReference matched;
  for (const auto& [name, pose] : poses) {
    const auto found = reference.find(name);
    if (found == reference.end()) continue;
    matched.model.push_back(pose);
    matched.reference.push_back(found->second);
  }
  return matched;
}

std::string FormatGigabytes(uint64_t bytes) {
  std::ostringstream text;
  text << std::fixed << std::setprecision(2) << static_cast<double>(bytes) / (1ull << 30) << " GB";
  return text.str();
}

}  // namespace

void ChunkingOptions::Check() const {
  if (chunk_size < 8) throw InvalidArgumentError("the chunk size must be at least 8 photos");
  if (!(std::isfinite(overlap_m) && overlap_m >= 0.0)) {
    throw InvalidArgumentError("the chunk overlap must be a finite distance >= 0 metres");
  }
  if (retrieval_neighbours < 1) {
    throw InvalidArgumentError("the retrieval neighbours per photo must be at least 1");
  }
}

std::string ChunkMethodName(ChunkMethod method) {
  switch (method) {
    case ChunkMethod::kAuto:
      return "auto";
    case ChunkMethod::kPosition:
      return "position";
    case ChunkMethod::kSequence:
      return "sequence";
    case ChunkMethod::kRetrieval:
      return "retrieval";
  }
  return "auto";
}

ChunkMethod ParseChunkMethod(const std::string& name) {
  for (const ChunkMethod method : {ChunkMethod::kAuto, ChunkMethod::kPosition,
                                   ChunkMethod::kSequence, ChunkMethod::kRetrieval}) {
    if (ChunkMethodName(method) == name) return method;
  }
  throw InvalidArgumentError("unknown chunk method '" + name +
                             "' (expected auto, position, sequence or retrieval)");
}

void ChunkedBuildOptions::Check() const {
  build.Check();
  chunking.Check();
  if (workers < 1) throw InvalidArgumentError("--workers must be at least 1");
  if ((only_chunk ? 1 : 0) + (merge_only ? 1 : 0) + (plan_only ? 1 : 0) > 1) {
    throw InvalidArgumentError("--chunk-index, --merge-only and --plan-only exclude each other");
  }
  if (memory_budget_bytes && *memory_budget_bytes == 0) {
    throw InvalidArgumentError("--memory-budget must be positive");
  }
  if (!(tile_size_m > 0.0 && std::isfinite(tile_size_m) && tile_overlap_m >= 0.0 &&
        tile_overlap_m < tile_size_m)) {
    throw InvalidArgumentError(
        "the tile size must be positive and the tile overlap in [0, tile size)");
  }
}

ChunkPlan PlanChunks(size_t num_images, const std::vector<Eigen::Vector3d>* positions,
                     const ChunkingOptions& options) {
  options.Check();
  if (num_images == 0) throw InvalidArgumentError("no photos to cut into chunks");
  ChunkPlan plan;
  if (positions != nullptr) {
    if (positions->size() != num_images) {
      throw InvalidArgumentError("PlanChunks: " + std::to_string(positions->size()) +
                                 " positions for " + std::to_string(num_images) + " photos");
    }
    for (const Eigen::Vector3d& position : *positions) {
      if (!position.allFinite()) throw InvalidArgumentError("PlanChunks: a position is not finite");
    }
    plan.method = "position";
    std::vector<size_t> all(num_images);
    std::iota(all.begin(), all.end(), size_t{0});
    std::vector<std::vector<size_t>> parts;
    SplitByPosition(std::move(all), *positions, options.chunk_size, &parts);
    // Deterministic order: by the first photo.
    std::sort(parts.begin(), parts.end(),
              [](const auto& a, const auto& b) { return a.front() < b.front(); });
    const double overlap2 = options.overlap_m * options.overlap_m;
    for (std::vector<size_t>& part : parts) {
      ChunkPlanEntry entry;
      std::vector<char> in_core(num_images, 0);
      for (const size_t index : part) in_core[index] = 1;
      for (size_t j = 0; j < num_images; ++j) {
        if (in_core[j]) {
          entry.members.push_back(j);
          continue;
        }
        for (const size_t index : part) {
          if (((*positions)[j] - (*positions)[index]).squaredNorm() <= overlap2) {
            entry.members.push_back(j);
            break;
          }
        }
      }
      entry.core = std::move(part);
      plan.chunks.push_back(std::move(entry));
    }
    return plan;
  }
  plan.method = "sequence";
  for (size_t begin = 0; begin < num_images; begin += options.chunk_size) {
    const size_t end = std::min(num_images, begin + options.chunk_size);
    ChunkPlanEntry entry;
    for (size_t i = begin; i < end; ++i) entry.core.push_back(i);
    const size_t first = begin >= options.overlap_photos ? begin - options.overlap_photos : 0;
    const size_t last = std::min(num_images, end + options.overlap_photos);
    for (size_t i = first; i < last; ++i) entry.members.push_back(i);
    plan.chunks.push_back(std::move(entry));
  }
  return plan;
}

ChunkPlan PlanChunksByRetrieval(const std::vector<std::vector<float>>& descriptors,
                                const ChunkingOptions& options) {
  options.Check();
  const size_t n = descriptors.size();
  if (n == 0) throw InvalidArgumentError("no photos to cut into chunks");
  // Cosine similarities of every pair (a zero descriptor, a photo without features, is similar
  // to nothing).
  Eigen::MatrixXf similarity;
  try {
    similarity = features::CosineSimilarities(descriptors);
  } catch (const InvalidArgumentError& error) {
    throw InvalidArgumentError(std::string("PlanChunksByRetrieval: ") + error.what());
  }
  const auto sim = [&](size_t a, size_t b) {
    return similarity(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(b));
  };

  // Seeds by farthest-point sampling; the growth's room: 0.85 of the chunk size on average.
  const size_t num_chunks =
      std::min(n, static_cast<size_t>(std::ceil(static_cast<double>(n) /
                                                (0.85 * static_cast<double>(options.chunk_size)))));
  std::vector<size_t> seeds;
  std::vector<float> closest_seed(n, -std::numeric_limits<float>::infinity());
  {
    size_t first = 0;
    double lowest = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < n; ++i) {
      const double total = similarity.col(static_cast<Eigen::Index>(i)).cast<double>().sum();
      if (total < lowest) {
        lowest = total;
        first = i;
      }
    }
    seeds.push_back(first);
  }
  std::vector<char> is_seed(n, 0);
  is_seed[seeds[0]] = 1;
  while (seeds.size() < num_chunks) {
    for (size_t i = 0; i < n; ++i)
      closest_seed[i] = std::max(closest_seed[i], sim(i, seeds.back()));
    size_t next = n;
    for (size_t i = 0; i < n; ++i) {
      if (!is_seed[i] && (next == n || closest_seed[i] < closest_seed[next])) next = i;
    }
    seeds.push_back(next);
    is_seed[next] = 1;
  }

  // Each photo's links: its most similar photos.
  std::vector<std::vector<size_t>> links =
      features::MostSimilar(similarity, options.retrieval_neighbours);
  // Only mutual links are followed: a photo that merely resembles another (repeated parked cars,
  // façades) is rarely among that photo's most similar ones in turn.
  std::vector<std::vector<size_t>> mutual(n);
  for (size_t i = 0; i < n; ++i) {
    for (const size_t j : links[i]) {
      if (std::find(links[j].begin(), links[j].end(), i) != links[j].end()) mutual[i].push_back(j);
    }
  }
  links = std::move(mutual);

  // Balanced growth along the links from the seeds: the smallest chunk that can still grow takes
  // its most similar linked photo (so that the chunks grow like the cells around their seeds, and
  // none runs ahead into the others' ground). Photos no link reaches (a group of photos similar
  // only among themselves, or whose links all lead into full chunks) join the chunk with room
  // that holds their most similar photo.
  constexpr size_t kNone = std::numeric_limits<size_t>::max();
  using Candidate = std::pair<float, size_t>;  // similarity, photo
  const auto later = [](const Candidate& a, const Candidate& b) {
    return a.first != b.first ? a.first < b.first : a.second > b.second;
  };
  using Queue = std::priority_queue<Candidate, std::vector<Candidate>, decltype(later)>;
  const auto grow_from = [&](const std::vector<size_t>& from) {
    std::vector<size_t> owner(n, kNone);
    std::vector<size_t> sizes(num_chunks, 0);
    std::vector<Queue> queues(num_chunks, Queue(later));
    const auto take = [&](size_t photo, size_t chunk) {
      owner[photo] = chunk;
      ++sizes[chunk];
      for (const size_t next : links[photo]) {
        if (owner[next] == kNone) queues[chunk].push({sim(photo, next), next});
      }
    };
    for (size_t c = 0; c < num_chunks; ++c) take(from[c], c);
    while (true) {
      size_t grow = kNone;
      for (size_t c = 0; c < num_chunks; ++c) {
        while (!queues[c].empty() && owner[queues[c].top().second] != kNone) queues[c].pop();
        if (queues[c].empty() || sizes[c] >= options.chunk_size) continue;
        if (grow == kNone || sizes[c] < sizes[grow]) grow = c;
      }
      if (grow == kNone) break;
      const size_t photo = queues[grow].top().second;
      queues[grow].pop();
      take(photo, grow);
    }
    for (size_t i = 0; i < n; ++i) {
      if (owner[i] != kNone) continue;
      size_t best_chunk = kNone;
      float best = -std::numeric_limits<float>::infinity();
      for (size_t j = 0; j < n; ++j) {
        if (owner[j] == kNone || sizes[owner[j]] >= options.chunk_size) continue;
        if (sim(i, j) > best) {
          best = sim(i, j);
          best_chunk = owner[j];
        }
      }
      // The chunks have room for more than n photos together (num_chunks * chunk_size > n).
      assert(best_chunk != kNone);
      owner[i] = best_chunk;
      ++sizes[best_chunk];
    }
    return owner;
  };
  // Farthest-point seeds lie at the edges of the set, so the first cells are lopsided; each chunk
  // is then grown again from its medoid (the photo most similar to the rest of its chunk), a few
  // times, as Lloyd's iterations centre k-means cells.
  constexpr int kRecentring = 4;
  std::vector<size_t> owner = grow_from(seeds);
  for (int round = 0; round < kRecentring; ++round) {
    std::vector<std::vector<size_t>> cells(num_chunks);
    for (size_t i = 0; i < n; ++i) cells[owner[i]].push_back(i);
    std::vector<size_t> medoids(num_chunks);
    for (size_t c = 0; c < num_chunks; ++c) {
      double best = -std::numeric_limits<double>::infinity();
      for (const size_t i : cells[c]) {
        double total = 0.0;
        for (const size_t j : cells[c]) total += sim(i, j);
        if (total > best) {
          best = total;
          medoids[c] = i;
        }
      }
    }
    if (medoids == seeds) break;
    seeds = medoids;
    owner = grow_from(seeds);
  }

  ChunkPlan plan;
  plan.method = "retrieval";
  const size_t overlap = std::min(2 * options.overlap_photos, n);
  for (size_t c = 0; c < num_chunks; ++c) {
    ChunkPlanEntry entry;
    for (size_t i = 0; i < n; ++i) {
      if (owner[i] == c) entry.core.push_back(i);
    }
    if (entry.core.empty()) continue;
    std::vector<std::pair<float, size_t>> outside;
    for (size_t j = 0; j < n; ++j) {
      if (owner[j] == c) continue;
      float best = -std::numeric_limits<float>::infinity();
      for (const size_t i : entry.core) best = std::max(best, sim(i, j));
      outside.emplace_back(-best, j);
    }
    const size_t joining = std::min(overlap, outside.size());
    std::partial_sort(outside.begin(), outside.begin() + static_cast<std::ptrdiff_t>(joining),
                      outside.end());
    entry.members = entry.core;
    for (size_t m = 0; m < joining; ++m) entry.members.push_back(outside[m].second);
    std::sort(entry.members.begin(), entry.members.end());
    plan.chunks.push_back(std::move(entry));
  }
  // Deterministic order: by the first photo.
  std::sort(plan.chunks.begin(), plan.chunks.end(),
            [](const auto& a, const auto& b) { return a.core.front() < b.core.front(); });
  return plan;
}

uint64_t EstimatedChunkPeakBytes(size_t num_photos, int width, int height) {
  // Fitted to the peak RSS of chunk builds of car-park survey photos (docs/mapper.md, "Memory"):
  // at 640 x 480, 27 photos peaked at 226 MB and 146 photos at 839 MB, 5.2 MB (17 bytes per pixel)
  // per photo: the semi-dense frames of the chunk's photos (image, gradients), kept for the whole
  // depth stage; COLMAP's processes stayed at 117 MB. A margin on both parts.
  const double pixels = static_cast<double>(width) * height;
  const double per_photo = 20.0 * pixels;  // bytes per photo
  const double fixed = 160.0 * (1 << 20);
  return static_cast<uint64_t>(fixed + per_photo * static_cast<double>(num_photos));
}

std::map<std::string, Rigid3d> ParseChunkPoses(std::string_view text, const std::string& source) {
  std::map<std::string, Rigid3d> poses;
  ForEachDataLine(text, [&](int64_t number, const std::string& line) {
    const size_t start = line.find_first_not_of(" \t");
    const size_t space = line.find_first_of(" \t", start);
    if (space == std::string::npos) {
      throw ParseError::AtLine(source, number, "expected IMAGE_NAME tx ty tz qx qy qz qw");
    }
    const std::string name = line.substr(start, space - start);
    try {
      const Rigid3d pose = ParsePoseText("pose", std::string_view(line).substr(space + 1));
      if (!poses.emplace(name, pose).second) {
        throw InvalidArgumentError("image " + name + " appears twice");
      }
    } catch (const InvalidArgumentError& error) {
      throw ParseError::AtLine(source, number, error.what());
    }
  });
  return poses;
}

std::string ChunkPlanToJson(const ChunkPlan& plan, const std::vector<std::string>& names,
                            const std::string& inputs) {
  nlohmann::json json;
  json["method"] = plan.method;
  json["inputs"] = inputs;
  json["chunks"] = nlohmann::json::array();
  for (const ChunkPlanEntry& entry : plan.chunks) {
    std::vector<std::string> core;
    std::vector<std::string> members;
    for (const size_t i : entry.core) core.push_back(names.at(i));
    for (const size_t i : entry.members) members.push_back(names.at(i));
    json["chunks"].push_back({{"core", core}, {"members", members}});
  }
  return json.dump(1) + "\n";
}

StoredChunkPlan ParseChunkPlan(std::string_view text, const std::vector<std::string>& names,
                               const std::string& source) {
  const auto fail = [&](const std::string& what) { return ParseError(source, "plan", what); };
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& error) {
    throw ParseError(source, "byte " + std::to_string(error.byte), "not JSON");
  } catch (const nlohmann::json::exception& error) {
    // A number beyond double's range throws out_of_range (found by evloc_chunk_plan_fuzzer).
    throw ParseError(source, "plan", std::string("not JSON: ") + error.what());
  }
  if (!json.is_object() || !json.contains("method") || !json["method"].is_string() ||
      !json.contains("inputs") || !json["inputs"].is_string() || !json.contains("chunks") ||
      !json["chunks"].is_array()) {
    throw fail("expected an object with the strings method and inputs and the array chunks");
  }
  std::map<std::string, size_t> index;
  for (size_t i = 0; i < names.size(); ++i) index.emplace(names[i], i);
  StoredChunkPlan stored;
  stored.plan.method = json["method"].get<std::string>();
  stored.inputs = json["inputs"].get<std::string>();
  std::vector<int> owners(names.size(), 0);
  const auto indices = [&](const nlohmann::json& list, size_t chunk, const char* field) {
    if (!list.is_array()) {
      throw fail("chunk " + std::to_string(chunk) + ": " + field + " is not an array");
    }
    std::vector<size_t> result;
    for (const nlohmann::json& name : list) {
      if (!name.is_string()) {
        throw fail("chunk " + std::to_string(chunk) + ": " + field + " holds a non-string");
      }
      const auto found = index.find(name.get<std::string>());
      if (found == index.end()) {
        throw fail("chunk " + std::to_string(chunk) + ": " + name.get<std::string>() +
                   " is not an input photo");
      }
      result.push_back(found->second);
    }
    std::sort(result.begin(), result.end());
    if (std::adjacent_find(result.begin(), result.end()) != result.end()) {
      throw fail("chunk " + std::to_string(chunk) + ": a photo appears twice in " + field);
    }
    return result;
  };
  for (const nlohmann::json& chunk : json["chunks"]) {
    const size_t number = stored.plan.chunks.size();
    if (!chunk.is_object() || !chunk.contains("core") || !chunk.contains("members")) {
      throw fail("chunk " + std::to_string(number) + ": expected core and members");
    }
    ChunkPlanEntry entry;
    entry.core = indices(chunk["core"], number, "core");
    entry.members = indices(chunk["members"], number, "members");
    if (entry.core.empty()) throw fail("chunk " + std::to_string(number) + " has no core photo");
    if (!std::includes(entry.members.begin(), entry.members.end(), entry.core.begin(),
                       entry.core.end())) {
      throw fail("chunk " + std::to_string(number) + ": a core photo is not a member");
    }
    for (const size_t i : entry.core) {
      if (++owners[i] > 1) throw fail(names[i] + " is in two chunks' cores");
    }
    stored.plan.chunks.push_back(std::move(entry));
  }
  for (size_t i = 0; i < names.size(); ++i) {
    if (owners[i] == 0) throw fail(names[i] + " is in no chunk's core");
  }
  return stored;
}

std::string ChunkFolderName(size_t index) {
  std::ostringstream text;
  text << "chunk_" << std::setw(4) << std::setfill('0') << index;
  return text.str();
}

ChunkResult ReadChunkResult(const fs::path& directory) {
  ChunkResult result;
  result.map = LoadMap(directory / kChunkMapFile);
  result.world_from_cams = ParseChunkPoses(ReadFileToString(directory / kChunkPosesFile),
                                           (directory / kChunkPosesFile).string());
  result.inputs_fingerprint = RecordedFingerprint(directory);
  if (result.inputs_fingerprint.empty()) {
    throw ParseError((directory / kChunkInputsFile).string(), "byte 0",
                     "missing or empty: the chunk did not finish");
  }
  for (const Keyframe& keyframe : result.map.keyframes) {
    if (!result.world_from_cams.contains(keyframe.image_name)) {
      throw ParseError((directory / kChunkPosesFile).string(), "line 0",
                       "keyframe image " + keyframe.image_name + " of map.evmap has no pose");
    }
  }
  return result;
}

ChunkAlignment AlignChunks(const std::vector<std::map<std::string, Rigid3d>>& chunk_poses) {
  const size_t count = chunk_poses.size();
  ChunkAlignment result;
  result.common_from_chunk.assign(count, Sim3d());
  if (count <= 1) return result;
  // Shared photos per pair.
  std::vector<std::vector<std::vector<std::string>>> shared(
      count, std::vector<std::vector<std::string>>(count));
  for (size_t a = 0; a < count; ++a) {
    for (size_t b = a + 1; b < count; ++b) {
      for (const auto& [name, pose] : chunk_poses[a]) {
        if (chunk_poses[b].contains(name)) shared[a][b].push_back(name);
      }
      shared[b][a] = shared[a][b];
      if (shared[a][b].size() >= 3) ++result.num_linked_pairs;
    }
  }
  // Breadth first from chunk 0, each chunk aligned to its best-linked aligned neighbour.
  std::vector<char> aligned(count, 0);
  aligned[0] = 1;
  std::vector<double> weights;
  std::vector<double> centre_rms;
  for (size_t round = 1; round < count; ++round) {
    size_t best_chunk = count;
    size_t best_neighbour = count;
    size_t best_shared = 0;
    for (size_t c = 0; c < count; ++c) {
      if (aligned[c]) continue;
      for (size_t n = 0; n < count; ++n) {
        if (!aligned[n] || shared[c][n].size() < 3) continue;
        if (shared[c][n].size() > best_shared) {
          best_shared = shared[c][n].size();
          best_chunk = c;
          best_neighbour = n;
        }
      }
    }
    if (best_chunk == count) {
      std::string list;
      for (size_t c = 0; c < count; ++c) {
        if (!aligned[c]) list += (list.empty() ? "" : ", ") + std::to_string(c);
      }
      throw InvalidArgumentError(
          "chunks " + list +
          " share fewer than 3 registered photos with the others and cannot be aligned; raise "
          "--chunk-overlap (or give --known-poses)");
    }
    std::vector<Rigid3d> model;
    std::vector<Rigid3d> reference;
    for (const std::string& name : shared[best_chunk][best_neighbour]) {
      model.push_back(chunk_poses[best_chunk].at(name));
      reference.push_back(result.common_from_chunk[best_neighbour].TransformPose(
          chunk_poses[best_neighbour].at(name)));
    }
    const PoseAlignment alignment = AlignPoses(model, reference);
    result.common_from_chunk[best_chunk] = alignment.reference_from_model;
    weights.push_back(alignment.orientation_weight);
    centre_rms.push_back(alignment.centre_rms);
    aligned[best_chunk] = 1;
  }
  result.initial_rms = SharedPhotoSpread(chunk_poses, result.common_from_chunk).first;

  // Global adjustment.
  std::sort(weights.begin(), weights.end());
  std::sort(centre_rms.begin(), centre_rms.end());
  const double rotation_weight = std::sqrt(std::max(weights[weights.size() / 2], 1e-12));
  const double huber = std::max(3.0 * centre_rms[centre_rms.size() / 2], 1e-9);
  std::vector<std::array<double, 7>> parameters(count);
  for (size_t c = 0; c < count; ++c) parameters[c] = ParametersFromSim(result.common_from_chunk[c]);
  ceres::Problem problem;
  for (size_t a = 0; a < count; ++a) {
    for (size_t b = a + 1; b < count; ++b) {
      if (shared[a][b].size() < 3) continue;
      for (const std::string& name : shared[a][b]) {
        const Rigid3d& pose_a = chunk_poses[a].at(name);
        const Rigid3d& pose_b = chunk_poses[b].at(name);
        problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<SharedPhotoResidual, 6, 7, 7>(
                new SharedPhotoResidual(pose_a.translation, pose_a.rotation, pose_b.translation,
                                        pose_b.rotation, rotation_weight)),
            new ceres::HuberLoss(huber), parameters[a].data(), parameters[b].data());
        ++result.num_shared_observations;
      }
    }
  }
  problem.SetParameterBlockConstant(parameters[0].data());
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  solver_options.max_num_iterations = 100;
  solver_options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  if (summary.IsSolutionUsable()) {
    for (size_t c = 0; c < count; ++c)
      result.common_from_chunk[c] = SimFromParameters(parameters[c]);
  }
  const auto [rms, largest] = SharedPhotoSpread(chunk_poses, result.common_from_chunk);
  result.adjusted_rms = rms;
  result.adjusted_max = largest;
  return result;
}

std::vector<ChunkReferenceFit> FitChunksToReference(
    const std::vector<std::map<std::string, Rigid3d>>& chunk_poses,
    const std::map<std::string, Rigid3d>& reference, const AlignmentLimits& limits) {
  std::vector<ChunkReferenceFit> fits;
  for (const std::map<std::string, Rigid3d>& poses : chunk_poses) {
    const PosesWithReference matched = MatchReference(poses, reference);
    ChunkReferenceFit fit;
    if (matched.model.size() >= 3) {
      try {
        const PoseAlignment alignment = AlignPoses(matched.model, matched.reference);
        fit.centre_rms = alignment.centre_rms;
        fit.fits = !AlignmentLimitViolation(alignment, limits);
      } catch (const InvalidArgumentError&) {
        // Coincident centres: no scale, no figure.
      }
    }
    fits.push_back(fit);
  }
  return fits;
}

std::string ChunkedBuildReportToJson(const ChunkedBuildReport& report) {
  nlohmann::json json = nlohmann::json::parse(MapBuildReportToJson(report.build));
  nlohmann::json chunks = nlohmann::json::array();
  for (size_t c = 0; c < report.chunk_sizes.size(); ++c) {
    chunks.push_back(
        {{"index", c},
         {"core_photos", report.chunk_sizes[c].first},
         {"photos", report.chunk_sizes[c].second},
         {"peak_rss_mb", c < report.chunk_peak_rss_bytes.size()
                             ? static_cast<double>(report.chunk_peak_rss_bytes[c]) / (1 << 20)
                             : 0.0},
         {"seconds", c < report.chunk_seconds.size() ? report.chunk_seconds[c] : 0.0}});
    if (c < report.chunk_reference_rms_m.size() && std::isfinite(report.chunk_reference_rms_m[c])) {
      chunks.back()["reference_rms_m"] = report.chunk_reference_rms_m[c];
      chunks.back()["fits_reference"] = report.chunk_fits_reference[c] != 0;
    }
  }
  json["chunking"] = {{"method", report.method},
                      {"chunks", chunks},
                      {"computed", report.computed_chunks},
                      {"reused", report.reused_chunks}};
  if (report.alignment) {
    json["chunk_alignment"] = {{"linked_pairs", report.alignment->num_linked_pairs},
                               {"shared_observations", report.alignment->num_shared_observations},
                               {"initial_rms", report.alignment->initial_rms},
                               {"adjusted_rms", report.alignment->adjusted_rms},
                               {"adjusted_max", report.alignment->adjusted_max}};
  } else {
    json["chunk_alignment"] = nullptr;
  }
  json["site"] = {{"tiles", report.num_tiles}, {"version", report.site_version}};
  return json.dump(2) + "\n";
}

ChunkedBuildReport BuildChunkedSite(const ChunkedBuildOptions& options,
                                    ProgressListener* progress) {
  options.Check();
  ChunkedBuildReport report;
  MapBuildReport& build = report.build;
  const StageClock clock(progress, &build);
  const BuildInputs inputs = LoadInputs(options.build);
  build.num_images = inputs.num_images;
  build.images_without_pose = inputs.images_without_pose;
  build.calibration_notes = inputs.calibration_notes;
  build.pose_source = options.build.known_poses ? "known" : "estimated";

  // The plan.
  ChunkPlan plan;
  const fs::path workspace = ChunkWorkspace(options);
  std::vector<std::string> names;
  for (const InputImage& image : inputs.images) names.push_back(image.name);
  const std::string plan_inputs = PlanInputsFingerprint(options, inputs);
  clock.Run("chunk_plan", [&] {
    const std::optional<std::vector<Eigen::Vector3d>> positions = PlanPositions(inputs);
    const bool timed = std::all_of(inputs.images.begin(), inputs.images.end(),
                                   [](const InputImage& image) { return image.has_time; });
    ChunkMethod method = options.chunking.method;
    if (method == ChunkMethod::kAuto) {
      method = positions ? ChunkMethod::kPosition
                         : (timed ? ChunkMethod::kSequence : ChunkMethod::kRetrieval);
    }
    if (method == ChunkMethod::kPosition && !positions) {
      throw InvalidArgumentError(
          "--chunk-by position needs every photo's position (--known-poses, or --align-to "
          "reference poses naming every photo)");
    }
    if (method == ChunkMethod::kSequence && !timed) {
      throw InvalidArgumentError(
          "--chunk-by sequence needs a timed sequence (--images-list with a time per photo)");
    }
    if (method == ChunkMethod::kRetrieval) {
      // The descriptors cost a feature extraction per photo: a plan this workspace already holds
      // for the same photos and options (written by the process that started the build, read by
      // its workers, a restart and an Indexed Job's pods) is taken as it is.
      const std::optional<ChunkPlan> stored =
          StoredRetrievalPlan(workspace / kPlanFile, names, plan_inputs);
      plan = stored
                 ? *stored
                 : PlanChunksByRetrieval(RetrievalDescriptors(options, inputs), options.chunking);
      return stored.has_value();
    }
    plan = PlanChunks(inputs.images.size(),
                      method == ChunkMethod::kPosition ? &*positions : nullptr, options.chunking);
    return false;
  });
  report.method = plan.method;
  for (const ChunkPlanEntry& entry : plan.chunks) {
    report.chunk_sizes.emplace_back(entry.core.size(), entry.members.size());
  }

  // The memory budget: every chunk must fit, and the workers share it.
  int workers = options.workers;
  const cv::Mat first =
      ReadImage(options.build.image_dir / inputs.images[0].name, cv::IMREAD_UNCHANGED);
  if (options.memory_budget_bytes) {
    uint64_t largest = 0;
    size_t largest_chunk = 0;
    for (size_t c = 0; c < plan.chunks.size(); ++c) {
      const uint64_t estimate =
          EstimatedChunkPeakBytes(plan.chunks[c].members.size(), first.cols, first.rows);
      if (estimate > largest) {
        largest = estimate;
        largest_chunk = c;
      }
    }
    if (largest > *options.memory_budget_bytes) {
      size_t fitting = options.chunking.chunk_size;
      while (fitting > 8 &&
             EstimatedChunkPeakBytes(fitting + (plan.chunks[largest_chunk].members.size() -
                                                plan.chunks[largest_chunk].core.size()),
                                     first.cols, first.rows) > *options.memory_budget_bytes) {
        fitting = fitting * 9 / 10;
      }
      throw InvalidArgumentError(
          "chunk " + std::to_string(largest_chunk) + " (" +
          std::to_string(plan.chunks[largest_chunk].members.size()) + " photos with its overlap, " +
          std::to_string(first.cols) + " x " + std::to_string(first.rows) + ") needs about " +
          FormatGigabytes(largest) + " at its peak, more than --memory-budget " +
          FormatGigabytes(*options.memory_budget_bytes) +
          "; nothing was computed. Use a smaller --chunk-size (about " + std::to_string(fitting) +
          " fits) or a larger budget (docs/mapper.md, \"Memory\")");
    }
    const int fit = static_cast<int>(*options.memory_budget_bytes / std::max<uint64_t>(largest, 1));
    workers = std::max(1, std::min(workers, fit));
  }

  // The chunks.
  std::error_code error;
  fs::create_directories(workspace, error);
  if (error)
    throw IoError("cannot create the chunk workspace " + workspace.string() + ": " +
                  error.message());
  WriteFileAtomically(workspace / kPlanFile, ChunkPlanToJson(plan, names, plan_inputs));
  if (options.plan_only) return report;
  std::string colmap_version;
  clock.Run("chunk_fingerprints", [&] {
    colmap_version = ColmapVersion(options.build.colmap);
    return false;
  });
  std::vector<std::string> fingerprints(plan.chunks.size());
  const auto fingerprint_of = [&](size_t c) -> const std::string& {
    if (fingerprints[c].empty()) {
      const MapBuilderOptions chunk_options = ChunkBuildOptions(options, plan, workspace, c);
      const ChunkInputs chunk = SelectChunkInputs(inputs, plan.chunks[c], chunk_options.output_dir);
      fingerprints[c] = ChunkFingerprint(chunk_options, chunk.inputs.images, chunk.core,
                                         inputs.camera, colmap_version);
    }
    return fingerprints[c];
  };
  const auto finished = [&](size_t c) {
    return RecordedFingerprint(workspace / ChunkFolderName(c)) == fingerprint_of(c);
  };
  if (options.only_chunk) {
    const size_t c = *options.only_chunk;
    if (c >= plan.chunks.size()) {
      throw InvalidArgumentError("--chunk-index " + std::to_string(c) + ": the plan has " +
                                 std::to_string(plan.chunks.size()) + " chunks (0 to " +
                                 std::to_string(plan.chunks.size() - 1) + ")");
    }
    if (finished(c)) {
      report.reused_chunks.push_back(c);
    } else {
      ComputeChunk(options, inputs, plan, c, workspace, fingerprint_of(c), progress);
      report.computed_chunks.push_back(c);
    }
    return report;
  }
  std::vector<size_t> missing;
  clock.Run("chunks", [&] {
    for (size_t c = 0; c < plan.chunks.size(); ++c) {
      if (finished(c)) {
        report.reused_chunks.push_back(c);
      } else {
        missing.push_back(c);
      }
    }
    if (options.merge_only) {
      if (!missing.empty()) {
        std::string list;
        for (const size_t c : missing) list += (list.empty() ? "" : ", ") + std::to_string(c);
        throw InvalidArgumentError(
            "--merge-only: chunks " + list + " of " + std::to_string(plan.chunks.size()) +
            " are not finished in " + workspace.string() +
            " (or were made from other inputs); run them first (--chunk-index K)");
      }
      return true;
    }
    if (options.worker_command.empty()) {
      for (const size_t c : missing) {
        clock.Progress("chunks", report.computed_chunks.size(), missing.size());
        ComputeChunk(options, inputs, plan, c, workspace, fingerprint_of(c), nullptr);
        report.computed_chunks.push_back(c);
      }
      return missing.empty();
    }
    // Worker processes, `workers` at a time; a failed chunk fails the build after the others end.
    fs::create_directories(workspace / "logs", error);
    std::atomic<size_t> next{0};
    std::mutex mutex;
    std::vector<std::string> failures;
    std::vector<std::thread> threads;
    for (int w = 0; w < std::min<int>(workers, static_cast<int>(missing.size())); ++w) {
      threads.emplace_back([&] {
        for (size_t i = next++; i < missing.size(); i = next++) {
          const size_t c = missing[i];
          std::vector<std::string> command = options.worker_command;
          command.push_back("--chunk-index");
          command.push_back(std::to_string(c));
          try {
            RunLoggedCommand(command, workspace / "logs" / (ChunkFolderName(c) + ".log"));
            std::lock_guard<std::mutex> lock(mutex);
            report.computed_chunks.push_back(c);
            clock.Progress("chunks", report.computed_chunks.size(), missing.size());
          } catch (const std::exception& failure) {
            std::lock_guard<std::mutex> lock(mutex);
            failures.push_back("chunk " + std::to_string(c) + ": " + failure.what());
          }
        }
      });
    }
    for (std::thread& thread : threads) thread.join();
    if (!failures.empty()) throw IoError(failures.front());
    std::sort(report.computed_chunks.begin(), report.computed_chunks.end());
    for (const size_t c : missing) {
      if (!finished(c)) {
        throw IoError("the worker of chunk " + std::to_string(c) +
                      " ended without its result; see " +
                      (workspace / "logs" / (ChunkFolderName(c) + ".log")).string());
      }
    }
    return missing.empty();
  });

  // Alignment and merge.
  std::vector<ChunkResult> chunks;
  clock.Run("chunk_read", [&] {
    for (size_t c = 0; c < plan.chunks.size(); ++c) {
      chunks.push_back(ReadChunkResult(workspace / ChunkFolderName(c)));
      const auto [peak, seconds] = ChunkReportFigures(workspace / ChunkFolderName(c));
      report.chunk_peak_rss_bytes.push_back(peak);
      report.chunk_seconds.push_back(seconds);
    }
    return false;
  });
  std::vector<Sim3d> common_from_chunk(chunks.size());
  if (!options.build.known_poses) {
    clock.Run("chunk_alignment", [&] {
      std::vector<std::map<std::string, Rigid3d>> poses;
      for (const ChunkResult& chunk : chunks) poses.push_back(chunk.world_from_cams);
      report.alignment = AlignChunks(poses);
      common_from_chunk = report.alignment->common_from_chunk;
      return false;
    });
  }
  // Each photo's pose from the chunk that owns it (or, when that chunk did not register it, from
  // the first that did).
  std::map<std::string, Rigid3d> common_from_cams;
  for (size_t c = 0; c < chunks.size(); ++c) {
    for (const size_t i : plan.chunks[c].core) {
      const auto pose = chunks[c].world_from_cams.find(inputs.images[i].name);
      if (pose != chunks[c].world_from_cams.end()) {
        common_from_cams[pose->first] = common_from_chunk[c].TransformPose(pose->second);
      }
    }
  }
  for (size_t c = 0; c < chunks.size(); ++c) {
    for (const auto& [name, pose] : chunks[c].world_from_cams) {
      if (!common_from_cams.contains(name)) {
        common_from_cams[name] = common_from_chunk[c].TransformPose(pose);
      }
    }
  }
  build.num_registered = common_from_cams.size();
  // --align-to: the merged model onto the reference poses (the map in the reference frame).
  Sim3d world_from_common;
  if (options.build.align_to) {
    clock.Run("alignment", [&] {
      // Each chunk on its own against the reference: which reconstructions are wrong.
      std::vector<std::map<std::string, Rigid3d>> poses;
      for (const ChunkResult& chunk : chunks) poses.push_back(chunk.world_from_cams);
      std::string misfits;
      const std::vector<ChunkReferenceFit> fits = FitChunksToReference(
          poses, inputs.reference_world_from_cams, options.build.alignment_limits);
      for (size_t c = 0; c < fits.size(); ++c) {
        report.chunk_reference_rms_m.push_back(fits[c].centre_rms);
        report.chunk_fits_reference.push_back(fits[c].fits ? 1 : 0);
        if (std::isfinite(fits[c].centre_rms) && !fits[c].fits) {
          std::ostringstream text;
          text << (misfits.empty() ? "" : ", ") << c << " (" << std::setprecision(3)
               << fits[c].centre_rms << " m RMS)";
          misfits += text.str();
        }
      }
      std::string likely_cause = "The chunks' models or their alignment are probably wrong";
      if (!misfits.empty()) {
        likely_cause += " (these chunks do not fit the reference on their own either: " + misfits +
                        "; COLMAP reconstructed them wrongly: smaller chunks (--chunk-size), more "
                        "overlapping photos or more texture help)";
      }
      const PosesWithReference matched =
          MatchReference(common_from_cams, inputs.reference_world_from_cams);
      if (matched.model.size() < 3) {
        throw InvalidArgumentError("only " + std::to_string(matched.model.size()) +
                                   " registered photos have a reference pose in " +
                                   options.build.align_to->string() + "; the alignment needs 3");
      }
      world_from_common = FitAlignmentToReference(options.build, matched.model, matched.reference,
                                                  likely_cause, &build);
      return false;
    });
  }
  for (const auto& [name, pose] : common_from_cams) {
    build.world_from_cams[name] = world_from_common.TransformPose(pose);
  }

  Map map;
  clock.Run("merge", [&] {
    std::vector<CandidatePoint> candidates;
    for (size_t c = 0; c < chunks.size(); ++c) {
      AppendChunk(chunks[c].map, Compose(world_from_common, common_from_chunk[c]), &map,
                  &candidates);
      build.num_keyframe_points += chunks[c].map.size();
      chunks[c].map = Map();  // Free it.
    }
    build.num_keyframes = map.keyframes.size();
    // The chunks removed their outliers; across chunks only duplicates of the overlap merge.
    MapMergeOptions merge = options.build.merge;
    merge.outlier_neighbours = 0;
    const MergeStatistics statistics = MergePoints(candidates, merge, &map);
    build.voxel_size = statistics.voxel_size;
    build.num_points = map.size();
    return false;
  });
  if (map.size() == 0) throw InvalidArgumentError("the chunks hold no map points");
  map.provenance.tool = "evloc-mapper build --chunked";
  map.provenance.tool_version = ToolVersion();
  map.provenance.created_utc = UtcNowIso8601();
  map.provenance.command_line = options.build.command_line;
  map.provenance.inputs.push_back(fs::absolute(options.build.image_dir).string());
  for (const auto& input : {options.build.image_list, options.build.calibration_file,
                            options.build.known_poses, options.build.align_to}) {
    if (input) map.provenance.inputs.push_back(fs::absolute(*input).string());
  }
  AddRelocalizationData(options.build, clock, &map, &build);
  if (options.build.geo.Any()) {
    GeoReferenceResult geo = GeoReferenceMap(map, options.build.image_dir, options.build.geo);
    map.geo_anchor = geo.anchor;
    build.geo_anchor = geo.anchor;
    build.geo_alignment = std::move(geo.alignment);
    build.geo_inputs = geo.inputs;
  }
  clock.Run("site", [&] {
    TilingOptions tiling;
    tiling.tile_size_m = options.tile_size_m;
    tiling.overlap_m = options.tile_overlap_m;
    tiling.command_line = options.build.command_line;
    const fs::path site = fs::absolute(options.build.output_dir).lexically_normal();
    const SiteManifest manifest = TileMap(map, site, tiling);
    report.num_tiles = manifest.tiles.size();
    report.site_version = manifest.version;
    report.site_written = true;
    return false;
  });
  WriteFileAtomically(fs::absolute(options.build.output_dir) / "report.json",
                      ChunkedBuildReportToJson(report));
  return report;
}

}  // namespace evloc::mapper
