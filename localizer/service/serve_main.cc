// evloc-localizer: the localizer service's thin main (docs/api.md).
#include <csignal>
#include <iostream>
#include <mutex>
#include <thread>

#include "core/common/error.h"
#include "localizer/service/serve_command.h"

int main(int argc, char** argv) {
  using evloc::service::LocalizerServer;
  const std::vector<std::string> arguments(argv + 1, argv + argc);
  evloc::service::ServeCommand command;
  try {
    command = evloc::service::ParseServeCommandLine(arguments);
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-localizer: " << error.what() << "\n";
    return 2;
  }
  if (command.help) {
    std::cout << evloc::service::ServeUsage();
    return 0;
  }
  // Block SIGINT and SIGTERM in every thread; a dedicated thread waits for them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  try {
    std::mutex log_mutex;
    std::cout << "evloc-localizer: effective configuration\n" << command.server.Describe();
    LocalizerServer server(command.server, [&log_mutex](const std::string& line) {
      std::lock_guard<std::mutex> lock(log_mutex);
      std::cout << "evloc-localizer: " << line << std::endl;
    });
    std::cout << "evloc-localizer: serving on port " << server.port() << std::endl;
    if (server.metrics_port() != 0) {
      std::cout << "evloc-localizer: metrics on port " << server.metrics_port() << " (GET /metrics)"
                << std::endl;
    }
    std::thread stopper([&server, &signals] {
      int received = 0;
      sigwait(&signals, &received);
      server.Shutdown();
    });
    server.Wait();
    stopper.join();
    std::cout << "evloc-localizer: stopped\n";
  } catch (const evloc::Error& error) {
    std::cerr << "evloc-localizer: " << error.what() << "\n";
    return 1;
  }
  return 0;
}
