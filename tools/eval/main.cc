// evloc-eval: scores an estimated trajectory against ground truth (see --help).
#include <iostream>
#include <string>

#include "core/common/cli.h"
#include "core/common/error.h"
#include "tools/eval/eval_command.h"

int main(int argc, char** argv) {
  return evloc::RunCommandTool(
      "evloc-eval", argc, argv, evloc::ParseEvalCommandLine, evloc::EvalCommandUsage,
      [](const evloc::EvalCommandOptions& options) {
        evloc::EvaluationResult result;
        try {
          result = evloc::RunEvalCommand(options);
        } catch (const evloc::Error& error) {
          throw evloc::Error(std::string(error.what()) +
                             " (check that both files are TUM trajectories, t tx ty tz qx qy qz "
                             "qw, on the same clock)");
        }
        std::cout << evloc::FormatEvaluationTable(result);
        return evloc::kExitSuccess;
      });
}
