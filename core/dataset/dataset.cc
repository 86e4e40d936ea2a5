#include "core/dataset/dataset.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/camera/calibration_file.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/text_lines.h"
#include "core/dataset/aedat4_dataset.h"
#include "core/dataset/rosbag_dataset.h"
#include "core/dataset/tum_rgbd.h"
#include "core/events/aedat4.h"
#include "core/events/rosbag.h"
#include "core/events/rosbag_events.h"
#include "core/trajectory/tum_io.h"

namespace evloc {
namespace fs = std::filesystem;
namespace {

// True when `dir` exists and holds at least one entry (or is not a folder).
bool ExistsAndNotEmpty(const fs::path& dir) {
  std::error_code error;
  if (!fs::exists(dir, error)) return false;
  if (!fs::is_directory(dir, error)) return true;
  return fs::directory_iterator(dir, error) != fs::directory_iterator();
}

// "frame_00000012.png"-style names.
std::string NumberedName(const char* prefix, size_t index) {
  char name[64];
  std::snprintf(name, sizeof(name), "%s_%08zu.png", prefix, index);
  return name;
}

// Writes a PNG atomically (encode in memory, then WriteFileAtomically).
void WritePngAtomically(const fs::path& path, const cv::Mat& image) {
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", image, bytes)) {
    throw IoError("cannot encode '" + path.string() + "' as PNG.");
  }
  WriteFileAtomically(path,
                      std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

// The text of a `t_s path` list.
std::string FormatTimedFileList(const std::vector<TimedFile>& files) {
  std::string text;
  for (const TimedFile& file : files) {
    text += FormatNanosecondsAsSeconds(file.t_ns) + " " + file.path.generic_string() + "\n";
  }
  return text;
}

void CheckIncreasing(const std::vector<TimedFile>& files, int64_t t_ns, const char* what) {
  if (!files.empty() && t_ns <= files.back().t_ns) {
    throw InvalidArgumentError(std::string("DatasetWriter: ") + what + " time " +
                               FormatNanosecondsAsSeconds(t_ns) + " s is not after the previous " +
                               FormatNanosecondsAsSeconds(files.back().t_ns) + " s.");
  }
}

}  // namespace

DatasetWriter::DatasetWriter(const fs::path& out_dir, const DatasetWriterOptions& options)
    : out_dir_(out_dir), options_(options) {
  options_.Check();
  if (out_dir_.filename().empty()) out_dir_ = out_dir_.parent_path();  // "out/" -> "out"
  if (ExistsAndNotEmpty(out_dir_) && !options_.force) {
    throw InvalidArgumentError("Output folder '" + out_dir_.string() +
                               "' already exists and is not empty; choose another --out or pass "
                               "--force to replace it.");
  }
  staging_dir_ = out_dir_;
  staging_dir_ += ".partial";
  std::error_code error;
  fs::remove_all(staging_dir_, error);
  if (error) {
    throw IoError("cannot remove the stale staging folder '" + staging_dir_.string() +
                  "': " + error.message());
  }
  fs::create_directories(staging_dir_ / "images", error);
  if (!error) fs::create_directories(staging_dir_ / "depth", error);
  if (!error) fs::create_directories(staging_dir_ / "gt_map", error);
  if (error) {
    throw IoError("cannot create '" + staging_dir_.string() + "': " + error.message() +
                  " (is the parent folder writable?)");
  }
}

void DatasetWriter::WriteCamera(const Camera& camera) {
  WriteCameraYaml(staging_dir_ / dataset_files::kCalibYaml, camera);
}

void DatasetWriter::AddImage(int64_t t_ns, const cv::Mat& image) {
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3)) {
    throw InvalidArgumentError("DatasetWriter::AddImage expects an 8-bit gray or BGR image.");
  }
  CheckIncreasing(images_, t_ns, "image");
  const fs::path relative = fs::path("images") / NumberedName("frame", images_.size());
  WritePngAtomically(staging_dir_ / relative, image);
  images_.push_back({t_ns, relative});
}

namespace {

// A depth map in metres (CV_32FC1) as 16-bit millimetres: rounded, 0 where there is no depth,
// clipped at 65.535 m.
cv::Mat DepthToMillimetres(const cv::Mat& depth_m, const char* what) {
  if (depth_m.type() != CV_32FC1) {
    throw InvalidArgumentError(std::string("DatasetWriter::") + what +
                               " expects CV_32FC1 depth in metres.");
  }
  cv::Mat millimetres(depth_m.size(), CV_16UC1);
  for (int row = 0; row < depth_m.rows; ++row) {
    const float* in = depth_m.ptr<float>(row);
    uint16_t* out = millimetres.ptr<uint16_t>(row);
    for (int col = 0; col < depth_m.cols; ++col) {
      const double mm = std::isfinite(in[col]) && in[col] > 0 ? std::round(in[col] * 1000.0) : 0;
      out[col] = static_cast<uint16_t>(std::clamp(mm, 0.0, 65535.0));
    }
  }
  return millimetres;
}

// One camera of a Kalibr camchain (`name:` and its fields), with T_cn_cnm1 when given.
std::string KalibrCameraText(const std::string& name, const Camera& camera,
                             const std::optional<Rigid3d>& cam_from_previous) {
  camera.Check();
  std::string distortion_model;
  std::vector<double> coefficients = camera.distortion;
  switch (camera.model) {
    case CameraModel::kPinhole:
      distortion_model = "none";
      break;
    case CameraModel::kRadialTangential:
      if (coefficients.size() == 5 && coefficients[4] != 0.0) {
        throw InvalidArgumentError("a Kalibr camchain cannot state the radtan k3 of camera " +
                                   name + "; use a camera with k3 = 0");
      }
      coefficients.resize(4);
      distortion_model = "radtan";
      break;
    case CameraModel::kEquidistant:
      distortion_model = "equidistant";
      break;
  }
  std::ostringstream out;
  out.precision(17);
  out << name << ":\n";
  if (cam_from_previous) {
    if (!cam_from_previous->IsFinite()) {
      throw InvalidArgumentError("the extrinsic of camera " + name + " is not finite");
    }
    const Eigen::Matrix3d rotation = cam_from_previous->RotationMatrix();
    out << "  T_cn_cnm1:\n";
    for (int row = 0; row < 3; ++row) {
      out << "  - [" << rotation(row, 0) << ", " << rotation(row, 1) << ", " << rotation(row, 2)
          << ", " << cam_from_previous->translation[row] << "]\n";
    }
    out << "  - [0.0, 0.0, 0.0, 1.0]\n";
  }
  out << "  camera_model: pinhole\n  distortion_coeffs: [";
  for (size_t i = 0; i < coefficients.size(); ++i) out << (i ? ", " : "") << coefficients[i];
  out << "]\n  distortion_model: " << distortion_model << "\n  intrinsics: [" << camera.fx << ", "
      << camera.fy << ", " << camera.cx << ", " << camera.cy << "]\n  resolution: [" << camera.width
      << ", " << camera.height << "]\n";
  return out.str();
}

}  // namespace

void DatasetWriter::AddDepth(int64_t t_ns, const cv::Mat& depth_m) {
  const cv::Mat millimetres = DepthToMillimetres(depth_m, "AddDepth");
  CheckIncreasing(depth_, t_ns, "depth");
  const fs::path relative = fs::path("depth") / NumberedName("depth", depth_.size());
  WritePngAtomically(staging_dir_ / relative, millimetres);
  depth_.push_back({t_ns, relative});
}

void DatasetWriter::WriteDepthCamera(const Camera& event_camera, const Camera& depth_camera,
                                     const Rigid3d& event_from_depth) {
  const std::string text =
      "# evloc dataset: cam0 the event camera, cam1 the depth camera (docs/dataset-format.md)\n" +
      KalibrCameraText("cam0", event_camera, std::nullopt) +
      KalibrCameraText("cam1", depth_camera, event_from_depth.Inverse());
  WriteFileAtomically(staging_dir_ / dataset_files::kDepthCamchainYaml, text);
  std::error_code error;
  fs::create_directories(staging_dir_ / "depth_camera", error);
  if (error) {
    throw IoError("cannot create '" + (staging_dir_ / "depth_camera").string() +
                  "': " + error.message());
  }
  has_depth_camera_ = true;
}

void DatasetWriter::AddDepthCameraFrame(int64_t t_ns, const cv::Mat& depth_m) {
  if (!has_depth_camera_) {
    throw InvalidArgumentError("DatasetWriter::AddDepthCameraFrame: call WriteDepthCamera first.");
  }
  const cv::Mat millimetres = DepthToMillimetres(depth_m, "AddDepthCameraFrame");
  CheckIncreasing(depth_camera_frames_, t_ns, "depth camera frame");
  const fs::path relative =
      fs::path("depth_camera") / NumberedName("depth", depth_camera_frames_.size());
  WritePngAtomically(staging_dir_ / relative, millimetres);
  depth_camera_frames_.push_back({t_ns, relative});
}

void DatasetWriter::WriteGroundTruth(const Trajectory& ground_truth) {
  WriteTumTrajectory(staging_dir_ / dataset_files::kGroundTruthTxt, ground_truth);
}

void DatasetWriter::WriteInfo(const nlohmann::json& info) {
  WriteFileAtomically(staging_dir_ / dataset_files::kInfoJson, info.dump(2) + "\n");
}

void DatasetWriter::Commit() {
  if (committed_) throw InvalidArgumentError("DatasetWriter::Commit called twice.");
  WriteFileAtomically(staging_dir_ / dataset_files::kImagesTxt, FormatTimedFileList(images_));
  WriteFileAtomically(staging_dir_ / dataset_files::kDepthTxt, FormatTimedFileList(depth_));
  if (has_depth_camera_) {
    WriteFileAtomically(staging_dir_ / dataset_files::kDepthCameraTxt,
                        FormatTimedFileList(depth_camera_frames_));
  }
  std::error_code error;
  if (fs::is_empty(staging_dir_ / "gt_map", error)) fs::remove(staging_dir_ / "gt_map", error);
  if (fs::exists(out_dir_, error)) {
    if (ExistsAndNotEmpty(out_dir_) && !options_.force) {
      throw InvalidArgumentError("Output folder '" + out_dir_.string() +
                                 "' appeared while writing; the result is left in '" +
                                 staging_dir_.string() + "'.");
    }
    fs::remove_all(out_dir_, error);
    if (error) {
      throw IoError("cannot replace '" + out_dir_.string() + "': " + error.message() +
                    "; the new dataset is in '" + staging_dir_.string() + "'.");
    }
  }
  fs::rename(staging_dir_, out_dir_, error);
  if (error) {
    throw IoError("cannot rename '" + staging_dir_.string() + "' to '" + out_dir_.string() +
                  "': " + error.message());
  }
  committed_ = true;
}

void RosbagTopics::Check() const {
  if (events.empty() || image.empty() || camera_info.empty() || groundtruth.empty()) {
    throw InvalidArgumentError(
        "The bag topics (events, image, camera info, ground truth) must "
        "not be empty.");
  }
}

void Aedat4DatasetOptions::Check() const {
  if (events.empty() || frames.empty()) {
    throw InvalidArgumentError("The AEDAT4 streams (events, frames) must not be empty.");
  }
}

bool ApplyRecordingFlag(const std::string& flag, const std::string& value, RosbagTopics* topics,
                        Aedat4DatasetOptions* aedat4) {
  if (flag == "--events-topic") {
    topics->events = value;
    aedat4->events = value;
  } else if (flag == "--image-topic") {
    topics->image = value;
    aedat4->frames = value;
  } else if (flag == "--camera-info-topic") {
    topics->camera_info = value;
  } else if (flag == "--groundtruth-topic") {
    topics->groundtruth = value;
  } else if (flag == "--calib") {
    aedat4->calibration = value;
  } else if (flag == "--groundtruth") {
    aedat4->groundtruth = value;
  } else {
    return false;
  }
  return true;
}

const char kRecordingFlagsUsage[] =
    "  --events-topic T       bag topic (default /dvs/events) or AEDAT4 stream name or id\n"
    "                         (default events) of the events\n"
    "  --image-topic T        bag topic (default /dvs/image_raw) or AEDAT4 stream (default\n"
    "                         frames) of the images\n"
    "  --camera-info-topic T  bag topic of the calibration (default /dvs/camera_info)\n"
    "  --groundtruth-topic T  bag topic of the ground-truth PoseStamped (default "
    "/optitrack/davis)\n"
    "  --calib FILE[#CAM]     AEDAT4: the camera, any format of docs/camera.md (evloc YAML,\n"
    "                         Kalibr, ROS camera_info, OpenCV, COLMAP, ECD calib.txt); required\n"
    "  --groundtruth FILE     AEDAT4: ground truth world_from_cam, TUM (optional)\n";

void DatasetReaderOptions::Check() const {
  if (ecd_width <= 0 || ecd_height <= 0) {
    throw InvalidArgumentError("The ECD sensor size must be positive.");
  }
  bag_topics.Check();
  aedat4.Check();
}

std::unique_ptr<EventReader> OpenDatasetEvents(const Dataset& dataset) {
  if (dataset.aedat4) {
    Aedat4EventOptions options;
    options.stream = dataset.aedat4->options.events;
    if (!dataset.events_path) throw InvalidArgumentError("an AEDAT4 dataset without its path");
    return std::make_unique<Aedat4EventReader>(*dataset.events_path, options);
  }
  if (dataset.bag) {
    RosbagEventOptions options;
    options.topic = dataset.bag->topics.events;
    if (!dataset.events_path) throw InvalidArgumentError("a bag dataset without its bag path");
    return std::make_unique<RosbagEventReader>(*dataset.events_path, options);
  }
  if (!dataset.events_path) {
    throw InvalidArgumentError("dataset '" + dataset.root.string() +
                               "' has no events.evb or events.txt");
  }
  return OpenEventFile(*dataset.events_path);
}

std::vector<TimedFile> ReadTimedFileList(const fs::path& list_path, const fs::path& root) {
  return ParseTimedFileList(ReadFileToString(list_path), list_path.string(), root);
}

std::vector<TimedFile> ParseTimedFileList(std::string_view text, const std::string& source_name,
                                          const fs::path& root) {
  std::vector<TimedFile> files;
  ForEachDataLine(text, [&](int64_t line_number, const std::string& line) {
    std::istringstream fields(line);
    std::string time_text;
    std::string relative;
    std::string extra;
    if (!(fields >> time_text >> relative) || (fields >> extra)) {
      throw ParseError::AtLine(source_name, line_number,
                               "expected two fields `t_seconds relative_path`");
    }
    int64_t t_ns = 0;
    try {
      t_ns = ParseSecondsAsNanoseconds(time_text);
    } catch (const InvalidArgumentError& error) {
      throw ParseError::AtLine(source_name, line_number,
                               "bad time '" + time_text + "': " + error.what());
    }
    if (!files.empty() && t_ns <= files.back().t_ns) {
      throw ParseError::AtLine(source_name, line_number,
                               "time " + time_text + " is not after the previous line's");
    }
    files.push_back({t_ns, root / relative});
  });
  return files;
}

Dataset ReadDataset(const fs::path& root, const DatasetReaderOptions& options) {
  options.Check();
  std::error_code error;
  if (fs::is_regular_file(root, error) && IsRosbagFile(root)) {
    return ReadRosbagDataset(root, options);
  }
  if (fs::is_regular_file(root, error) && IsAedat4File(root)) {
    return ReadAedat4Dataset(root, options);
  }
  // --calib and --groundtruth are for AEDAT4 files, the only input without its own camera: on
  // anything else they would be ignored, and a user would track with a camera they did not mean.
  if (!options.aedat4.calibration.empty() || !options.aedat4.groundtruth.empty()) {
    throw InvalidArgumentError(
        "--calib and --groundtruth apply to AEDAT4 files only; '" + root.string() +
        "' is not one (a ROS bag carries its camera info and ground-truth topics, a dataset "
        "folder its calib.yaml and groundtruth.txt): drop the flags, or convert the recording "
        "with evloc-convert and edit the folder's files.");
  }
  if (IsTumRgbdFolder(root)) return ReadTumRgbdDataset(root);
  if (!fs::is_directory(root, error)) {
    throw IoError("dataset folder '" + root.string() + "' does not exist.");
  }
  if (root.filename().string().ends_with(".partial")) {
    throw InvalidArgumentError("'" + root.string() +
                               "' is an unfinished evloc-sim output (the run was interrupted); "
                               "run the simulator again.");
  }
  Dataset dataset;
  dataset.root = root;
  if (fs::exists(root / dataset_files::kCalibYaml)) {
    dataset.camera =
        ReadCalibrationFile(root / dataset_files::kCalibYaml, 0, 0, &dataset.calibration_notes);
  } else if (fs::exists(root / dataset_files::kCalibTxt)) {
    dataset.camera =
        ReadEcdCalibration(root / dataset_files::kCalibTxt, options.ecd_width, options.ecd_height);
  } else {
    throw InvalidArgumentError("dataset folder '" + root.string() + "' has neither " +
                               dataset_files::kCalibYaml + " nor " + dataset_files::kCalibTxt +
                               "; it is not a dataset.");
  }
  if (fs::exists(root / dataset_files::kImagesTxt)) {
    dataset.images = ReadTimedFileList(root / dataset_files::kImagesTxt, root);
  }
  if (fs::exists(root / dataset_files::kDepthTxt)) {
    dataset.depth = ReadTimedFileList(root / dataset_files::kDepthTxt, root);
  }
  if (fs::exists(root / dataset_files::kDepthCamchainYaml)) {
    dataset.depth_camera = ReadDepthCameraStream(root, dataset.camera);
  }
  CheckListedFilesExist(dataset);
  if (fs::exists(root / dataset_files::kGroundTruthTxt)) {
    dataset.ground_truth = ReadTumTrajectory(root / dataset_files::kGroundTruthTxt);
  }
  if (fs::exists(root / dataset_files::kEventsEvb)) {
    dataset.events_path = root / dataset_files::kEventsEvb;
  } else if (fs::exists(root / dataset_files::kEventsTxt)) {
    dataset.events_path = root / dataset_files::kEventsTxt;
  }
  if (fs::exists(root / dataset_files::kGroundTruthMap)) {
    dataset.ground_truth_map_path = root / dataset_files::kGroundTruthMap;
  }
  if (fs::exists(root / dataset_files::kInfoJson)) {
    const fs::path info_path = root / dataset_files::kInfoJson;
    try {
      dataset.info = nlohmann::json::parse(ReadFileToString(info_path));
    } catch (const nlohmann::json::parse_error& parse_error) {
      throw ParseError(info_path.string(), "byte " + std::to_string(parse_error.byte),
                       "malformed JSON");
    } catch (const nlohmann::json::exception& error) {
      // A number beyond double's range throws out_of_range, not parse_error.
      throw ParseError(info_path.string(), "JSON", std::string("malformed JSON: ") + error.what());
    }
  }
  return dataset;
}

DepthCameraStream ReadDepthCameraStream(const fs::path& root, const Camera& event_camera) {
  const fs::path camchain = root / dataset_files::kDepthCamchainYaml;
  const Calibration calibration = ReadCalibration(camchain, 0, 0);
  if (calibration.format != CalibrationFormat::kKalibrCamchain || calibration.cameras.size() != 2) {
    throw ParseError(camchain.string(), "cam0",
                     "expected a Kalibr camchain of two cameras: cam0 the event camera, cam1 the "
                     "depth camera with T_cn_cnm1");
  }
  const RigCamera& event = calibration.cameras[0];
  const RigCamera& depth = calibration.cameras[1];
  if (event.camera.width != event_camera.width || event.camera.height != event_camera.height) {
    throw ParseError(camchain.string(), "cam0",
                     "its resolution " + std::to_string(event.camera.width) + "x" +
                         std::to_string(event.camera.height) + " is not the dataset camera's " +
                         std::to_string(event_camera.width) + "x" +
                         std::to_string(event_camera.height) +
                         ": cam0 must be the event camera of calib.yaml");
  }
  if (!depth.cam_from_cam0) {
    throw ParseError(camchain.string(), "cam1",
                     "the depth camera needs T_cn_cnm1 (its pose relative to the event camera)");
  }
  const fs::path list = root / dataset_files::kDepthCameraTxt;
  if (!fs::exists(list)) {
    throw IoError("dataset '" + root.string() + "' has " + dataset_files::kDepthCamchainYaml +
                  " but no " + dataset_files::kDepthCameraTxt + " (the depth camera's frames).");
  }
  DepthCameraStream stream;
  stream.camera = depth.camera;
  stream.event_from_depth = depth.cam_from_cam0->Inverse();
  stream.frames = ReadTimedFileList(list, root);
  return stream;
}

void CheckListedFilesExist(const Dataset& dataset) {
  std::vector<const std::vector<TimedFile>*> lists = {&dataset.images, &dataset.depth};
  if (dataset.depth_camera) lists.push_back(&dataset.depth_camera->frames);
  for (const auto* list : lists) {
    for (const TimedFile& file : *list) {
      if (!fs::exists(file.path)) {
        throw IoError("dataset '" + dataset.root.string() + "' lists '" + file.path.string() +
                      "', which does not exist.");
      }
    }
  }
}

TimedPose ResolveInitialPose(const Dataset& dataset,
                             const std::optional<Rigid3d>& initial_world_from_cam,
                             int64_t fallback_t_ns) {
  const bool has_ground_truth = dataset.ground_truth && !dataset.ground_truth->empty();
  if (!initial_world_from_cam && !has_ground_truth && dataset.bag) {
    throw InvalidArgumentError("bag '" + dataset.root.string() + "' has no ground-truth topic '" +
                               dataset.bag->topics.groundtruth +
                               "' (its topics: " + dataset.bag->topic_list +
                               "): name it (--groundtruth-topic) or give the initial pose with "
                               "--init-pose");
  }
  if (!initial_world_from_cam && !has_ground_truth && dataset.aedat4) {
    throw InvalidArgumentError("AEDAT4 file '" + dataset.root.string() +
                               "' holds no ground truth: give a TUM file with --groundtruth or "
                               "the initial pose with --init-pose");
  }
  if (!initial_world_from_cam && !has_ground_truth) {
    throw InvalidArgumentError("dataset '" + dataset.root.string() +
                               "' has no groundtruth.txt: give the initial pose with --init-pose");
  }
  return TimedPose{has_ground_truth ? dataset.ground_truth->start_ns() : fallback_t_ns,
                   initial_world_from_cam ? *initial_world_from_cam
                                          : dataset.ground_truth->poses().front().world_from_cam};
}

cv::Mat ReadDepthPng(const fs::path& path, double units_per_metre) {
  if (!(units_per_metre > 0) || !std::isfinite(units_per_metre)) {
    throw InvalidArgumentError("ReadDepthPng: units per metre must be positive and finite, got " +
                               std::to_string(units_per_metre));
  }
  const cv::Mat raw = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  if (raw.empty()) throw IoError("cannot read depth image '" + path.string() + "'.");
  if (raw.type() != CV_16UC1) {
    throw ParseError(path.string(), "header", "a depth PNG must be 16-bit single-channel");
  }
  cv::Mat metres;
  raw.convertTo(metres, CV_32FC1, 1.0 / units_per_metre);
  return metres;
}

bool DatasetHasImages(const Dataset& dataset) {
  if (dataset.bag) return dataset.bag->image_messages > 0;
  if (dataset.aedat4) return dataset.aedat4->has_frames;
  return !dataset.images.empty();
}

void ForEachDatasetImage(const Dataset& dataset, const ImageSink& add) {
  if (dataset.bag) {
    ForEachRosbagImage(dataset, add);
    return;
  }
  if (dataset.aedat4) {
    ForEachAedat4Frame(dataset, add);
    return;
  }
  for (const TimedFile& image : dataset.images) add(image.t_ns, ReadImageFile(image.path));
}

cv::Mat ReadImageFile(const fs::path& path) {
  cv::Mat pixels = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  if (pixels.empty()) {
    throw IoError("cannot read image '" + path.string() +
                  "' (missing, or not an image OpenCV reads)");
  }
  return pixels;
}

cv::Mat ToGray8(const cv::Mat& pixels) {
  cv::Mat eight = pixels;
  if (pixels.depth() == CV_16U) {
    pixels.convertTo(eight, CV_8U, 1.0 / 257.0);
  } else if (pixels.depth() != CV_8U) {
    throw InvalidArgumentError("an image of " + std::to_string(pixels.channels()) +
                               " channels of OpenCV depth " + std::to_string(pixels.depth()) +
                               ": frames must be 8 or 16 bits per channel");
  }
  const int channels = eight.channels();
  if (channels == 1) return eight;
  if (channels != 3 && channels != 4) {
    throw InvalidArgumentError("an image of " + std::to_string(channels) +
                               " channels: frames must be grey, BGR or BGRA");
  }
  // libpng's conversion, which cv::imread(IMREAD_GRAYSCALE) applies to a colour PNG: weights
  // 0.299 and 0.587 in 15-bit fixed point (9797, 19234, and the rest 3737 for blue), truncated,
  // grey pixels kept as they are. cv::cvtColor rounds instead and differs by one level in about
  // half the pixels of a rendered frame, which is enough to change a Canny-VT run; this keeps
  // the frames of a folder exactly what they were when the tools read them in grey.
  cv::Mat gray(eight.rows, eight.cols, CV_8UC1);
  for (int y = 0; y < eight.rows; ++y) {
    const uint8_t* in = eight.ptr<uint8_t>(y);
    uint8_t* out = gray.ptr<uint8_t>(y);
    for (int x = 0; x < eight.cols; ++x, in += channels) {
      const uint32_t blue = in[0], green = in[1], red = in[2];
      out[x] = red == green && red == blue
                   ? static_cast<uint8_t>(red)
                   : static_cast<uint8_t>((9797u * red + 19234u * green + 3737u * blue) >> 15);
    }
  }
  return gray;
}

cv::Mat ReadGrayImage(const fs::path& path) {
  const cv::Mat raw = ReadImageFile(path);
  const double scale = raw.depth() == CV_16U ? 1.0 / 65535.0 : 1.0 / 255.0;
  cv::Mat gray;
  if (raw.channels() == 1) {
    gray = raw;
  } else {
    cv::Mat bgr;
    if (raw.channels() == 4) {
      cv::cvtColor(raw, bgr, cv::COLOR_BGRA2BGR);
    } else {
      bgr = raw;
    }
    cv::Mat bgr_float;
    bgr.convertTo(bgr_float, CV_32FC3);
    cv::transform(bgr_float, gray, cv::Matx13f(0.0722f, 0.7152f, 0.2126f));  // Rec. 709
    gray.convertTo(gray, CV_32FC1, scale);
    return gray;
  }
  gray.convertTo(gray, CV_32FC1, scale);
  return gray;
}

}  // namespace evloc
