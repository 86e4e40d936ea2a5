#include "tools/convert/convert_command.h"

#include "core/common/cli_app.h"
#include "core/common/error.h"

namespace evloc {

void ConvertCommandOptions::Check() const {
  if (help) return;
  if (input_path.empty()) {
    throw InvalidArgumentError("--input is required: a ROS1 bag or an AEDAT4 file");
  }
  if (out_dir.empty()) throw InvalidArgumentError("--out is required: the dataset folder to write");
  topics.Check();
  aedat4.Check();
}

namespace {

// The command line of evloc-convert over `options`.
std::unique_ptr<CommandLine> DeclareConvertCommandLine(ConvertCommandOptions* options) {
  auto line = std::make_unique<CommandLine>(
      "evloc-convert", "--input FILE.bag|FILE.aedat4 --out DIR [options]",
      "Converts a ROS1 bag (format 2.0, uncompressed, bz2 or lz4) or an iniVation AEDAT4 file "
      "(uncompressed, LZ4 or Zstd) into a dataset folder: calib.yaml (from the bag's camera info, "
      "or the AEDAT4 file's --calib), events.evb, images/ with images.txt, groundtruth.txt (TUM), "
      "imu.txt (AEDAT4 IMU samples) and info.json (docs/event-formats.md, sections 7 and 8; "
      "docs/dataset-format.md). evloc-track and evloc-replay also read both directly with "
      "--dataset FILE; the folder is needed for frames mode.");
  line->Add("--input,--bag", "FILE", "the bag or AEDAT4 file (required; --bag is the same flag)",
            &options->input_path)
      .Add("--out", "DIR", "the dataset folder to write; it appears only when complete (required)",
           &options->out_dir)
      .AddFlagsOfUsage(kRecordingFlagsUsage,
                       [options](const std::string& flag, const std::string& value) {
                         return ApplyRecordingFlag(flag, value, &options->topics, &options->aedat4);
                       })
      .Switch("--force", "replace an existing output folder", &options->force)
      .Footer("Exit codes: 0 success, 1 bad input or failure, 2 bad command line.");
  return line;
}

}  // namespace

std::string ConvertCommandUsage() { return HelpOfDeclaredCommandLine(&DeclareConvertCommandLine); }

ConvertCommandOptions ParseConvertCommandLine(const std::vector<std::string>& arguments) {
  ConvertCommandOptions options = ParseDeclaredCommandLine(&DeclareConvertCommandLine, arguments);
  options.Check();
  return options;
}

RecordingConversionSummary RunConvertCommand(const ConvertCommandOptions& options,
                                             std::ostream& log) {
  options.Check();
  DatasetReaderOptions reader_options;
  reader_options.bag_topics = options.topics;
  reader_options.aedat4 = options.aedat4;
  RecordingConversionOptions conversion;
  conversion.force = options.force;
  const RecordingConversionSummary summary =
      ConvertRecordingToDataset(options.input_path, options.out_dir, reader_options, conversion);
  log << "evloc-convert: " << options.out_dir.string() << ": " << summary.events << " events ("
      << summary.dropped_events << " dropped outside the sensor), " << summary.images << " images, "
      << summary.poses << " ground-truth poses";
  if (summary.imu_samples > 0 || summary.triggers > 0) {
    log << ", " << summary.imu_samples << " IMU samples, " << summary.triggers << " triggers";
  }
  log << "\n";
  return summary;
}

}  // namespace evloc
