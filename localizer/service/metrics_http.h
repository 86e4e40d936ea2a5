// A tiny HTTP/1.0 server that answers `GET /metrics` with a text body (the Prometheus text
// exposition format), for `evloc-localizer serve --metrics ADDR`. One connection at a time,
// on its own thread, each with an absolute deadline (a slow or silent client is dropped when it
// passes, and stopping never waits longer than one poll); meant for a scraper nearby.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <string>
#include <thread>

namespace evloc::service {

// Serves GET /metrics until destroyed.
class MetricsHttpServer {
 public:
  // Produces the body of each response.
  using BodyFunction = std::function<std::string()>;

  // Default of the time one connection may take from accept to the last byte sent, seconds.
  static constexpr double kDefaultConnectionDeadlineS = 2.0;

  // Listens on `address`, "IPV4:PORT" (port 0: any free port); a connection is closed when it is
  // not answered `connection_deadline_s` after it was accepted. Throws InvalidArgumentError for
  // a malformed address or a deadline that is not positive, IoError when it cannot be bound.
  MetricsHttpServer(const std::string& address, BodyFunction body,
                    double connection_deadline_s = kDefaultConnectionDeadlineS);
  // Stops the thread and closes the socket.
  ~MetricsHttpServer();
  MetricsHttpServer(const MetricsHttpServer&) = delete;
  MetricsHttpServer& operator=(const MetricsHttpServer&) = delete;

  // The port bound.
  int port() const { return port_; }

 private:
  void Serve();
  void Answer(int connection);

  // Waits until `connection` is ready for `events` (POLLIN / POLLOUT), the deadline passes or
  // the server stops; true when ready.
  bool WaitFor(int connection, short events) const;

  BodyFunction body_;
  double connection_deadline_s_;
  // Deadline of the connection being answered (serving thread only).
  std::chrono::steady_clock::time_point deadline_;
  int socket_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace evloc::service
