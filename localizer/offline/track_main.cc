// evloc-track: thin entry point; the logic is in track_command.cc.
#include <exception>
#include <iostream>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "localizer/offline/track_command.h"

int main(int argc, char** argv) {
  const std::vector<std::string> arguments(argv + 1, argv + argc);
  evloc::tracking::TrackCommandOptions options;
  try {
    options = evloc::tracking::ParseTrackCommandLine(arguments);
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-track: " << error.what() << "\n(see evloc-track --help)\n";
    return 2;
  }
  if (options.help) {
    std::cout << evloc::tracking::TrackCommandUsage();
    return 0;
  }
  try {
    evloc::tracking::RunTrackCommand(options, std::cerr);
  } catch (const std::exception& error) {
    std::cerr << "evloc-track: error: " << error.what() << "\n";
    return 1;
  }
  return 0;
}
