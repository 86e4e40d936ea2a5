// `GET /metrics` with a text body (the Prometheus text exposition format), for `evloc-localizer
// serve --metrics ADDR`, on the service's HTTP server (http_server.h: cpp-httplib with one
// absolute deadline per request, so a slow or silent client is dropped when it passes, and
// stopping never waits longer than one poll); meant for a scraper nearby.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "localizer/service/http_server.h"

namespace evloc::service {

// Serves GET /metrics until destroyed.
class MetricsHttpServer {
 public:
  // Produces the body of each response.
  using BodyFunction = std::function<std::string()>;

  // Default of the time one connection may take from accept to the end of its request, seconds.
  static constexpr double kDefaultConnectionDeadlineS = 2.0;

  // Listens on `address`, "IPV4:PORT" (port 0: any free port); a connection whose request has not
  // arrived `connection_deadline_s` after it was accepted is closed. Throws InvalidArgumentError
  // for a malformed address or a deadline that is not positive, IoError when it cannot be bound.
  MetricsHttpServer(const std::string& address, BodyFunction body,
                    double connection_deadline_s = kDefaultConnectionDeadlineS);

  // The port bound.
  int port() const { return server_->port(); }

 private:
  std::unique_ptr<HttpServer> server_;
};

}  // namespace evloc::service
