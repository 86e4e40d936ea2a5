// evloc-localizer: the localizer service's thin main (docs/api.md).
#include <csignal>
#include <iostream>
#include <mutex>
#include <string>
#include <thread>

#include "core/common/cli.h"
#include "localizer/service/serve_command.h"

namespace {

// Serves until SIGINT or SIGTERM.
int Serve(const evloc::service::ServeCommand& command) {
  // Block SIGINT and SIGTERM in every thread; a dedicated thread waits for them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::mutex log_mutex;
  std::cout << "evloc-localizer: effective configuration\n" << command.server.Describe();
  evloc::service::LocalizerServer server(command.server, [&log_mutex](const std::string& line) {
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
  return evloc::kExitSuccess;
}

}  // namespace

int main(int argc, char** argv) {
  return evloc::RunCommandTool("evloc-localizer", argc, argv, evloc::service::ParseServeCommandLine,
                               evloc::service::ServeUsage, Serve);
}
