// evloc-replay: streams a dataset to a localizer server (docs/api.md).
#include <iostream>

#include "core/common/error.h"
#include "tools/replay/replay.h"

int main(int argc, char** argv) {
  const std::vector<std::string> arguments(argv + 1, argv + argc);
  evloc::replay::ReplayOptions options;
  bool help = false;
  try {
    options = evloc::replay::ParseReplayCommandLine(arguments, &help);
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-replay: " << error.what() << "\n";
    return 2;
  }
  if (help) {
    std::cout << evloc::replay::ReplayUsage();
    return 0;
  }
  try {
    evloc::replay::RunReplay(options, std::cout);
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-replay: " << error.what() << "\n";
    return 1;
  }
  return 0;
}
