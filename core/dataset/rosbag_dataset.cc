#include "core/dataset/rosbag_dataset.h"

#include <array>
#include <cmath>
#include <cstring>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/events/rosbag_events.h"
#include "core/trajectory/tum_io.h"

namespace evloc {
namespace {

constexpr char kCameraInfo[] = "sensor_msgs/CameraInfo";
constexpr char kImage[] = "sensor_msgs/Image";
constexpr char kPoseStamped[] = "geometry_msgs/PoseStamped";

// The connections of `topic`, all of type `type`; empty when the topic is absent. Throws
// InvalidArgumentError when the topic has another type.
bool HasTopicOfType(const RosbagReader& bag, const std::string& topic, const std::string& type,
                    const char* what) {
  const auto connections = bag.ConnectionsOf(topic);
  for (const RosbagConnection* connection : connections) {
    if (connection->type != type) {
      throw InvalidArgumentError(bag.source() + ": the " + what + " topic '" + topic +
                                 "' has type " + connection->type + ", expected " + type +
                                 "; the bag's topics are: " + bag.DescribeTopics());
    }
  }
  return !connections.empty();
}

}  // namespace

Camera CameraFromRosCameraInfo(uint32_t width, uint32_t height, const std::string& model,
                               const std::vector<double>& d, const std::array<double, 9>& k) {
  if (width == 0 || height == 0 || width > 65536 || height > 65536) {
    throw InvalidArgumentError("expected a width and height in 1..65536, found " +
                               std::to_string(width) + "x" + std::to_string(height));
  }
  Camera camera;
  camera.width = static_cast<int>(width);
  camera.height = static_cast<int>(height);
  camera.fx = k[0];
  camera.cx = k[2];
  camera.fy = k[4];
  camera.cy = k[5];
  const bool no_distortion =
      std::all_of(d.begin(), d.end(), [](double value) { return value == 0.0; });
  if (no_distortion) {
    camera.model = CameraModel::kPinhole;
  } else if ((model == "plumb_bob" || model == "radtan") && (d.size() == 5 || d.size() == 4)) {
    camera.model = CameraModel::kRadialTangential;
    camera.distortion = d;
    camera.distortion.resize(5, 0.0);
  } else if ((model == "equidistant" || model == "fisheye") && d.size() == 4) {
    camera.model = CameraModel::kEquidistant;
    camera.distortion = d;
  } else {
    throw InvalidArgumentError("unsupported distortion model '" + model + "' with " +
                               std::to_string(d.size()) +
                               " coefficients (evloc reads plumb_bob with 5, equidistant with 4, "
                               "or all zeros)");
  }
  try {
    camera.Check();
  } catch (const InvalidArgumentError& error) {
    throw InvalidArgumentError(std::string("invalid camera: ") + error.what());
  }
  return camera;
}

Camera DecodeRosCameraInfo(const RosbagMessage& message, const std::string& source) {
  RosMessageCursor cursor(message, source);
  cursor.Header();
  const uint32_t height = cursor.U32("height");
  const uint32_t width = cursor.U32("width");
  if (width == 0 || height == 0 || width > 65536 || height > 65536) {
    cursor.Fail("expected a width and height in 1..65536, found " + std::to_string(width) + "x" +
                std::to_string(height));
  }
  const size_t model_offset = cursor.offset();
  const std::string model = cursor.String("distortion_model");
  const uint32_t count = cursor.ArrayLength("D", 8);
  std::vector<double> d(count);
  for (double& value : d) value = cursor.F64("D");
  std::array<double, 9> k;
  for (double& value : k) value = cursor.F64("K");
  try {
    return CameraFromRosCameraInfo(width, height, model, d, k);
  } catch (const InvalidArgumentError& error) {
    // A refused model is reported where the model is; an invalid camera at the message.
    const bool model_refused = std::string(error.what()).rfind("unsupported", 0) == 0;
    throw ParseError(
        source, RosbagPosition(message, model_refused ? model_offset : 0),
        std::string(kCameraInfo) + " on " + message.connection->topic + ": " + error.what());
  }
}

TimedPose DecodeRosPoseStamped(const RosbagMessage& message, const std::string& source) {
  RosMessageCursor cursor(message, source);
  TimedPose pose;
  pose.t_ns = cursor.Header();
  double values[7];
  for (double& value : values) value = cursor.F64("pose");
  const Eigen::Quaterniond rotation(values[6], values[3], values[4], values[5]);
  const double norm = rotation.norm();
  if (!(norm > 0.9 && norm < 1.1) || !std::isfinite(values[0] + values[1] + values[2])) {
    cursor.Fail("expected a finite position and a unit quaternion, |q| = " + std::to_string(norm));
  }
  pose.world_from_cam =
      Rigid3d(rotation.normalized(), Eigen::Vector3d(values[0], values[1], values[2]));
  return pose;
}

RosImage DecodeRosImage(const RosbagMessage& message, const std::string& source) {
  RosMessageCursor cursor(message, source);
  RosImage image;
  image.t_ns = cursor.Header();
  const uint32_t height = cursor.U32("height");
  const uint32_t width = cursor.U32("width");
  const size_t encoding_offset = cursor.offset();
  const std::string encoding = cursor.String("encoding");
  const bool big_endian = cursor.U8("is_bigendian") != 0;
  const uint32_t step = cursor.U32("step");
  const uint32_t size = cursor.ArrayLength("data", 1);
  int type = 0;
  size_t pixel_bytes = 0;
  if (encoding == "mono8" || encoding == "8UC1") {
    type = CV_8UC1;
    pixel_bytes = 1;
  } else if (encoding == "mono16" || encoding == "16UC1") {
    type = CV_16UC1;
    pixel_bytes = 2;
  } else if (encoding == "bgr8" || encoding == "rgb8") {
    type = CV_8UC3;
    pixel_bytes = 3;
  } else {
    throw ParseError(source, RosbagPosition(message, encoding_offset),
                     std::string(kImage) + " on " + message.connection->topic +
                         ": unsupported encoding '" + encoding +
                         "' (evloc reads mono8, mono16, bgr8 and rgb8)");
  }
  if (big_endian && pixel_bytes == 2) cursor.Fail("big-endian mono16 images are not supported");
  if (width == 0 || height == 0 || width > 65536 || height > 65536 ||
      step < static_cast<uint64_t>(width) * pixel_bytes ||
      static_cast<uint64_t>(step) * height != size) {
    cursor.Fail("expected data of step × height bytes with step >= width × " +
                std::to_string(pixel_bytes) + " (width " + std::to_string(width) + ", height " +
                std::to_string(height) + ", step " + std::to_string(step) + ", " +
                std::to_string(size) + " bytes)");
  }
  const cv::Mat view(static_cast<int>(height), static_cast<int>(width), type,
                     const_cast<uint8_t*>(cursor.here()), step);
  if (encoding == "rgb8") {
    cv::cvtColor(view, image.pixels, cv::COLOR_RGB2BGR);
  } else {
    image.pixels = view.clone();
  }
  return image;
}

Dataset ReadRosbagDataset(const std::filesystem::path& path, const DatasetReaderOptions& options) {
  options.Check();
  const RosbagTopics& topics = options.bag_topics;
  RosbagReader bag(path);
  Dataset dataset;
  dataset.root = path;
  dataset.layout = DatasetLayout::kRosbag;
  dataset.events_path = path;
  dataset.bag = RosbagDatasetSource{topics, bag.DescribeTopics(), 0};
  if (!HasTopicOfType(bag, topics.camera_info, kCameraInfo, "camera-info")) {
    throw InvalidArgumentError(
        path.string() + " has no camera-info topic '" + topics.camera_info +
        "' (sensor_msgs/CameraInfo); the bag's topics are: " + bag.DescribeTopics());
  }
  const bool has_groundtruth =
      HasTopicOfType(bag, topics.groundtruth, kPoseStamped, "ground-truth");
  const bool has_images = HasTopicOfType(bag, topics.image, kImage, "image");
  std::vector<std::string> selected = {topics.camera_info};
  if (has_groundtruth) selected.push_back(topics.groundtruth);
  if (has_images) selected.push_back(topics.image);
  bag.SetTopics(selected);
  std::optional<Camera> camera;
  Trajectory ground_truth;
  RosbagMessage message;
  while (bag.Next(&message)) {
    const std::string& topic = message.connection->topic;
    if (topic == topics.camera_info) {
      if (!camera) camera = DecodeRosCameraInfo(message, bag.source());
    } else if (topic == topics.groundtruth) {
      const TimedPose pose = DecodeRosPoseStamped(message, bag.source());
      if (!ground_truth.empty() && pose.t_ns <= ground_truth.end_ns()) {
        throw ParseError(bag.source(), RosbagPosition(message, 4),
                         "ground-truth pose at " + std::to_string(pose.t_ns) +
                             " ns is not after the previous one (" +
                             std::to_string(ground_truth.end_ns()) + " ns)");
      }
      ground_truth.Append(pose);
    } else {
      ++dataset.bag->image_messages;
    }
  }
  if (!camera) {
    throw InvalidArgumentError(path.string() + ": the camera-info topic '" + topics.camera_info +
                               "' has no messages");
  }
  dataset.camera = *camera;
  if (!ground_truth.empty()) dataset.ground_truth = std::move(ground_truth);
  return dataset;
}

void ForEachRosbagImage(const Dataset& dataset, const ImageSink& add) {
  if (!dataset.bag || dataset.bag->image_messages == 0) return;
  RosbagReader bag(dataset.root);
  bag.SetTopics({dataset.bag->topics.image});
  RosbagMessage message;
  while (bag.Next(&message)) {
    const RosImage image = DecodeRosImage(message, bag.source());
    add(image.t_ns, image.pixels);
  }
}

RecordingConversionSummary ConvertRosbagToDataset(const std::filesystem::path& bag_path,
                                                  const std::filesystem::path& out_dir,
                                                  const DatasetReaderOptions& reader_options,
                                                  const RecordingConversionOptions& options) {
  const Dataset dataset = ReadRosbagDataset(bag_path, reader_options);
  const RosbagTopics& topics = reader_options.bag_topics;
  const auto for_each_image = [&](const ImageSink& add_image) {
    ForEachRosbagImage(dataset, add_image);
  };
  return WriteRecordingAsDataset(dataset, out_dir, options, for_each_image,
                                 {{"source", bag_path.filename().string()},
                                  {"converted_from", "ROS1 bag"},
                                  {"topics",
                                   {{"events", topics.events},
                                    {"image", topics.image},
                                    {"camera_info", topics.camera_info},
                                    {"groundtruth", topics.groundtruth}}}});
}

}  // namespace evloc
