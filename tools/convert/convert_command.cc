#include "tools/convert/convert_command.h"

#include "core/common/cli.h"
#include "core/common/error.h"

namespace evloc {

void ConvertCommandOptions::Check() const {
  if (help) return;
  if (bag_path.empty()) throw InvalidArgumentError("--bag is required: a ROS1 bag");
  if (out_dir.empty()) throw InvalidArgumentError("--out is required: the dataset folder to write");
  topics.Check();
}

std::string ConvertCommandUsage() {
  return R"(Usage: evloc-convert --bag FILE.bag --out DIR [options]

Converts a ROS1 bag (format 2.0, uncompressed, bz2 or lz4) into a dataset folder: calib.yaml from
the camera info, events.evb, images/ with images.txt, groundtruth.txt (TUM) and info.json
(docs/event-formats.md, section 7; docs/dataset-format.md). evloc-track and evloc-replay also
read the bag directly with --dataset FILE.bag; the folder is needed for frames mode.

Options:
  --bag FILE.bag         the bag (required)
  --out DIR              the dataset folder to write; it appears only when complete (required)
)" + std::string(kRosbagTopicFlagsUsage) +
         R"(  --force                replace an existing output folder
  --help                 print this help

Exit codes: 0 success, 1 bad input or failure, 2 bad command line.
)";
}

ConvertCommandOptions ParseConvertCommandLine(const std::vector<std::string>& arguments) {
  ConvertCommandOptions options;
  for (size_t i = 0; i < arguments.size(); ++i) {
    const std::string& flag = arguments[i];
    if (flag == "--help" || flag == "-h") {
      options.help = true;
      continue;
    }
    if (flag == "--force") {
      options.force = true;
      continue;
    }
    const std::string& value = TakeFlagValue(arguments, &i);
    if (flag == "--bag") {
      options.bag_path = value;
    } else if (flag == "--out") {
      options.out_dir = value;
    } else if (!ApplyRosbagTopicFlag(flag, value, &options.topics)) {
      throw UsageError("unknown flag '" + flag + "' (see --help)");
    }
  }
  options.Check();
  return options;
}

RosbagConversionSummary RunConvertCommand(const ConvertCommandOptions& options, std::ostream& log) {
  options.Check();
  DatasetReaderOptions reader_options;
  reader_options.bag_topics = options.topics;
  RosbagConversionOptions conversion;
  conversion.force = options.force;
  const RosbagConversionSummary summary =
      ConvertRosbagToDataset(options.bag_path, options.out_dir, reader_options, conversion);
  log << "evloc-convert: " << options.out_dir.string() << ": " << summary.events << " events ("
      << summary.dropped_events << " dropped outside the sensor), " << summary.images << " images, "
      << summary.poses << " ground-truth poses\n";
  return summary;
}

}  // namespace evloc
