// evloc-convert: converts a recording (a ROS1 bag or an AEDAT4 file) into the dataset folder
// layout (docs/dataset-format.md) that every evloc tool reads.
#pragma once

#include <filesystem>
#include <ostream>
#include <string>
#include <vector>

#include "core/dataset/dataset.h"
#include "core/dataset/recording_conversion.h"

namespace evloc {

// Everything evloc-convert's command line sets.
struct ConvertCommandOptions {
  // The ROS1 bag or AEDAT4 file to convert (--input, or its older name --bag).
  std::filesystem::path input_path;
  // The dataset folder to write (--out).
  std::filesystem::path out_dir;
  // The bag's topics (--events-topic, --image-topic, --camera-info-topic, --groundtruth-topic).
  RosbagTopics topics;
  // The AEDAT4 streams and side files (--events-topic, --image-topic, --calib, --groundtruth).
  Aedat4DatasetOptions aedat4;
  // Replace an existing output folder (--force).
  bool force = false;
  // Print the usage (--help).
  bool help = false;

  // Throws InvalidArgumentError when --input or --out is missing or a topic is empty.
  void Check() const;
};

// The usage text.
std::string ConvertCommandUsage();

// Parses the arguments after the program name. Throws UsageError for a malformed command line.
ConvertCommandOptions ParseConvertCommandLine(const std::vector<std::string>& arguments);

// Converts and writes a one-line summary to `log`.
RecordingConversionSummary RunConvertCommand(const ConvertCommandOptions& options,
                                             std::ostream& log);

}  // namespace evloc
