// AEDAT4 files (iniVation DV) as datasets: events through core/events' Aedat4EventReader, the
// camera and ground truth from side files (the format holds neither), frames and IMU samples for
// the converter to the dataset folder layout (docs/event-formats.md, section 8;
// docs/dataset-format.md).
#pragma once

#include <filesystem>

#include <opencv2/core.hpp>

#include "core/dataset/dataset.h"
#include "core/dataset/recording_conversion.h"
#include "core/events/aedat4.h"

namespace evloc {

// Reads an AEDAT4 file as a dataset: the camera from options.aedat4.calibration (an evloc YAML
// camera, or an ECD calib.txt sized from the events stream), which must match the events
// stream's sensor size; the ground truth from options.aedat4.groundtruth when given; `root` and
// `events_path` are the file. Reads the header only. Throws InvalidArgumentError when the
// calibration is missing or does not match, or a named stream has another type (the message
// lists the file's streams); ParseError for a malformed file; IoError / ParseError for the side
// files.
Dataset ReadAedat4Dataset(const std::filesystem::path& path, const DatasetReaderOptions& options);

// The pixels of a decoded frame as an OpenCV image: CV_8UC1, CV_16UC1, CV_8UC3 (BGR) or CV_8UC4
// (BGRA), a copy.
cv::Mat Aedat4FrameImage(const Aedat4Frame& frame);

// Hands the frames of an AEDAT4 file read as a dataset (ReadAedat4Dataset) to `add` in file order,
// as Aedat4FrameImage gives them; nothing when the file has no frames stream. Throws ParseError
// for a malformed packet.
void ForEachAedat4Frame(const Dataset& dataset, const ImageSink& add);

// Converts an AEDAT4 file into a dataset folder (calib.yaml, events.evb, images/ with images.txt
// from the frames stream when it exists, imu.txt from the IMU streams when there are any,
// groundtruth.txt when given, info.json naming the source and streams, with the counts of
// IMU samples and triggers) with WriteRecordingAsDataset: OUT appears only when complete. Streams
// the file (events in one pass, frames, IMU and triggers in another). Throws as
// ReadAedat4Dataset and OpenDatasetEvents do, IoError when writing fails.
RecordingConversionSummary ConvertAedat4ToDataset(const std::filesystem::path& path,
                                                  const std::filesystem::path& out_dir,
                                                  const DatasetReaderOptions& reader_options,
                                                  const RecordingConversionOptions& options);

}  // namespace evloc
