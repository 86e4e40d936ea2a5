// evloc-replay: streams a dataset to a localizer server (docs/api.md), or checks its health.
#include <iostream>

#include "core/common/error.h"
#include "tools/replay/replay.h"

int main(int argc, char** argv) {
  const std::vector<std::string> arguments(argv + 1, argv + argc);
  evloc::replay::ReplayCommand command;
  try {
    command = evloc::replay::ParseReplayCommandLine(arguments);
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-replay: " << error.what() << "\n";
    return 2;
  }
  if (command.help) {
    std::cout << evloc::replay::ReplayUsage();
    return 0;
  }
  try {
    if (command.health_check) {
      const std::string status =
          evloc::replay::CheckHealth(command.options, command.health_timeout_s);
      std::cout << "evloc-replay: " << command.options.server << " is " << status << "\n";
      return status == "SERVING" ? 0 : 1;
    }
    evloc::replay::RunReplay(command.options, std::cout);
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-replay: " << error.what() << "\n";
    return 1;
  }
  return 0;
}
