// evloc-load: many concurrent sessions against a localizer server (tools/load/load_driver.h).
#include <iostream>
#include <string>
#include <vector>

#include "core/common/cli.h"
#include "tools/load/load_driver.h"

namespace {

// The parsed command line.
struct LoadCommand {
  // The load to run.
  evloc::load::LoadOptions options;
  // --help was given.
  bool help = false;
};

LoadCommand ParseLoadCommand(const std::vector<std::string>& arguments) {
  LoadCommand command;
  command.options = evloc::load::ParseLoadCommandLine(arguments, &command.help);
  return command;
}

}  // namespace

int main(int argc, char** argv) {
  return evloc::RunCommandTool(
      "evloc-load", argc, argv, ParseLoadCommand, evloc::load::LoadUsage,
      [](const LoadCommand& command) {
        const evloc::load::LoadResult result = evloc::load::RunLoad(command.options, std::cout);
        return result.sessions_as_planned == result.sessions ? evloc::kExitSuccess
                                                             : evloc::kExitFailure;
      });
}
