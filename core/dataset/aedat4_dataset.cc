#include "core/dataset/aedat4_dataset.h"

#include <cstring>
#include <sstream>

#include "core/camera/calibration_file.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/trajectory/tum_io.h"

namespace evloc {
namespace {

// Standard gravity, m/s^2 (DV records accelerations in g).
constexpr double kStandardGravity = 9.80665;
constexpr double kDegreesToRadians = 3.14159265358979323846 / 180.0;

// The stream `name` of type `type`, nullptr when absent. Throws InvalidArgumentError when it has
// another type.
const Aedat4Stream* StreamOfType(const Aedat4Reader& file, const std::string& name,
                                 const std::string& type, const char* what) {
  const Aedat4Stream* stream = file.FindStream(name);
  if (stream != nullptr && stream->type != type) {
    throw InvalidArgumentError(file.source() + ": the " + what + " stream '" + name +
                               "' has type " + stream->type + ", expected " + type +
                               "; the file's streams are: " + file.DescribeStreams());
  }
  return stream;
}

}  // namespace

Dataset ReadAedat4Dataset(const std::filesystem::path& path, const DatasetReaderOptions& options) {
  options.Check();
  const Aedat4DatasetOptions& streams = options.aedat4;
  Aedat4Reader file(path);
  Dataset dataset;
  dataset.root = path;
  dataset.events_path = path;
  const Aedat4Stream* events = StreamOfType(file, streams.events, "EVTS", "events");
  const Aedat4Stream* frames = StreamOfType(file, streams.frames, "FRME", "frames");
  dataset.aedat4 = Aedat4DatasetSource{streams, file.DescribeStreams(), frames != nullptr};
  if (streams.calibration.empty()) {
    throw InvalidArgumentError(
        path.string() +
        ": an AEDAT4 file holds no camera calibration; give the camera with --calib FILE (an "
        "evloc YAML camera, a Kalibr camchain, a ROS camera_info, an OpenCV or COLMAP file, or "
        "an ECD calib.txt: docs/camera.md). Its streams are: " +
        file.DescribeStreams());
  }
  const std::optional<SensorSize> size = events != nullptr ? events->size : std::nullopt;
  // A calibration without an image size (ECD calib.txt) takes the events stream's; with neither,
  // ReadCalibrationFile says so.
  dataset.camera = ReadCalibrationFile(streams.calibration, size ? size->width : 0,
                                       size ? size->height : 0, &dataset.calibration_notes);
  if (size && (dataset.camera.width != size->width || dataset.camera.height != size->height)) {
    throw InvalidArgumentError(
        path.string() + ": the camera of " + streams.calibration.string() + " is " +
        std::to_string(dataset.camera.width) + "x" + std::to_string(dataset.camera.height) +
        " but the events stream '" + streams.events + "' is " + std::to_string(size->width) + "x" +
        std::to_string(size->height) + " (give the calibration of this camera)");
  }
  if (!streams.groundtruth.empty()) {
    dataset.ground_truth = ReadTumTrajectory(streams.groundtruth);
  }
  dataset.layout = DatasetLayout::kAedat4;
  return dataset;
}

cv::Mat Aedat4FrameImage(const Aedat4Frame& frame) {
  const int type = frame.bytes_per_channel == 2 ? CV_16UC1 : CV_8UC(frame.channels);
  cv::Mat image(frame.height, frame.width, type);
  std::memcpy(image.data, frame.pixels.data(), frame.pixels.size());
  return image;
}

void ForEachAedat4Frame(const Dataset& dataset, const ImageSink& add) {
  if (!dataset.aedat4 || !dataset.aedat4->has_frames) return;
  Aedat4Reader file(dataset.root);
  const Aedat4Stream* frames = file.FindStream(dataset.aedat4->options.frames);
  if (frames == nullptr) return;
  file.SetStreams({frames->id});
  Aedat4Packet packet;
  while (file.Next(&packet)) {
    const Aedat4Frame frame = DecodeAedat4Frame(packet, file.source());
    add(frame.t_ns, Aedat4FrameImage(frame));
  }
}

RecordingConversionSummary ConvertAedat4ToDataset(const std::filesystem::path& path,
                                                  const std::filesystem::path& out_dir,
                                                  const DatasetReaderOptions& reader_options,
                                                  const RecordingConversionOptions& options) {
  const Dataset dataset = ReadAedat4Dataset(path, reader_options);
  const Aedat4DatasetOptions& streams = reader_options.aedat4;
  // The second pass: frames, IMU samples and triggers, in file order.
  Aedat4Reader file(path);
  std::vector<int32_t> selected;
  const Aedat4Stream* frames = file.FindStream(streams.frames);
  if (frames != nullptr) selected.push_back(frames->id);
  for (const char* type : {"IMUS", "TRIG"}) {
    for (const Aedat4Stream* stream : Aedat4StreamsOfType(file, type)) {
      selected.push_back(stream->id);
    }
  }
  std::ostringstream imu_text;
  uint64_t imu_samples = 0;
  uint64_t triggers = 0;
  const auto for_each_image = [&](const ImageSink& add_image) {
    if (selected.empty()) return;
    file.SetStreams(selected);
    Aedat4Packet packet;
    std::vector<Aedat4ImuSample> imu;
    std::vector<Aedat4Trigger> trigger_list;
    while (file.Next(&packet)) {
      if (packet.stream == frames) {
        const Aedat4Frame frame = DecodeAedat4Frame(packet, file.source());
        add_image(frame.t_ns, Aedat4FrameImage(frame));
      } else if (packet.stream->type == "IMUS") {
        imu.clear();
        DecodeAedat4Imu(packet, file.source(), &imu);
        for (const Aedat4ImuSample& sample : imu) {
          imu_text << FormatNanosecondsAsSeconds(sample.t_ns);
          for (float value : sample.accelerometer_g) imu_text << ' ' << value * kStandardGravity;
          for (float value : sample.gyroscope_dps) imu_text << ' ' << value * kDegreesToRadians;
          imu_text << '\n';
        }
        imu_samples += imu.size();
      } else {
        trigger_list.clear();
        DecodeAedat4Triggers(packet, file.source(), &trigger_list);
        triggers += trigger_list.size();
      }
    }
  };
  const nlohmann::json info = {{"source", path.filename().string()},
                               {"converted_from", "AEDAT4"},
                               {"compression", Aedat4CompressionName(file.compression())},
                               {"streams",
                                {{"events", streams.events},
                                 {"frames", dataset.aedat4->has_frames ? streams.frames : ""},
                                 {"all", dataset.aedat4->stream_list}}}};
  return WriteRecordingAsDataset(dataset, out_dir, options, for_each_image, info,
                                 [&](DatasetWriter* writer, RecordingConversionSummary* summary) {
                                   summary->imu_samples = imu_samples;
                                   summary->triggers = triggers;
                                   if (imu_samples > 0) {
                                     WriteFileAtomically(
                                         writer->staging_dir() / dataset_files::kImuTxt,
                                         "# t_s ax ay az (m/s^2) gx gy gz (rad/s), from " +
                                             path.filename().string() + "\n" + imu_text.str());
                                   }
                                 });
}

}  // namespace evloc
