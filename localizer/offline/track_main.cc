// evloc-track: thin entry point; the logic is in track_command.cc.
#include <iostream>

#include "core/common/cli.h"
#include "localizer/offline/track_command.h"

int main(int argc, char** argv) {
  return evloc::RunCommandTool("evloc-track", argc, argv, evloc::tracking::ParseTrackCommandLine,
                               evloc::tracking::TrackCommandUsage,
                               [](const evloc::tracking::TrackCommandOptions& options) {
                                 evloc::tracking::RunTrackCommand(options, std::cerr);
                                 return evloc::kExitSuccess;
                               });
}
