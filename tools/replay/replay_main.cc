// evloc-replay: streams a dataset to a localizer server (docs/api.md), or checks its health.
#include <iostream>
#include <string>

#include "core/common/cli.h"
#include "tools/replay/replay.h"

int main(int argc, char** argv) {
  return evloc::RunCommandTool(
      "evloc-replay", argc, argv, evloc::replay::ParseReplayCommandLine, evloc::replay::ReplayUsage,
      [](const evloc::replay::ReplayCommand& command) {
        if (command.options.token) {
          std::cerr << "evloc-replay: warning: --token shows the secret to every user of this "
                       "machine (ps, /proc/PID/cmdline) and keeps it in the shell history; use "
                       "--token-file FILE\n";
        }
        if (command.health_check) {
          const std::string status = evloc::replay::CheckHealth(
              command.options, command.health_timeout_s, command.health_service);
          std::cout << "evloc-replay: " << command.options.server << " is " << status << "\n";
          return status == "SERVING" ? evloc::kExitSuccess : evloc::kExitFailure;
        }
        evloc::replay::RunReplay(command.options, std::cout);
        return evloc::kExitSuccess;
      });
}
