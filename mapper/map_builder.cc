#include "mapper/map_builder.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <fstream>
#include <functional>
#include <iomanip>
#include <numbers>
#include <set>
#include <span>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/dataset/dataset.h"
#include "core/dataset/pose_text.h"
#include "core/trajectory/trajectory.h"
#include "core/trajectory/tum_io.h"
#include "mapper/colmap_model.h"
#include "mapper/pose_alignment.h"
#include "maps/map_directory.h"

#ifndef EVLOC_VERSION
#define EVLOC_VERSION "unknown"
#endif

namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const std::set<std::string> kImageExtensions = {".png",  ".jpg", ".jpeg", ".bmp", ".tif",
                                                ".tiff", ".pgm", ".ppm",  ".pnm"};

std::string Lowercase(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

std::vector<std::string> Tokenize(const std::string& line) {
  std::string cleaned = line;
  std::replace(cleaned.begin(), cleaned.end(), ',', ' ');
  std::replace(cleaned.begin(), cleaned.end(), '\t', ' ');
  std::istringstream stream(cleaned);
  std::vector<std::string> tokens;
  std::string token;
  while (stream >> token) tokens.push_back(token);
  return tokens;
}

// True when the first data line of a pose file starts with a time (TUM layout) rather than an
// image name.
bool IsTimeKeyedPoseText(const std::string& text) {
  std::istringstream stream(text);
  std::string line;
  while (std::getline(stream, line)) {
    const std::vector<std::string> tokens = Tokenize(line);
    if (tokens.empty() || tokens[0][0] == '#' || tokens[0] == "timestamp") continue;
    try {
      ParseSecondsAsNanoseconds(tokens[0]);
      return true;
    } catch (const InvalidArgumentError&) {
      return false;
    }
  }
  return false;
}

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  std::ostringstream text;
  text << std::put_time(&utc, "%Y-%m-%dT%H:%M:%SZ");
  return text.str();
}

// CPU seconds (user + system) used so far by this process and its waited-for children.
double ProcessCpuSeconds() {
  double total = 0.0;
  for (const int who : {RUSAGE_SELF, RUSAGE_CHILDREN}) {
    rusage usage{};
    if (getrusage(who, &usage) != 0) continue;
    total += static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
             1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
  }
  return total;
}

// Runs a stage, timing it and reporting progress.
class StageClock {
 public:
  StageClock(ProgressListener* listener, MapBuildReport* report)
      : listener_(listener), report_(report), start_(Clock::now()) {}

  double Elapsed() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }
  void Progress(const std::string& stage, size_t done, size_t total) const {
    if (listener_ != nullptr) listener_->OnProgress({stage, done, total, Elapsed()});
  }
  // Times `body`; `body` returns true when it reused a cached result.
  void Run(const std::string& stage, const std::function<bool()>& body) const {
    Progress(stage, 0, 1);
    const Clock::time_point begin = Clock::now();
    const double cpu_begin = ProcessCpuSeconds();
    const bool reused = body();
    report_->timings.push_back({stage, std::chrono::duration<double>(Clock::now() - begin).count(),
                                ProcessCpuSeconds() - cpu_begin, reused});
    Progress(stage, 1, 1);
  }

 private:
  ProgressListener* listener_;
  MapBuildReport* report_;
  Clock::time_point start_;
};

// Fingerprint of the inputs that determine the COLMAP features and matches (the workspace's
// fingerprint.txt): images, camera, matcher, features.
std::string WorkspaceFingerprint(const MapBuilderOptions& options,
                                 const std::vector<InputImage>& images,
                                 const std::optional<Camera>& camera, MatcherType matcher) {
  std::ostringstream text;
  text << "evloc-mapper colmap workspace v2\n";
  text << "images " << fs::absolute(options.image_dir).lexically_normal().string() << "\n";
  for (const InputImage& image : images) {
    std::error_code error;
    text << image.name << " " << fs::file_size(options.image_dir / image.name, error) << "\n";
  }
  if (camera) {
    const ColmapCamera colmap_camera = ColmapCameraFromCamera(*camera, 1);
    text << "camera " << colmap_camera.model_name << " " << FormatColmapParams(colmap_camera.params)
         << "\n";
  } else {
    text << "camera estimated\n";
  }
  text << "matcher " << MatcherTypeName(matcher) << " overlap " << options.colmap.sequential_overlap
       << " features " << options.colmap.max_num_features << "\n";
  return text.str();
}

// Fingerprint of the model stage (mapper or triangulation) on top of the workspace's: its options
// and the known poses. Known and estimated poses keep separate models, so one workspace serves
// both without matching twice.
std::string ModelFingerprint(const MapBuilderOptions& options,
                             const std::string& workspace_fingerprint) {
  std::ostringstream text;
  text << workspace_fingerprint;
  // v3: the estimated model with fixed intrinsics is filtered and adjusted after mapping, once
  // per bound.
  text << "model v3 mapper " << options.colmap.abs_pose_min_num_inliers << " "
       << options.colmap.abs_pose_min_inlier_ratio << " " << options.colmap.min_num_matches
       << " refinement";
  for (const double bound : options.colmap.fixed_camera_refinement_px) text << " " << bound;
  text << "\n";
  if (options.known_poses) {
    text << "known poses\n" << ReadFileToString(*options.known_poses) << "\n";
  }
  return text.str();
}

bool MarkerMatches(const fs::path& marker, const std::string& fingerprint) {
  std::error_code error;
  if (!fs::exists(marker, error)) return false;
  return ReadFileToString(marker) == fingerprint;
}

// Prepares the workspace: a fresh folder, or a previous one of the same inputs (reused), or a
// previous one of other inputs (emptied). Refuses folders that are not mapper workspaces.
void PrepareWorkspace(const fs::path& workspace, const std::string& fingerprint) {
  std::error_code error;
  const fs::path fingerprint_file = workspace / "fingerprint.txt";
  if (fs::exists(workspace, error)) {
    if (!fs::is_directory(workspace, error)) {
      throw InvalidArgumentError("COLMAP workspace '" + workspace.string() +
                                 "' exists and is not a directory");
    }
    const bool is_empty = fs::is_empty(workspace, error);
    if (!is_empty && !fs::exists(fingerprint_file, error)) {
      throw InvalidArgumentError("COLMAP workspace '" + workspace.string() +
                                 "' is not empty and was not made by evloc-mapper; remove it or "
                                 "choose another with --colmap-workspace");
    }
    if (!is_empty && ReadFileToString(fingerprint_file) != fingerprint) {
      fs::remove_all(workspace, error);
      if (error) {
        throw IoError("cannot clear the stale COLMAP workspace " + workspace.string() + ": " +
                      error.message());
      }
    }
  }
  fs::create_directories(workspace, error);
  if (error) {
    throw IoError("cannot create the COLMAP workspace " + workspace.string() + ": " +
                  error.message());
  }
  WriteFileAtomically(fingerprint_file, fingerprint);
}

// Reads an image for the semi-dense stage or the preview; throws IoError when it cannot.
cv::Mat ReadImage(const fs::path& path, int flags) {
  cv::Mat image = cv::imread(path.string(), flags);
  if (image.empty()) throw IoError("cannot read image " + path.string());
  return image;
}

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

// The map drawn over a few keyframe images, points coloured by depth (near red, far blue).
cv::Mat RenderPreview(const Map& map, const fs::path& image_dir, int num_keyframes) {
  std::vector<size_t> chosen;
  const size_t count = std::min<size_t>(map.keyframes.size(), num_keyframes);
  for (size_t i = 0; i < count; ++i) {
    chosen.push_back(count == 1 ? 0 : i * (map.keyframes.size() - 1) / (count - 1));
  }
  std::vector<cv::Mat> tiles;
  for (const size_t index : chosen) {
    const Keyframe& keyframe = map.keyframes[index];
    cv::Mat image = ReadImage(image_dir / keyframe.image_name, cv::IMREAD_COLOR);
    cv::Mat gray;
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
    cv::cvtColor(gray, image, cv::COLOR_GRAY2BGR);
    const Camera& camera = map.cameras[keyframe.camera_index];
    std::vector<std::pair<Eigen::Vector2d, double>> projected;
    for (const uint32_t point : keyframe.visible_points) {
      const Eigen::Vector3d in_cam = keyframe.cam_from_world * map.positions[point].cast<double>();
      Eigen::Vector2d pixel;
      if (camera.Project(in_cam, &pixel) && camera.IsInside(pixel)) {
        projected.emplace_back(pixel, in_cam.z());
      }
    }
    if (!projected.empty()) {
      std::vector<double> depths;
      for (const auto& [pixel, depth] : projected) depths.push_back(depth);
      std::sort(depths.begin(), depths.end());
      const double near = depths[depths.size() / 20];
      const double far = std::max(depths[depths.size() * 19 / 20], near * (1.0 + 1e-6));
      cv::Mat levels(1, static_cast<int>(projected.size()), CV_8U);
      for (size_t i = 0; i < projected.size(); ++i) {
        const double t = std::clamp((projected[i].second - near) / (far - near), 0.0, 1.0);
        levels.at<uint8_t>(0, static_cast<int>(i)) = static_cast<uint8_t>(255.0 * (1.0 - t));
      }
      cv::Mat colors;
      cv::applyColorMap(levels, colors, cv::COLORMAP_JET);
      for (size_t i = 0; i < projected.size(); ++i) {
        const cv::Point at(static_cast<int>(std::lround(projected[i].first.x())),
                           static_cast<int>(std::lround(projected[i].first.y())));
        image.at<cv::Vec3b>(at) = colors.at<cv::Vec3b>(0, static_cast<int>(i));
      }
    }
    cv::putText(image, keyframe.image_name, cv::Point(5, 15), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                cv::Scalar(255, 255, 255), 1);
    tiles.push_back(image);
  }
  if (tiles.empty()) return cv::Mat(1, 1, CV_8UC3, cv::Scalar(0, 0, 0));
  const int columns = tiles.size() > 1 ? 2 : 1;
  const int rows = static_cast<int>((tiles.size() + columns - 1) / columns);
  const int width = tiles[0].cols;
  const int height = tiles[0].rows;
  cv::Mat canvas(rows * height, columns * width, CV_8UC3, cv::Scalar(0, 0, 0));
  for (size_t i = 0; i < tiles.size(); ++i) {
    const int row = static_cast<int>(i) / columns;
    const int column = static_cast<int>(i) % columns;
    tiles[i].copyTo(canvas(cv::Rect(column * width, row * height, width, height)));
  }
  return canvas;
}

// Removes a staging directory when the build fails.
class StagingDirectory {
 public:
  explicit StagingDirectory(fs::path path) : path_(std::move(path)) {
    std::error_code error;
    fs::remove_all(path_, error);
    fs::create_directories(path_, error);
    if (error) throw IoError("cannot create " + path_.string() + ": " + error.message());
  }
  ~StagingDirectory() {
    if (!committed_) {
      std::error_code error;
      fs::remove_all(path_, error);
    }
  }
  StagingDirectory(const StagingDirectory&) = delete;
  StagingDirectory& operator=(const StagingDirectory&) = delete;
  const fs::path& path() const { return path_; }
  // Renames the staging directory to `target` (an absent or empty directory).
  void CommitTo(const fs::path& target) {
    std::error_code error;
    if (fs::exists(target, error)) {
      fs::remove(target, error);  // only succeeds for an empty directory
      if (error) throw IoError("cannot replace " + target.string() + ": " + error.message());
    }
    fs::rename(path_, target, error);
    if (error) {
      throw IoError("cannot rename " + path_.string() + " to " + target.string() + ": " +
                    error.message());
    }
    committed_ = true;
  }

 private:
  fs::path path_;
  bool committed_ = false;
};

void CopyFileInto(const fs::path& source, const fs::path& directory) {
  std::error_code error;
  fs::copy_file(source, directory / source.filename(), fs::copy_options::overwrite_existing, error);
  if (error) throw IoError("cannot copy " + source.string() + ": " + error.message());
}

}  // namespace

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
  alignment_limits.Check();
}

double MapBuildReport::TotalSeconds(const std::string& prefix) const {
  double total = 0.0;
  for (const StageTiming& timing : timings) {
    if (timing.stage.rfind(prefix, 0) == 0) total += timing.seconds;
  }
  return total;
}

double MapBuildReport::TotalCpuSeconds(const std::string& prefix) const {
  double total = 0.0;
  for (const StageTiming& timing : timings) {
    if (timing.stage.rfind(prefix, 0) == 0) total += timing.cpu_seconds;
  }
  return total;
}

std::vector<InputImage> ListInputImages(const fs::path& image_dir,
                                        const std::optional<fs::path>& image_list) {
  std::error_code error;
  if (!fs::is_directory(image_dir, error)) {
    throw InvalidArgumentError("image folder '" + image_dir.string() +
                               "' does not exist or is not a directory");
  }
  const fs::path root = fs::weakly_canonical(image_dir);
  std::vector<InputImage> images;
  if (image_list) {
    // The strict `t_s path` reader of core/dataset; a listed path is relative to the image folder
    // or, failing that, to the list's folder (docs/dataset-format.md, "Timed file lists").
    const std::string source = image_list->string();
    for (const TimedFile& listed : ReadTimedFileList(*image_list, fs::path())) {
      fs::path file = image_dir / listed.path;
      if (!fs::exists(file, error)) file = image_list->parent_path() / listed.path;
      if (!fs::exists(file, error)) {
        throw IoError(source + " lists image '" + listed.path.string() +
                      "', which exists neither in " + image_dir.string() + " nor beside the list");
      }
      const fs::path relative = fs::weakly_canonical(file).lexically_relative(root);
      if (relative.empty() || *relative.begin() == "..") {
        throw InvalidArgumentError(source + " lists image '" + listed.path.string() +
                                   "', which is outside the image folder " + image_dir.string());
      }
      images.push_back({relative.generic_string(), listed.t_ns, true});
    }
  } else {
    for (const fs::directory_entry& entry : fs::directory_iterator(image_dir, error)) {
      if (!entry.is_regular_file()) continue;
      if (!kImageExtensions.contains(Lowercase(entry.path().extension().string()))) continue;
      images.push_back({entry.path().filename().string(), 0, false});
    }
    std::sort(images.begin(), images.end(),
              [](const InputImage& a, const InputImage& b) { return a.name < b.name; });
  }
  if (images.empty()) {
    throw InvalidArgumentError(
        "no images found in '" + image_dir.string() +
        "' (expected .png, .jpg, .bmp, .tif or .pgm files" +
        (image_list ? std::string(" listed in ") + image_list->string() : std::string()) + ")");
  }
  std::set<std::string> seen;
  for (const InputImage& image : images) {
    if (!seen.insert(image.name).second) {
      throw InvalidArgumentError("image " + image.name + " is listed twice");
    }
  }
  return images;
}

std::map<std::string, Rigid3d> ReadPosesForImages(const fs::path& path,
                                                  const std::vector<InputImage>& images) {
  const std::string text = ReadFileToString(path);
  const std::string source = path.string();
  std::string line;
  std::map<std::string, Rigid3d> poses;
  if (IsTimeKeyedPoseText(text)) {
    const Trajectory trajectory = ReadTumTrajectory(path);
    for (const InputImage& image : images) {
      if (!image.has_time) {
        throw InvalidArgumentError(source +
                                   " is a TUM trajectory keyed by time, but the images have no "
                                   "times: pass --images-list with `t_s path` lines");
      }
      const std::optional<Rigid3d> pose = trajectory.Lookup(image.t_ns);
      if (pose) poses[image.name] = *pose;
    }
    return poses;
  }
  std::unordered_map<std::string, std::string> by_name;
  std::unordered_map<std::string, int> basename_count;
  for (const InputImage& image : images) {
    by_name[image.name] = image.name;
    ++basename_count[fs::path(image.name).filename().string()];
  }
  for (const InputImage& image : images) {
    const std::string basename = fs::path(image.name).filename().string();
    if (basename_count[basename] == 1) by_name.emplace(basename, image.name);
  }
  std::istringstream lines(text);
  int64_t line_number = 0;
  while (std::getline(lines, line)) {
    ++line_number;
    const std::vector<std::string> tokens = Tokenize(line);
    if (tokens.empty() || tokens[0][0] == '#') continue;
    if (tokens.size() != 8) {
      throw ParseError::AtLine(source, line_number,
                               "expected `IMAGE_NAME tx ty tz qx qy qz qw` (world_from_cam)");
    }
    Rigid3d pose;
    try {
      pose = ParsePoseTokens("pose", std::span(tokens).subspan(1));
    } catch (const InvalidArgumentError& pose_error) {
      throw ParseError::AtLine(source, line_number, pose_error.what());
    }
    const auto image = by_name.find(tokens[0]);
    if (image == by_name.end()) {
      throw InvalidArgumentError(source + ": line " + std::to_string(line_number) + ": image " +
                                 tokens[0] + " is not among the input images");
    }
    if (!poses.emplace(image->second, pose).second) {
      throw ParseError::AtLine(source, line_number, "second pose for image " + tokens[0]);
    }
  }
  return poses;
}

bool IsTimeKeyedPoseFile(const fs::path& path) {
  return IsTimeKeyedPoseText(ReadFileToString(path));
}

std::vector<InputImage> ImagesWithKnownPoses(const std::vector<InputImage>& images,
                                             const std::map<std::string, Rigid3d>& poses,
                                             bool time_keyed, double min_fraction,
                                             const std::string& source,
                                             std::vector<std::string>* left_out) {
  std::vector<InputImage> kept;
  std::vector<std::string> missing;
  for (const InputImage& image : images) {
    if (poses.contains(image.name)) {
      kept.push_back(image);
    } else {
      missing.push_back(image.name);
    }
  }
  if (missing.empty()) return kept;
  const bool enough = static_cast<double>(kept.size()) >= min_fraction * images.size();
  if (!time_keyed || !enough || kept.empty()) {
    std::string list;
    for (size_t i = 0; i < missing.size() && i < 5; ++i) list += (i ? ", " : "") + missing[i];
    throw InvalidArgumentError(
        "the known poses in " + source + " do not match the images: " +
        std::to_string(missing.size()) + " of " + std::to_string(images.size()) +
        " images have no pose (" + list + (missing.size() > 5 ? ", ..." : "") + ")" +
        (time_keyed ? "; their times lie outside the trajectory's time span (at most half of "
                      "the images may, at the ends of the sequence)"
                    : ""));
  }
  if (left_out != nullptr) *left_out = missing;
  return kept;
}

MapBuildReport BuildMap(const MapBuilderOptions& options_in, ProgressListener* progress) {
  options_in.Check();
  MapBuilderOptions options = options_in;
  MapBuildReport report;
  const StageClock clock(progress, &report);
  std::error_code error;

  // Output checks first: never start hours of work for a directory that cannot take the map.
  const fs::path output_dir = fs::absolute(options.output_dir).lexically_normal();
  if (fs::exists(output_dir / kMapFileName, error)) {
    throw InvalidArgumentError("'" + output_dir.string() +
                               "' already holds a map; choose another --out or remove it");
  }
  if (fs::exists(output_dir, error) &&
      (!fs::is_directory(output_dir, error) || !fs::is_empty(output_dir, error))) {
    throw InvalidArgumentError("output '" + output_dir.string() +
                               "' exists and is not an empty directory");
  }
  const fs::path parent = output_dir.parent_path();
  fs::create_directories(parent, error);
  if (error) throw IoError("cannot create " + parent.string() + ": " + error.message());

  // Images: listed, readable, one size.
  std::vector<InputImage> images = ListInputImages(options.image_dir, options.image_list);
  report.num_images = images.size();
  cv::Size image_size;
  for (size_t i = 0; i < images.size(); ++i) {
    const cv::Mat image =
        cv::imread((options.image_dir / images[i].name).string(), cv::IMREAD_UNCHANGED);
    if (image.empty()) {
      throw InvalidArgumentError("cannot read image " +
                                 (options.image_dir / images[i].name).string() +
                                 " (missing, unreadable or not an image)");
    }
    if (i == 0) {
      image_size = image.size();
    } else if (image.size() != image_size) {
      throw InvalidArgumentError("images differ in size: " + images[0].name + " is " +
                                 std::to_string(image_size.width) + " x " +
                                 std::to_string(image_size.height) + ", " + images[i].name +
                                 " is " + std::to_string(image.cols) + " x " +
                                 std::to_string(image.rows) + "; all images must share one camera");
    }
  }
  // Camera.
  std::optional<Camera> camera = options.camera;
  if (options.calibration_file) {
    const std::string extension = Lowercase(options.calibration_file->extension().string());
    camera =
        (extension == ".yaml" || extension == ".yml")
            ? ReadCameraYaml(*options.calibration_file)
            : ReadEcdCalibration(*options.calibration_file, image_size.width, image_size.height);
  }
  if (camera && (camera->width != image_size.width || camera->height != image_size.height)) {
    throw InvalidArgumentError("the camera is " + std::to_string(camera->width) + " x " +
                               std::to_string(camera->height) + " but the images are " +
                               std::to_string(image_size.width) + " x " +
                               std::to_string(image_size.height));
  }
  options.colmap.camera = camera;

  // Known poses must cover every image (a trajectory may start late or end early: those images
  // are left out).
  std::map<std::string, Rigid3d> known_world_from_cams;
  if (options.known_poses) {
    known_world_from_cams = ReadPosesForImages(*options.known_poses, images);
    images = ImagesWithKnownPoses(images, known_world_from_cams,
                                  IsTimeKeyedPoseFile(*options.known_poses),
                                  options.min_registered_fraction, options.known_poses->string(),
                                  &report.images_without_pose);
  }
  // Reference poses for the alignment, read before COLMAP so that a bad file fails early.
  std::map<std::string, Rigid3d> reference_world_from_cams;
  if (options.align_to) {
    reference_world_from_cams = ReadPosesForImages(*options.align_to, images);
    if (reference_world_from_cams.size() < 3) {
      throw InvalidArgumentError("--align-to " + options.align_to->string() + " gives poses for " +
                                 std::to_string(reference_world_from_cams.size()) +
                                 " of the images; the alignment needs at least 3");
    }
  }

  // COLMAP.
  const fs::path workspace = options.colmap_workspace
                                 ? fs::absolute(*options.colmap_workspace)
                                 : fs::path(output_dir.string() + ".colmap-workspace");
  // A timed image list is a time-ordered video: sequential matching (each image with the next
  // sequential_overlap ones) instead of all pairs, whatever the number of images.
  const bool timed_sequence = std::all_of(images.begin(), images.end(),
                                          [](const InputImage& image) { return image.has_time; });
  if (options.colmap.matcher == MatcherType::kAuto && timed_sequence) {
    options.colmap.matcher = MatcherType::kSequential;
  }
  ColmapRunner runner(options.colmap, workspace, options.image_dir);
  report.colmap_version = ColmapVersion(options.colmap);
  const MatcherType matcher = runner.EffectiveMatcher(images.size());
  report.matcher = MatcherTypeName(matcher);
  report.pose_source = options.known_poses ? "known" : "estimated";
  const std::string fingerprint = WorkspaceFingerprint(options, images, camera, matcher);
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
      // Keep the largest reconstruction.
      fs::path best;
      uintmax_t best_size = 0;
      for (const fs::directory_entry& entry : fs::directory_iterator(sparse, error)) {
        const fs::path images_bin = entry.path() / "images.bin";
        if (!fs::exists(images_bin, error)) continue;
        const uintmax_t size = fs::file_size(images_bin, error);
        if (best.empty() || size > best_size) {
          best = entry.path();
          best_size = size;
        }
      }
      if (best.empty()) {
        throw InvalidArgumentError(
            "COLMAP could not reconstruct any image pair (no model written); the images may "
            "lack texture or overlap; see " +
            (runner.LogDir() / "mapper.log").string());
      }
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
        runner.RefineModel(best, refined);
        best = refined;
      }
      fs::remove_all(text_model, error);
      runner.ConvertToText(best, text_model);
    });
  }
  ColmapModel model = ReadColmapTextModel(text_model);
  report.num_registered = model.images.size();
  report.num_sparse_points = model.points.size();
  report.colmap_mean_reprojection_error_px = model.MeanReprojectionError();
  if (static_cast<double>(model.images.size()) <
      options.min_registered_fraction * static_cast<double>(images.size())) {
    throw InvalidArgumentError(
        "COLMAP registered only " + std::to_string(model.images.size()) + " of " +
        std::to_string(images.size()) + " images (fewer than " +
        std::to_string(static_cast<int>(options.min_registered_fraction * 100)) +
        " %); check overlap and texture, or give the camera");
  }
  if (model.cameras.empty()) throw IoError("the COLMAP model has no camera");

  // Alignment to the reference positions.
  clock.Run("alignment", [&] {
    if (!options.align_to) return false;
    std::vector<Rigid3d> model_poses;
    std::vector<Rigid3d> reference_poses;
    for (const auto& [id, image] : model.images) {
      const auto reference = reference_world_from_cams.find(image.name);
      if (reference == reference_world_from_cams.end()) continue;
      model_poses.push_back(image.cam_from_world.Inverse());
      reference_poses.push_back(reference->second);
    }
    if (model_poses.size() < 3) {
      throw InvalidArgumentError("only " + std::to_string(model_poses.size()) +
                                 " registered images have a reference pose in " +
                                 options.align_to->string() + "; the alignment needs 3");
    }
    const PoseAlignment alignment = AlignPoses(model_poses, reference_poses);
    const Sim3d& world_from_model = alignment.reference_from_model;
    report.alignment_num_images = alignment.num_poses;
    report.alignment_rms_m = alignment.centre_rms;
    report.alignment_max_m = alignment.centre_max;
    report.alignment_rotation_rms_deg = alignment.rotation_rms_deg;
    report.alignment_rotation_max_deg = alignment.rotation_max_deg;
    report.alignment_scale = world_from_model.scale;
    report.alignment_reference_spread_m = alignment.reference_spread;
    report.world_from_model = world_from_model;
    if (const std::optional<std::string> violation =
            AlignmentLimitViolation(alignment, options.alignment_limits)) {
      if (!options.accept_bad_alignment) {
        throw InvalidArgumentError(
            "--align-to " + options.align_to->string() + ": " + *violation +
            ". The COLMAP reconstruction is probably wrong (see the COLMAP logs in " +
            runner.LogDir().string() +
            ") or the reference poses belong to other images; no map was written. To build it "
            "anyway pass --accept-bad-alignment, or raise --max-alignment-residual / "
            "--max-alignment-rotation");
      }
      report.alignment_warning = *violation;
    }
    for (auto& [id, image] : model.images) {
      image.cam_from_world =
          world_from_model.TransformPose(image.cam_from_world.Inverse()).Inverse();
    }
    for (auto& [id, point] : model.points) point.position = world_from_model * point.position;
    return false;
  });

  // Registered views in input order.
  std::vector<RegisteredView> views;
  std::unordered_map<uint64_t, Eigen::Vector3d> sparse_points;
  for (const auto& [id, point] : model.points) sparse_points[id] = point.position;
  std::vector<uint32_t> view_camera_ids;
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
    views.push_back(std::move(view));
    view_camera_ids.push_back(image.camera_id);
    report.world_from_cams[image.name] = image.cam_from_world.Inverse();
  }
  std::map<uint32_t, uint32_t> camera_index_of_id;
  Map map;
  for (const auto& [id, colmap_camera] : model.cameras) {
    camera_index_of_id[id] = static_cast<uint32_t>(map.cameras.size());
    map.cameras.push_back(camera ? *camera : CameraFromColmap(colmap_camera));
  }

  KeyframeSelection selection;
  clock.Run("keyframes", [&] {
    selection = SelectKeyframes(views, sparse_points, options.keyframes);
    return false;
  });
  report.num_keyframes = selection.keyframes.size();

  // Semi-dense depth per keyframe.
  std::map<size_t, DepthFrame> frames;
  const auto frame_of = [&](size_t view) -> const DepthFrame& {
    auto found = frames.find(view);
    if (found == frames.end()) {
      const cv::Mat image =
          ReadImage(options.image_dir / views[view].image_name, cv::IMREAD_UNCHANGED);
      const Camera& view_camera = map.cameras[camera_index_of_id.at(view_camera_ids[view])];
      found = frames
                  .emplace(view, MakeDepthFrame(image, view_camera, views[view].cam_from_world,
                                                options.semidense))
                  .first;
    }
    return found->second;
  };
  std::vector<KeyframeDepth> depths(selection.keyframes.size());
  clock.Run("semidense_depth", [&] {
    for (size_t k = 0; k < selection.keyframes.size(); ++k) {
      clock.Progress("semidense_depth", k, selection.keyframes.size());
      const size_t view = selection.keyframes[k];
      std::vector<Eigen::Vector3d> seen;
      for (const uint64_t id : views[view].observed_points) seen.push_back(sparse_points.at(id));
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

  // Points in the world, with 3D gradients.
  std::vector<CandidatePoint> candidates;
  clock.Run("semidense_gradients", [&] {
    for (size_t k = 0; k < selection.keyframes.size(); ++k) {
      const RegisteredView& view = views[selection.keyframes[k]];
      Keyframe keyframe;
      keyframe.cam_from_world = view.cam_from_world;
      keyframe.camera_index = camera_index_of_id.at(view_camera_ids[selection.keyframes[k]]);
      keyframe.t_ns = view.t_ns;
      keyframe.image_name = view.image_name;
      map.keyframes.push_back(keyframe);
      const Camera& keyframe_camera = map.cameras[keyframe.camera_index];
      const Rigid3d world_from_cam = view.cam_from_world.Inverse();
      const std::vector<std::optional<Eigen::Vector3d>> surface_gradients =
          SurfaceGradients3d(keyframe_camera, depths[k], options.semidense);
      for (size_t p = 0; p < depths[k].pixels.size(); ++p) {
        const DepthPixel& pixel = depths[k].pixels[p];
        Eigen::Vector3d ray;
        if (!keyframe_camera.Unproject(pixel.pixel.cast<double>(), &ray)) continue;
        const Eigen::Vector3d point_in_cam = ray / pixel.inverse_depth;
        Eigen::Vector3d gradient_in_cam;
        if (!ComputeGradient3d(keyframe_camera, pixel.pixel.cast<double>(),
                               pixel.gradient_direction, point_in_cam, &gradient_in_cam)) {
          continue;
        }
        CandidatePoint candidate;
        candidate.position = world_from_cam * point_in_cam;
        candidate.gradient =
            (world_from_cam.rotation * surface_gradients[p].value_or(gradient_in_cam)).normalized();
        if (surface_gradients[p]) ++report.num_surface_gradients;
        const double sigma = std::sqrt(pixel.inverse_depth_variance);
        candidate.inverse_depth_sigma = sigma;
        candidate.position_sigma = sigma / (pixel.inverse_depth * pixel.inverse_depth) * ray.norm();
        candidate.pixel_footprint = point_in_cam.z() / keyframe_camera.fx;
        candidate.gradient_magnitude = pixel.gradient_magnitude;
        candidate.source_keyframe = static_cast<uint32_t>(k);
        candidate.observing_keyframes = pixel.confirming_keyframes;
        candidates.push_back(std::move(candidate));
      }
    }
    return false;
  });
  report.num_keyframe_points = candidates.size();
  clock.Run("merge", [&] {
    const MergeStatistics statistics = MergePoints(candidates, options.merge, &map);
    report.voxel_size = statistics.voxel_size;
    return false;
  });
  report.num_points = map.size();
  if (map.size() == 0) {
    throw InvalidArgumentError(
        "the semi-dense stage found no consistent edge points (" +
        std::to_string(selection.keyframes.size()) + " keyframes, " +
        std::to_string(report.num_keyframe_points) +
        " keyframe points before merging); the images may lack edges or baseline, or every "
        "point lacks " +
        std::to_string(options.semidense.min_keyframe_confirmations) +
        " confirming keyframes (--min-keyframes, --min-confirmations); see the COLMAP model in " +
        text_model.string());
  }
  map.provenance.tool = "evloc-mapper build";
  map.provenance.tool_version = EVLOC_VERSION;
  map.provenance.created_utc = UtcNow();
  map.provenance.command_line = options.command_line;
  map.provenance.inputs.push_back(fs::absolute(options.image_dir).string());
  for (const auto& input :
       {options.image_list, options.calibration_file, options.known_poses, options.align_to}) {
    if (input) map.provenance.inputs.push_back(fs::absolute(*input).string());
  }

  // Outputs, assembled in a staging sibling and renamed into place.
  clock.Run("outputs", [&] {
    StagingDirectory staging(
        parent / ("." + output_dir.filename().string() + ".staging-" + std::to_string(::getpid())));
    WriteMapDirectory(staging.path(), map);
    const cv::Mat preview = RenderPreview(map, options.image_dir, options.preview_keyframes);
    std::vector<uint8_t> png;
    if (!cv::imencode(".png", preview, png)) throw IoError("cannot encode preview.png");
    WriteFileAtomically(staging.path() / "preview.png",
                        std::string_view(reinterpret_cast<const char*>(png.data()), png.size()));
    const fs::path colmap_dir = staging.path() / "colmap";
    fs::create_directories(colmap_dir / "logs", error);
    if (error) throw IoError("cannot create " + colmap_dir.string() + ": " + error.message());
    for (const char* name : {"cameras.txt", "images.txt", "points3D.txt"}) {
      CopyFileInto(text_model / name, colmap_dir);
    }
    for (const fs::directory_entry& entry : fs::directory_iterator(runner.LogDir(), error)) {
      CopyFileInto(entry.path(), colmap_dir / "logs");
    }
    // report.json holds the timings of every stage before this one.
    WriteFileAtomically(staging.path() / "report.json", MapBuildReportToJson(report));
    staging.CommitTo(output_dir);
    return false;
  });
  return report;
}

std::string MapBuildReportToJson(const MapBuildReport& report) {
  nlohmann::json json;
  json["images"] = report.num_images;
  json["images_registered"] = report.num_registered;
  json["images_without_pose"] = report.images_without_pose;
  json["keyframes"] = report.num_keyframes;
  json["sparse_points"] = report.num_sparse_points;
  json["keyframe_points"] = report.num_keyframe_points;
  json["surface_gradients"] = report.num_surface_gradients;
  json["points"] = report.num_points;
  json["voxel_size"] = report.voxel_size;
  json["colmap_mean_reprojection_error_px"] = report.colmap_mean_reprojection_error_px;
  json["pose_source"] = report.pose_source;
  json["matcher"] = report.matcher;
  json["colmap_version"] = report.colmap_version;
  if (report.alignment_rms_m) {
    nlohmann::json alignment;
    alignment["images"] = report.alignment_num_images;
    alignment["rms_m"] = *report.alignment_rms_m;
    alignment["max_m"] = *report.alignment_max_m;
    alignment["rotation_rms_deg"] = *report.alignment_rotation_rms_deg;
    alignment["rotation_max_deg"] = *report.alignment_rotation_max_deg;
    alignment["scale"] = *report.alignment_scale;
    alignment["reference_spread_m"] = *report.alignment_reference_spread_m;
    alignment["rms_fraction_of_spread"] =
        *report.alignment_reference_spread_m > 0.0
            ? nlohmann::json(*report.alignment_rms_m / *report.alignment_reference_spread_m)
            : nlohmann::json(nullptr);
    alignment["within_limits"] = report.alignment_warning.empty();
    alignment["warning"] = report.alignment_warning;
    const Eigen::Quaterniond& q = report.world_from_model.rotation;
    alignment["world_from_model"] = {
        {"scale", report.world_from_model.scale},
        {"rotation_wxyz", {q.w(), q.x(), q.y(), q.z()}},
        {"translation",
         {report.world_from_model.translation.x(), report.world_from_model.translation.y(),
          report.world_from_model.translation.z()}}};
    json["alignment"] = alignment;
  } else {
    json["alignment"] = nullptr;
  }
  nlohmann::json timings = nlohmann::json::array();
  for (const StageTiming& timing : report.timings) {
    timings.push_back({{"stage", timing.stage},
                       {"seconds", timing.seconds},
                       {"cpu_seconds", timing.cpu_seconds},
                       {"reused", timing.reused}});
  }
  json["timings"] = timings;
  json["colmap_seconds"] = report.TotalSeconds("colmap");
  json["semidense_seconds"] = report.TotalSeconds("semidense");
  json["colmap_cpu_seconds"] = report.TotalCpuSeconds("colmap");
  json["semidense_cpu_seconds"] = report.TotalCpuSeconds("semidense");
  return json.dump(2) + "\n";
}

}  // namespace evloc::mapper
