// evloc-eval: scores an estimated trajectory against ground truth (see --help).
#include <iostream>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "tools/eval/eval_command.h"

int main(int argc, char** argv) {
  const std::vector<std::string> arguments(argv + 1, argv + argc);
  evloc::EvalCommandOptions options;
  try {
    options = evloc::ParseEvalCommandLine(arguments);
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-eval: " << error.what() << "\nRun evloc-eval --help for the usage.\n";
    return 2;
  }
  if (options.help) {
    std::cout << evloc::EvalCommandUsage();
    return 0;
  }
  try {
    const evloc::EvaluationResult result = evloc::RunEvalCommand(options);
    std::cout << evloc::FormatEvaluationTable(result);
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-eval: " << error.what()
              << "\nCheck that both files are TUM trajectories (t tx ty tz qx qy qz qw) on the "
                 "same clock.\n";
    return 1;
  }
  return 0;
}
