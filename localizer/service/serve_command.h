// The command line of `evloc-localizer serve` (docs/api.md): every flag maps to a field of
// LocalizerServerOptions.
#pragma once

#include <string>
#include <vector>

#include "localizer/service/localizer_server.h"

namespace evloc::service {

// What the command line asks for.
struct ServeCommand {
  // Print the usage and exit.
  bool help = false;
  // The server options.
  LocalizerServerOptions server;
  // The service's log (--log-level, --log-format; docs/api.md, "Logs").
  LoggerOptions logging;
};

// The usage text of `evloc-localizer`.
std::string ServeUsage();

// Parses the arguments after the program name (the first must be `serve`, or `--help`). Throws
// InvalidArgumentError naming the flag for an unknown flag, a missing or bad value, or invalid
// options.
ServeCommand ParseServeCommandLine(const std::vector<std::string>& arguments);

}  // namespace evloc::service
