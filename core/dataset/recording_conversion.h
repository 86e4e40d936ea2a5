// Converting a recording read as a dataset (a ROS1 bag, an AEDAT4 file) into the dataset folder
// layout (docs/dataset-format.md): the part every format shares (camera, events, images, ground
// truth, info.json, the atomic commit) and the dispatcher evloc-convert calls.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/dataset/dataset.h"

namespace evloc {

// Options of the converters.
struct RecordingConversionOptions {
  // Replace an existing output folder.
  bool force = false;

  // Nothing to check; present for uniformity with other options structs.
  void Check() const {}
};

// What a converter wrote.
struct RecordingConversionSummary {
  // Events written to events.evb.
  uint64_t events = 0;
  // Events the reader dropped (outside the sensor).
  uint64_t dropped_events = 0;
  // Images written (0 when the recording has no image topic or frames stream).
  uint64_t images = 0;
  // Ground-truth poses written (0 when there is no ground truth).
  uint64_t poses = 0;
  // IMU samples written to imu.txt (AEDAT4; bags: 0).
  uint64_t imu_samples = 0;
  // Triggers counted in info.json (AEDAT4; bags: 0).
  uint64_t triggers = 0;
};

// Writes `dataset` (read from a recording) into OUT with DatasetWriter: calib.yaml, events.evb
// (streamed through OpenDatasetEvents), the images `for_each_image` hands to its sink (16-bit
// scaled to 8 bits, BGRA to BGR), groundtruth.txt when there is ground truth, whatever `extra`
// adds to the staging folder, and info.json (`info` plus "counts"); OUT appears only when
// complete. Throws as OpenDatasetEvents and the readers do, IoError when writing fails.
RecordingConversionSummary WriteRecordingAsDataset(
    const Dataset& dataset, const std::filesystem::path& out_dir,
    const RecordingConversionOptions& options,
    const std::function<void(const ImageSink&)>& for_each_image, nlohmann::json info,
    const std::function<void(DatasetWriter*, RecordingConversionSummary*)>& extra = {});

// Converts a ROS1 bag (ConvertRosbagToDataset) or an AEDAT4 file (ConvertAedat4ToDataset),
// detected from its first bytes. Throws InvalidArgumentError for any other file.
RecordingConversionSummary ConvertRecordingToDataset(const std::filesystem::path& path,
                                                     const std::filesystem::path& out_dir,
                                                     const DatasetReaderOptions& reader_options,
                                                     const RecordingConversionOptions& options);

}  // namespace evloc
