// ROS1 bags as datasets: the calibration from sensor_msgs/CameraInfo, ground truth from
// geometry_msgs/PoseStamped, images from sensor_msgs/Image, events through core/events'
// RosbagEventReader; and the converter to the dataset folder layout (docs/event-formats.md,
// section 7; docs/dataset-format.md).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/dataset/dataset.h"
#include "core/dataset/recording_conversion.h"
#include "core/events/rosbag.h"

namespace evloc {

// Reads a bag as a dataset: the camera from the first message on topics.camera_info, the ground
// truth from every message on topics.groundtruth (header stamps; the pose is taken as
// world_from_cam), the number of image messages; `events_path` is the bag. Streams the bag once.
// Throws InvalidArgumentError, listing the bag's topics, when the camera-info topic is missing or
// a topic has an unexpected type; ParseError for malformed bags and messages.
Dataset ReadRosbagDataset(const std::filesystem::path& path, const DatasetReaderOptions& options);

// The camera of a sensor_msgs/CameraInfo's fields (the one rule of the bag reader and the ROS
// node): no distortion (every coefficient zero) is a pinhole, plumb_bob (radtan) with 5 (or 4)
// coefficients radial-tangential, equidistant (fisheye) with 4 equidistant; fx, fy, cx, cy from K.
// Throws InvalidArgumentError ("unsupported distortion model ..." for another model, "invalid
// camera: ..." when Camera::Check fails, or a size outside 1..65536).
Camera CameraFromRosCameraInfo(uint32_t width, uint32_t height, const std::string& model,
                               const std::vector<double>& d, const std::array<double, 9>& k);

// Decodes a sensor_msgs/CameraInfo: plumb_bob (5 coefficients, radtan), equidistant (4) or no
// distortion (pinhole). Throws ParseError for other models or a malformed message.
Camera DecodeRosCameraInfo(const RosbagMessage& message, const std::string& source);

// Decodes a geometry_msgs/PoseStamped at its header stamp. Throws ParseError when malformed or
// the quaternion is far from unit length (|q| outside [0.9, 1.1]); it is normalised otherwise.
TimedPose DecodeRosPoseStamped(const RosbagMessage& message, const std::string& source);

// A decoded sensor_msgs/Image.
struct RosImage {
  // Header stamp, nanoseconds.
  int64_t t_ns = 0;
  // CV_8UC1 (mono8), CV_16UC1 (mono16) or CV_8UC3 BGR (bgr8, rgb8 converted).
  cv::Mat pixels;
};

// Decodes a sensor_msgs/Image with encoding mono8, mono16, bgr8 or rgb8 (little-endian).
// Throws ParseError for other encodings or a data size that does not match step × height.
RosImage DecodeRosImage(const RosbagMessage& message, const std::string& source);

// Hands the images of a bag read as a dataset (ReadRosbagDataset) to `add` in bag order, decoded
// by DecodeRosImage; nothing when the image topic has no messages. Throws as DecodeRosImage.
void ForEachRosbagImage(const Dataset& dataset, const ImageSink& add);

// Converts a bag into a dataset folder (calib.yaml, events.evb, images/ with images.txt when the
// image topic exists, groundtruth.txt when the ground-truth topic exists, info.json naming the
// source and topics) with WriteRecordingAsDataset: OUT appears only when complete. Streams the bag
// (events in one pass, images in another). Throws as ReadRosbagDataset and OpenDatasetEvents do,
// IoError when writing fails.
RecordingConversionSummary ConvertRosbagToDataset(const std::filesystem::path& bag_path,
                                                  const std::filesystem::path& out_dir,
                                                  const DatasetReaderOptions& reader_options,
                                                  const RecordingConversionOptions& options);

}  // namespace evloc
