#include "tools/eval/eval_command.h"

#include "core/common/cli.h"
#include "core/common/cli_app.h"
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

namespace {

// The command line of evloc-eval over `options`.
std::unique_ptr<CommandLine> DeclareEvalCommandLine(EvalCommandOptions* options) {
  auto line = std::make_unique<CommandLine>(
      "evloc-eval", "--gt GT.txt --est EST.txt [options]",
      "Scores an estimated camera trajectory against ground truth. Both files are TUM "
      "trajectories (`t tx ty tz qx qy qz qw`, world_from_cam, seconds and metres). Method: "
      "docs/accuracy.md.");
  EvaluationOptions& evaluation = options->evaluation;
  line->Add("--gt", "PATH", "ground-truth TUM trajectory (required)", &options->ground_truth_path)
      .Add("--est", "PATH", "estimated TUM trajectory (required)", &options->estimate_path)
      .Add("--align", "MODE",
           "none | se3 | sim3: alignment of the estimate before measuring (default none: a "
           "map-based tracker lives in the map frame)",
           [&evaluation](const std::string&, const std::string& value) {
             evaluation.alignment = ParseAlignment(value);
           })
      .Add("--delta", "SECONDS", "RPE time step (default 1.0)", &evaluation.delta_s)
      .Add("--max-dt", "SECONDS",
           "association tolerance to the nearest ground-truth pose (default 0.02)",
           &evaluation.max_dt_s)
      .Add("--fail-cm", "CM",
           "translation error that counts as a failure, for failed_at_s (default 10)",
           &evaluation.fail_cm)
      .Add("--coverage-gap", "SECONDS",
           "estimates further apart than this leave the time between uncovered (default 0.1)",
           &evaluation.coverage_max_gap_s)
      .Add("--segments", "M,M,...",
           "also the drift over these path lengths of the ground truth, metres: the mean "
           "translation error in % of the length and rotation error in deg/m over every "
           "segment (odometry benchmarks' figure; default: none)",
           [&evaluation](const std::string& flag, const std::string& value) {
             evaluation.segment_lengths_m = ParseDoubleListFlag(flag, value);
           })
      .Add("--json", "PATH", "write the figures as JSON", &options->json_path)
      .Add("--plot", "PATH", "write a PNG: top view of both trajectories and the error over time",
           &options->plot_path)
      .Footer(
          "Exit codes: 0 success, 1 bad input (unreadable or malformed file, no matching poses), "
          "2 bad command line.");
  return line;
}

}  // namespace

std::string EvalCommandUsage() { return HelpOfDeclaredCommandLine(&DeclareEvalCommandLine); }

EvalCommandOptions ParseEvalCommandLine(const std::vector<std::string>& arguments) {
  EvalCommandOptions options = ParseDeclaredCommandLine(&DeclareEvalCommandLine, arguments);
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
