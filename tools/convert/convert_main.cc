// evloc-convert: thin entry point; the logic is in convert_command.cc.
#include <iostream>

#include "core/common/cli.h"
#include "tools/convert/convert_command.h"

int main(int argc, char** argv) {
  return evloc::RunCommandTool("evloc-convert", argc, argv, evloc::ParseConvertCommandLine,
                               evloc::ConvertCommandUsage,
                               [](const evloc::ConvertCommandOptions& options) {
                                 evloc::RunConvertCommand(options, std::cerr);
                                 return evloc::kExitSuccess;
                               });
}
