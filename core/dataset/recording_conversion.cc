#include "core/dataset/recording_conversion.h"

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/dataset/aedat4_dataset.h"
#include "core/dataset/rosbag_dataset.h"
#include "core/events/aedat4.h"
#include "core/events/evb.h"
#include "core/events/rosbag.h"

namespace evloc {

RecordingConversionSummary WriteRecordingAsDataset(
    const Dataset& dataset, const std::filesystem::path& out_dir,
    const RecordingConversionOptions& options,
    const std::function<void(const ImageSink&)>& for_each_image, nlohmann::json info,
    const std::function<void(DatasetWriter*, RecordingConversionSummary*)>& extra) {
  options.Check();
  DatasetWriterOptions writer_options;
  writer_options.force = options.force;
  DatasetWriter writer(out_dir, writer_options);
  RecordingConversionSummary summary;
  writer.WriteCamera(dataset.camera);
  {
    const auto reader = OpenDatasetEvents(dataset);
    EvbWriter events(writer.staging_dir() / dataset_files::kEventsEvb, reader->sensor_size());
    EventBuffer buffer;
    while (reader->Read(1 << 16, &buffer) > 0) {
      events.Write(buffer);
      buffer.clear();
    }
    events.Close();
    summary.events = events.event_count();
    summary.dropped_events = reader->dropped_event_count();
  }
  if (for_each_image) {
    for_each_image([&](int64_t t_ns, const cv::Mat& pixels) {
      cv::Mat eight = pixels;
      if (pixels.depth() == CV_16U) pixels.convertTo(eight, CV_8U, 1.0 / 257.0);
      if (eight.channels() == 4) cv::cvtColor(eight, eight, cv::COLOR_BGRA2BGR);
      writer.AddImage(t_ns, eight);
      ++summary.images;
    });
  }
  if (dataset.ground_truth) {
    writer.WriteGroundTruth(*dataset.ground_truth);
    summary.poses = dataset.ground_truth->size();
  }
  if (extra) extra(&writer, &summary);
  info["counts"] = {{"events", summary.events},
                    {"dropped_events", summary.dropped_events},
                    {"images", summary.images},
                    {"poses", summary.poses}};
  if (dataset.aedat4) {
    info["counts"]["imu_samples"] = summary.imu_samples;
    info["counts"]["triggers"] = summary.triggers;
  }
  writer.WriteInfo(info);
  writer.Commit();
  return summary;
}

RecordingConversionSummary ConvertRecordingToDataset(const std::filesystem::path& path,
                                                     const std::filesystem::path& out_dir,
                                                     const DatasetReaderOptions& reader_options,
                                                     const RecordingConversionOptions& options) {
  if (IsRosbagFile(path)) return ConvertRosbagToDataset(path, out_dir, reader_options, options);
  if (IsAedat4File(path)) return ConvertAedat4ToDataset(path, out_dir, reader_options, options);
  throw InvalidArgumentError(path.string() +
                             " is neither a ROS1 bag ('#ROSBAG V2.0') nor an AEDAT4 file "
                             "('#!AER-DAT4.0'); evloc-convert converts those two");
}

}  // namespace evloc
