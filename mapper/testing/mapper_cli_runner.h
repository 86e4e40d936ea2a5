// Test helper: runs `evloc-mapper` in-process (RunMapperCli) and keeps its exit code and output.
#pragma once

#include <sstream>
#include <string>
#include <vector>

#include "mapper/mapper_cli.h"

namespace evloc::testing {

// The outcome of one CLI run.
struct CliResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};

// Runs `evloc-mapper ARGUMENTS...`.
inline CliResult RunCli(std::vector<std::string> arguments) {
  arguments.insert(arguments.begin(), "evloc-mapper");
  std::vector<const char*> argv;
  for (const std::string& argument : arguments) argv.push_back(argument.c_str());
  std::ostringstream out, err;
  CliResult result;
  result.exit_code = RunMapperCli(static_cast<int>(argv.size()), argv.data(), out, err);
  result.out = out.str();
  result.err = err.str();
  return result;
}

}  // namespace evloc::testing
