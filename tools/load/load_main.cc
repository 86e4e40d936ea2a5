// evloc-load: many concurrent sessions against a localizer server (tools/load/load_driver.h).
#include <iostream>

#include "core/common/error.h"
#include "tools/load/load_driver.h"

int main(int argc, char** argv) {
  const std::vector<std::string> arguments(argv + 1, argv + argc);
  evloc::load::LoadOptions options;
  try {
    bool help = false;
    options = evloc::load::ParseLoadCommandLine(arguments, &help);
    if (help) {
      std::cout << evloc::load::LoadUsage();
      return 0;
    }
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-load: " << error.what() << "\n";
    return 2;
  }
  try {
    const evloc::load::LoadResult result = evloc::load::RunLoad(options, std::cout);
    return result.sessions_as_planned == result.sessions ? 0 : 1;
  } catch (const std::exception& error) {
    std::cerr << "evloc-load: " << error.what() << "\n";
    return 1;
  }
}
