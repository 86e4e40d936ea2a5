// Sequence datasets in the Event Camera Dataset layout (docs/dataset-format.md): a writer that
// stages everything in OUT.partial and renames it to OUT only when complete, and a reader that
// loads both evloc-sim output (calib.yaml, events.evb) and real ECD folders (calib.txt,
// events.txt).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/events/event_reader.h"
#include "core/trajectory/trajectory.h"

namespace evloc {

// A file of a dataset with its time stamp (an image or a depth map).
struct TimedFile {
  // Time stamp, nanoseconds (seconds in the list files).
  int64_t t_ns = 0;
  // Absolute path (relative paths of the list files resolved against the dataset folder).
  std::filesystem::path path;
};

// File names inside a dataset folder.
namespace dataset_files {
// evloc camera YAML.
inline constexpr char kCalibYaml[] = "calib.yaml";
// ECD calibration: `fx fy cx cy k1 k2 p1 p2 k3`.
inline constexpr char kCalibTxt[] = "calib.txt";
// evloc binary events.
inline constexpr char kEventsEvb[] = "events.evb";
// ECD text events: `t x y p`, p in {0, 1}.
inline constexpr char kEventsTxt[] = "events.txt";
// Image list: `t_s relative_path`.
inline constexpr char kImagesTxt[] = "images.txt";
// Depth list: `t_s relative_path` (16-bit PNG, millimetres, 0 = no depth).
inline constexpr char kDepthTxt[] = "depth.txt";
// The depth camera beside the event camera (docs/dataset-format.md, "Depth camera"): a Kalibr
// camchain, cam0 the event camera (calib.yaml's), cam1 the depth camera with T_cn_cnm1 =
// depth_from_event.
inline constexpr char kDepthCamchainYaml[] = "depth_camchain.yaml";
// The depth camera's frames: `t_s depth_camera/depth_NNNNNNNN.png` (16-bit PNG, millimetres,
// 0 = no depth), at its own times.
inline constexpr char kDepthCameraTxt[] = "depth_camera.txt";
// Ground truth, TUM: `t tx ty tz qx qy qz qw`, world_from_cam.
inline constexpr char kGroundTruthTxt[] = "groundtruth.txt";
// TUM RGB-D layout: colour image list `t_s rgb/T.png` (instead of images.txt).
inline constexpr char kRgbTxt[] = "rgb.txt";
// Ground-truth map, evloc .evmap.
inline constexpr char kGroundTruthMap[] = "gt_map/map.evmap";
// Ground-truth map, PLY export.
inline constexpr char kGroundTruthPly[] = "gt_map/map.ply";
// IMU samples (converted recordings, ECD layout): `t_s ax ay az gx gy gz`, m/s^2 and rad/s.
inline constexpr char kImuTxt[] = "imu.txt";
// Provenance and counts (JSON).
inline constexpr char kInfoJson[] = "info.json";
}  // namespace dataset_files

// Options of the dataset writer.
struct DatasetWriterOptions {
  // Replace an existing non-empty output folder (only once the new one is complete).
  bool force = false;

  // Nothing to check; present for uniformity with other options structs.
  void Check() const {}
};

// Writes a dataset folder. Everything goes to `OUT.partial` (removed first if a previous run left
// it); Commit() writes the list files and renames it to OUT. A run that stops before Commit()
// leaves only OUT.partial, which no reader accepts as a dataset (it has no images.txt).
class DatasetWriter {
 public:
  // Prepares OUT.partial. Throws InvalidArgumentError when OUT exists, is not an empty folder and
  // options.force is false; IoError when the staging folder cannot be created.
  DatasetWriter(const std::filesystem::path& out_dir, const DatasetWriterOptions& options);

  // The folder files are staged in; write extra files (events, maps) below it.
  const std::filesystem::path& staging_dir() const { return staging_dir_; }
  // The final folder.
  const std::filesystem::path& out_dir() const { return out_dir_; }

  // Writes calib.yaml.
  void WriteCamera(const Camera& camera);
  // Writes images/frame_NNNNNNNN.png (CV_8UC1 or CV_8UC3 BGR) and lists it for images.txt.
  // Throws InvalidArgumentError when times do not increase or the image is not 8-bit.
  void AddImage(int64_t t_ns, const cv::Mat& image);
  // Writes depth/depth_NNNNNNNN.png (16-bit, millimetres rounded, 0 where depth is 0, clipped at
  // 65.535 m) from a CV_32FC1 depth in metres, and lists it for depth.txt.
  void AddDepth(int64_t t_ns, const cv::Mat& depth_m);
  // Writes depth_camchain.yaml: `event_camera` as cam0, `depth_camera` as cam1 with the extrinsic
  // (p_event = event_from_depth * p_depth). Throws InvalidArgumentError for a camera that fails
  // Check(), a non-finite extrinsic, or a camera model Kalibr cannot state.
  void WriteDepthCamera(const Camera& event_camera, const Camera& depth_camera,
                        const Rigid3d& event_from_depth);
  // Writes depth_camera/depth_NNNNNNNN.png (as AddDepth) and lists it for depth_camera.txt.
  void AddDepthCameraFrame(int64_t t_ns, const cv::Mat& depth_m);
  // Writes groundtruth.txt (TUM, world_from_cam).
  void WriteGroundTruth(const Trajectory& ground_truth);
  // Writes info.json.
  void WriteInfo(const nlohmann::json& info);
  // Writes images.txt, depth.txt (and depth_camera.txt when a depth camera was written), removes
  // gt_map/ when nothing was written there, then moves OUT.partial to OUT (replacing OUT when
  // forced). Throws IoError when the rename fails.
  void Commit();

  // Number of images added.
  size_t num_images() const { return images_.size(); }
  // Number of depth maps added.
  size_t num_depth_maps() const { return depth_.size(); }
  // Number of depth-camera frames added.
  size_t num_depth_camera_frames() const { return depth_camera_frames_.size(); }

 private:
  std::filesystem::path out_dir_;
  std::filesystem::path staging_dir_;
  DatasetWriterOptions options_;
  std::vector<TimedFile> images_;  // paths relative to the dataset folder
  std::vector<TimedFile> depth_;
  std::vector<TimedFile> depth_camera_frames_;
  bool has_depth_camera_ = false;
  bool committed_ = false;
};

// The topics of a ROS1 bag read as a dataset (docs/event-formats.md, section 7). Defaults: the
// rpg_dvs_ros driver's topics and the Event Camera Dataset's motion-capture pose.
struct RosbagTopics {
  // Events: dvs_msgs/EventArray, prophesee_event_msgs/EventArray or event_camera_msgs/EventPacket.
  // Required when events are read (OpenDatasetEvents).
  std::string events = "/dvs/events";
  // Images, sensor_msgs/Image; when absent the dataset has no images.
  std::string image = "/dvs/image_raw";
  // Calibration, sensor_msgs/CameraInfo (the first message); required.
  std::string camera_info = "/dvs/camera_info";
  // Ground truth world_from_cam, geometry_msgs/PoseStamped; when absent, no ground truth.
  std::string groundtruth = "/optitrack/davis";

  // Throws InvalidArgumentError when a topic is empty.
  void Check() const;
};

// An AEDAT4 file (iniVation DV) read as a dataset (docs/event-formats.md, section 8): its
// streams, and the calibration and ground truth that the format does not hold.
struct Aedat4DatasetOptions {
  // The events stream (EVTS), by name or id; required when events are read.
  std::string events = "events";
  // The frames stream (FRME); when absent the dataset has no images.
  std::string frames = "frames";
  // The camera: an evloc YAML camera, or an ECD calib.txt sized from the events stream; required
  // (the format holds no calibration).
  std::filesystem::path calibration;
  // Ground truth world_from_cam, a TUM file; optional.
  std::filesystem::path groundtruth;

  // Throws InvalidArgumentError when a stream name is empty.
  void Check() const;
};

// The command-line flags of recordings read as datasets, shared by evloc-track, evloc-replay and
// evloc-convert: --events-topic and --image-topic name the bag topic and the AEDAT4 stream,
// --camera-info-topic and --groundtruth-topic the bag topics, --calib and --groundtruth the
// AEDAT4 file's calibration and ground truth. Sets what `flag` names to `value` and returns true,
// or returns false for any other flag.
bool ApplyRecordingFlag(const std::string& flag, const std::string& value, RosbagTopics* topics,
                        Aedat4DatasetOptions* aedat4);

// The help text of those flags (one line each, indented as the tools' usage).
extern const char kRecordingFlagsUsage[];

// Options of the dataset reader.
struct DatasetReaderOptions {
  // Sensor width used with an ECD calib.txt (which has no size); DAVIS240C: 240.
  int ecd_width = 240;
  // Sensor height used with an ECD calib.txt; DAVIS240C: 180.
  int ecd_height = 180;
  // The topics used when the dataset is a ROS1 bag.
  RosbagTopics bag_topics;
  // The streams and side files used when the dataset is an AEDAT4 file.
  Aedat4DatasetOptions aedat4;

  // Throws InvalidArgumentError unless both sizes are positive and the topics are valid.
  void Check() const;
};

// The folder layout a dataset was read from (docs/dataset-format.md).
enum class DatasetLayout {
  // evloc / Event Camera Dataset: images.txt, depth at the frame times in millimetres.
  kEvloc,
  // TUM RGB-D: rgb.txt and depth.txt at their own times, depth in 1/5000 m.
  kTumRgbd,
  // A ROS1 bag file.
  kRosbag,
  // An AEDAT4 file.
  kAedat4,
};

// Depth PNG units per metre of the evloc layout (millimetres).
inline constexpr double kEvlocDepthUnitsPerMetre = 1000.0;
// Depth PNG units per metre of the TUM RGB-D layout.
inline constexpr double kTumDepthUnitsPerMetre = 5000.0;
// The association tolerance of the TUM RGB-D tools (associate.py): 0.02 s.
inline constexpr int64_t kTumAssociationToleranceNs = 20'000'000;

// What a dataset read from a ROS1 bag holds besides the Dataset fields.
struct RosbagDatasetSource {
  // The topics it was read with.
  RosbagTopics topics;
  // Every topic of the bag with its type, for error messages.
  std::string topic_list;
  // Messages on the image topic (images are decoded by the converter, ConvertRosbagToDataset).
  uint64_t image_messages = 0;
};

// What a dataset read from an AEDAT4 file holds besides the Dataset fields.
struct Aedat4DatasetSource {
  // The options it was read with.
  Aedat4DatasetOptions options;
  // Every stream of the file with its id and type, for error messages.
  std::string stream_list;
  // True when the file has the frames stream (frames are decoded by the converter).
  bool has_frames = false;
};

// A depth camera beside the event camera, and its frames (depth_camchain.yaml, depth_camera.txt).
struct DepthCameraStream {
  // The depth camera.
  Camera camera;
  // p_event = event_from_depth * p_depth.
  Rigid3d event_from_depth;
  // Its depth frames in time order (16-bit PNG).
  std::vector<TimedFile> frames;
  // Units per metre of those PNGs (pass to ReadDepthPng): millimetres.
  double units_per_metre = kEvlocDepthUnitsPerMetre;
};

// A loaded dataset: its calibration, the lists of images and depth maps, ground truth and where
// its events are. Image and depth pixels are read on demand.
struct Dataset {
  // The dataset folder.
  std::filesystem::path root;
  // The camera (from calib.yaml, else from calib.txt with the reader's size).
  Camera camera;
  // What the calibration reader read but did not use (e.g. a Kalibr camchain's imu fields), one
  // sentence each, prefixed with the file: for the tools to print.
  std::vector<std::string> calibration_notes;
  // Images in time order (empty when the folder has no images.txt).
  std::vector<TimedFile> images;
  // Depth maps in time order (empty when there is no depth.txt).
  std::vector<TimedFile> depth;
  // The depth camera and its frames, when the folder has depth_camchain.yaml.
  std::optional<DepthCameraStream> depth_camera;
  // Ground truth world_from_cam, when groundtruth.txt exists.
  std::optional<Trajectory> ground_truth;
  // The event file (events.evb preferred, else events.txt), when one exists; open it with
  // OpenEventFile() from core/events.
  std::optional<std::filesystem::path> events_path;
  // The ground-truth map (gt_map/map.evmap), when present.
  std::optional<std::filesystem::path> ground_truth_map_path;
  // info.json, when present (evloc-sim output).
  std::optional<nlohmann::json> info;
  // Set when the dataset is a ROS1 bag (`root` is then the bag file and `events_path` too).
  std::optional<RosbagDatasetSource> bag;
  // Set when the dataset is an AEDAT4 file (`root` is then the file and `events_path` too).
  std::optional<Aedat4DatasetSource> aedat4;
  // The layout it was read from.
  DatasetLayout layout = DatasetLayout::kEvloc;
  // Units per metre of the depth PNGs (pass to ReadDepthPng): 1000, or 5000 for TUM RGB-D.
  double depth_units_per_metre = kEvlocDepthUnitsPerMetre;
};

// Loads a dataset folder, a ROS1 bag file (see ReadRosbagDataset in rosbag_dataset.h) or an
// AEDAT4 file (ReadAedat4Dataset in aedat4_dataset.h). A folder with rgb.txt and no images.txt is
// read in the TUM RGB-D layout (ReadTumRgbdDataset in tum_rgbd.h).
// Throws IoError when the folder or a listed file is missing, ParseError naming the file and line
// for malformed lists, InvalidArgumentError when the folder has neither calib.yaml nor calib.txt,
// or is an unfinished OUT.partial.
Dataset ReadDataset(const std::filesystem::path& root, const DatasetReaderOptions& options = {});

// Receives the images of a dataset or recording in time order: (t_ns, CV_8UC1, CV_16UC1, CV_8UC3
// BGR or CV_8UC4 BGRA pixels).
using ImageSink = std::function<void(int64_t t_ns, const cv::Mat& pixels)>;

// True when `dataset` has images: a folder's images.txt lists some, a bag has messages on its
// image topic, an AEDAT4 file has its frames stream.
bool DatasetHasImages(const Dataset& dataset);

// Hands the images of `dataset` to `add` in time order, one at a time (a recording's images are
// streamed, never all in memory): the files of a folder's images.txt as stored (8 or 16 bits,
// grey or colour), the image topic of a bag (ForEachRosbagImage), the frames stream of an AEDAT4
// file (ForEachAedat4Frame). Throws IoError naming the file for an image that cannot be read,
// ParseError for a malformed message or packet.
void ForEachDatasetImage(const Dataset& dataset, const ImageSink& add);

// An image file's pixels as stored (cv::IMREAD_UNCHANGED). Throws IoError naming the file when it
// is missing or not an image OpenCV reads.
cv::Mat ReadImageFile(const std::filesystem::path& path);

// `pixels` (CV_8UC1, CV_16UC1, CV_8UC3 BGR or CV_8UC4 BGRA) as 8-bit grey: 16 bits scaled by
// 1/257 (rounded, as the converters write them), colour as cv::imread(IMREAD_GRAYSCALE) makes a
// colour PNG grey (libpng's truncating 0.299 R + 0.587 G + 0.114 B; alpha ignored). The one
// conversion of every frame source, so that a recording and its converted folder give the same
// pixels, and a folder's colour PNGs the pixels the tools always read. Throws
// InvalidArgumentError for any other type.
cv::Mat ToGray8(const cv::Mat& pixels);

// Reads the depth camera of a dataset folder: depth_camchain.yaml (the calibration reader; two
// cameras, cam0 of `event_camera`'s size, cam1 with T_cn_cnm1) and depth_camera.txt. Throws
// ParseError naming the file for a camchain that is not that, IoError when the list is missing.
DepthCameraStream ReadDepthCameraStream(const std::filesystem::path& root,
                                        const Camera& event_camera);

// Throws IoError naming the dataset and the file when an image or depth map it lists does not
// exist.
void CheckListedFilesExist(const Dataset& dataset);

// Opens the events of a dataset: its event file, the events topic of a bag or the events stream
// of an AEDAT4 file. Throws InvalidArgumentError when the dataset has no events (for a bag or an
// AEDAT4 file: naming the topics or streams present).
std::unique_ptr<EventReader> OpenDatasetEvents(const Dataset& dataset);

// The pose a run over `dataset` starts from: `initial_world_from_cam` when given, else the first
// ground-truth pose; at the ground truth's start time when there is ground truth, else at
// `fallback_t_ns` (the first measurement's time). Throws InvalidArgumentError naming the dataset
// when there is neither an initial pose nor ground truth.
TimedPose ResolveInitialPose(const Dataset& dataset,
                             const std::optional<Rigid3d>& initial_world_from_cam,
                             int64_t fallback_t_ns);

// Reads a list file `t_s path` (images.txt, depth.txt); `#` comments and blank lines skipped.
// Paths are resolved against `root`. Throws ParseError naming the line for a malformed line or a
// time that does not increase.
std::vector<TimedFile> ReadTimedFileList(const std::filesystem::path& list_path,
                                         const std::filesystem::path& root);

// The same rule for list text already in memory; `source_name` names it in error messages.
std::vector<TimedFile> ParseTimedFileList(std::string_view text, const std::string& source_name,
                                          const std::filesystem::path& root);

// Reads a 16-bit depth PNG as CV_32FC1 metres (0 = no depth): values divided by
// `units_per_metre` (1000 for DatasetWriter::AddDepth, 5000 for TUM RGB-D; use the dataset's
// depth_units_per_metre). Throws IoError when it cannot be read, ParseError when it is not 16-bit
// single-channel, InvalidArgumentError when units_per_metre is not positive and finite.
cv::Mat ReadDepthPng(const std::filesystem::path& path,
                     double units_per_metre = kEvlocDepthUnitsPerMetre);

// Reads an image as linear gray intensity in [0, 1] (CV_32FC1): 8- or 16-bit, gray or colour
// (Rec. 709 luminance). Throws IoError when it cannot be read.
cv::Mat ReadGrayImage(const std::filesystem::path& path);

}  // namespace evloc
