// The evloc-eval command: flags, file reading and writing around EvaluateTrajectory(). The
// binary (main.cc) only prints and turns errors into exit codes.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "tools/eval/evaluation.h"

namespace evloc {

// What evloc-eval was asked to do.
struct EvalCommandOptions {
  // Ground-truth TUM trajectory (--gt).
  std::filesystem::path ground_truth_path;
  // Estimated TUM trajectory (--est).
  std::filesystem::path estimate_path;
  // Evaluation settings (--align, --delta, --max-dt, --fail-cm, --coverage-gap).
  EvaluationOptions evaluation;
  // Where to write the JSON report (--json); none when absent.
  std::optional<std::filesystem::path> json_path;
  // Where to write the PNG figure (--plot); none when absent.
  std::optional<std::filesystem::path> plot_path;
  // --help was given: print the usage and do nothing else.
  bool help = false;

  // Throws InvalidArgumentError unless both trajectories are named (when not help) and the
  // evaluation options are valid.
  void Check() const;
};

// The --help text.
std::string EvalCommandUsage();

// Parses the arguments after the program name. Throws InvalidArgumentError naming the flag for
// unknown flags, missing values and malformed numbers; the result is checked.
EvalCommandOptions ParseEvalCommandLine(const std::vector<std::string>& arguments);

// Reads both trajectories, evaluates, and writes the JSON report and the figure when asked.
// Throws IoError, ParseError or InvalidArgumentError.
EvaluationResult RunEvalCommand(const EvalCommandOptions& options);

}  // namespace evloc
