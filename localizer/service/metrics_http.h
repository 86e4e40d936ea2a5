// A tiny HTTP/1.0 server that answers `GET /metrics` with a text body (the Prometheus text
// exposition format), for `evloc-localizer serve --metrics ADDR`. One connection at a time,
// on its own thread; meant for a loopback address scraped by a local Prometheus agent.
#pragma once

#include <atomic>
#include <functional>
#include <string>
#include <thread>

namespace evloc::service {

// Serves GET /metrics until destroyed.
class MetricsHttpServer {
 public:
  // Produces the body of each response.
  using BodyFunction = std::function<std::string()>;

  // Listens on `address`, "IPV4:PORT" (port 0: any free port). Throws InvalidArgumentError for
  // a malformed address, IoError when it cannot be bound.
  MetricsHttpServer(const std::string& address, BodyFunction body);
  // Stops the thread and closes the socket.
  ~MetricsHttpServer();
  MetricsHttpServer(const MetricsHttpServer&) = delete;
  MetricsHttpServer& operator=(const MetricsHttpServer&) = delete;

  // The port bound.
  int port() const { return port_; }

 private:
  void Serve();
  void Answer(int connection);

  BodyFunction body_;
  int socket_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace evloc::service
