// evloc-localizer: the localizer service's thin main (docs/api.md): `serve`, or `locate` one image.
#include <csignal>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/common/cli.h"
#include "core/common/log.h"
#include "localizer/service/locate_command.h"
#include "localizer/service/serve_command.h"

namespace {

// Logs the effective configuration: in text, the "key: value" lines under one heading (as
// before JSON logs existed); in JSON, one record whose fields are those keys.
void LogConfiguration(evloc::Logger& logger, const std::string& description) {
  if (logger.format() == evloc::LogFormat::kText) {
    logger.Info("effective configuration\n" +
                description.substr(0, description.find_last_not_of('\n') + 1));
    return;
  }
  std::vector<evloc::LogField> fields;
  std::istringstream lines(description);
  for (std::string line; std::getline(lines, line);) {
    const size_t colon = line.find(": ");
    if (colon == std::string::npos) continue;
    fields.emplace_back(line.substr(0, colon), line.substr(colon + 2));
  }
  logger.Log(evloc::LogLevel::kInfo, "effective configuration", fields);
}

// Serves until SIGINT or SIGTERM.
int Serve(const evloc::service::ServeCommand& command) {
  // Block SIGINT and SIGTERM in every thread; a dedicated thread waits for them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  // Records are written to stdout by the logger's own thread: a slow terminal or a full pipe
  // never stalls a tracking worker (records beyond the queue are dropped and counted in
  // /metrics, evloc_log_records_dropped_total).
  const auto logger = std::make_shared<evloc::Logger>("evloc-localizer", command.logging,
                                                      evloc::StandardOutputSink());
  LogConfiguration(*logger, command.server.Describe());
  evloc::service::LocalizerServer server(command.server, logger);
  logger->Info("serving on port " + std::to_string(server.port()), {{"port", server.port()}});
  if (server.metrics_port() != 0) {
    logger->Info("metrics on port " + std::to_string(server.metrics_port()) + " (GET /metrics)",
                 {{"port", server.metrics_port()}});
  }
  std::thread stopper([&server, &signals] {
    int received = 0;
    sigwait(&signals, &received);
    server.Shutdown();
  });
  server.Wait();
  stopper.join();
  logger->Info("stopped");
  logger->Flush();
  return evloc::kExitSuccess;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1 && std::string(argv[1]) == "locate") {
    return evloc::service::RunLocateTool(argc, argv);
  }
  return evloc::RunCommandTool("evloc-localizer", argc, argv, evloc::service::ParseServeCommandLine,
                               evloc::service::ServeUsage, Serve);
}
