#include "mapper/build_inputs.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <span>
#include <sstream>
#include <unordered_map>

#include <opencv2/imgcodecs.hpp>

#include "core/camera/calibration_file.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/dataset/dataset.h"
#include "core/dataset/pose_text.h"
#include "core/trajectory/trajectory.h"
#include "core/trajectory/tum_io.h"
#include "mapper/build_stages.h"
#include "maps/map_directory.h"

namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;

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

}  // namespace

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

BuildInputs LoadInputs(const MapBuilderOptions& options) {
  BuildInputs inputs;
  std::error_code error;
  // Output checks first: never start hours of work for a directory that cannot take the map.
  inputs.output_dir = fs::absolute(options.output_dir).lexically_normal();
  const fs::path& output_dir = inputs.output_dir;
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
  std::vector<InputImage>& images = inputs.images;
  images = ListInputImages(options.image_dir, options.image_list);
  inputs.num_images = images.size();
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
  std::optional<Camera>& camera = inputs.camera;
  camera = options.camera;
  if (options.calibration_file) {
    camera = ReadCalibrationFile(*options.calibration_file, image_size.width, image_size.height,
                                 &inputs.calibration_notes);
  }
  if (camera && (camera->width != image_size.width || camera->height != image_size.height)) {
    throw InvalidArgumentError("the camera is " + std::to_string(camera->width) + " x " +
                               std::to_string(camera->height) + " but the images are " +
                               std::to_string(image_size.width) + " x " +
                               std::to_string(image_size.height));
  }

  // Known poses must cover every image (a trajectory may start late or end early: those images
  // are left out).
  std::map<std::string, Rigid3d>& known_world_from_cams = inputs.known_world_from_cams;
  if (options.known_poses) {
    known_world_from_cams = ReadPosesForImages(*options.known_poses, images);
    images = ImagesWithKnownPoses(images, known_world_from_cams,
                                  IsTimeKeyedPoseFile(*options.known_poses),
                                  options.min_registered_fraction, options.known_poses->string(),
                                  &inputs.images_without_pose);
  }
  // Reference poses for the alignment, read before COLMAP so that a bad file fails early.
  std::map<std::string, Rigid3d>& reference_world_from_cams = inputs.reference_world_from_cams;
  if (options.align_to) {
    reference_world_from_cams = ReadPosesForImages(*options.align_to, images);
    if (reference_world_from_cams.size() < 3) {
      throw InvalidArgumentError("--align-to " + options.align_to->string() + " gives poses for " +
                                 std::to_string(reference_world_from_cams.size()) +
                                 " of the images; the alignment needs at least 3");
    }
  }

  return inputs;
}

}  // namespace evloc::mapper
