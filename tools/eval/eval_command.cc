#include "tools/eval/eval_command.h"

#include "core/common/cli.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/trajectory/tum_io.h"
#include "tools/eval/plot.h"

namespace evloc {

void EvalCommandOptions::Check() const {
  if (help) return;
  if (ground_truth_path.empty()) {
    throw InvalidArgumentError("--gt is required: the ground-truth TUM trajectory");
  }
  if (estimate_path.empty()) {
    throw InvalidArgumentError("--est is required: the estimated TUM trajectory");
  }
  evaluation.Check();
}

std::string EvalCommandUsage() {
  return R"(Usage: evloc-eval --gt GT.txt --est EST.txt [options]

Scores an estimated camera trajectory against ground truth. Both files are TUM trajectories
(`t tx ty tz qx qy qz qw`, world_from_cam, seconds and metres). Method: docs/accuracy.md.

Options:
  --gt PATH            ground-truth TUM trajectory (required)
  --est PATH           estimated TUM trajectory (required)
  --align MODE         none | se3 | sim3: alignment of the estimate before measuring
                       (default none: a map-based tracker lives in the map frame)
  --delta SECONDS      RPE time step (default 1.0)
  --max-dt SECONDS     association tolerance to the nearest ground-truth pose (default 0.02)
  --fail-cm CM         translation error that counts as a failure, for failed_at_s (default 10)
  --coverage-gap SECONDS
                       estimates further apart than this leave the time between uncovered
                       (default 0.1)
  --json PATH          write the figures as JSON
  --plot PATH          write a PNG: top view of both trajectories and the error over time
  --help               print this help

Exit codes: 0 success, 1 bad input (unreadable or malformed file, no matching poses),
2 bad command line.
)";
}

EvalCommandOptions ParseEvalCommandLine(const std::vector<std::string>& arguments) {
  EvalCommandOptions options;
  for (size_t i = 0; i < arguments.size(); ++i) {
    const std::string& flag = arguments[i];
    if (flag == "--help" || flag == "-h") {
      options.help = true;
      continue;
    }
    const std::string& value = TakeFlagValue(arguments, &i);
    if (flag == "--gt") {
      options.ground_truth_path = value;
    } else if (flag == "--est") {
      options.estimate_path = value;
    } else if (flag == "--align") {
      options.evaluation.alignment = ParseAlignment(value);
    } else if (flag == "--delta") {
      options.evaluation.delta_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-dt") {
      options.evaluation.max_dt_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--fail-cm") {
      options.evaluation.fail_cm = ParseDoubleFlag(flag, value);
    } else if (flag == "--coverage-gap") {
      options.evaluation.coverage_max_gap_s = ParseDoubleFlag(flag, value);
    } else if (flag == "--json") {
      options.json_path = value;
    } else if (flag == "--plot") {
      options.plot_path = value;
    } else {
      throw InvalidArgumentError("unknown flag '" + flag + "'");
    }
  }
  options.Check();
  return options;
}

EvaluationResult RunEvalCommand(const EvalCommandOptions& options) {
  options.Check();
  const Trajectory ground_truth = ReadTumTrajectory(options.ground_truth_path);
  if (ground_truth.empty()) {
    throw InvalidArgumentError(options.ground_truth_path.string() + " holds no pose");
  }
  const Trajectory estimate = ReadTumTrajectory(options.estimate_path);
  if (estimate.empty()) {
    throw InvalidArgumentError(options.estimate_path.string() + " holds no pose");
  }
  const EvaluationResult result = EvaluateTrajectory(ground_truth, estimate, options.evaluation);
  if (options.json_path) {
    WriteFileAtomically(*options.json_path, EvaluationToJson(result).dump(2) + "\n");
  }
  if (options.plot_path) {
    WriteEvaluationPlot(*options.plot_path, ground_truth, estimate, result);
  }
  return result;
}

}  // namespace evloc
