#include "localizer/service/metrics_http.h"

#include <utility>

namespace evloc::service {

MetricsHttpServer::MetricsHttpServer(const std::string& address, BodyFunction body,
                                     double connection_deadline_s) {
  HttpServerOptions options;
  options.address = address;
  options.flag = "--metrics";
  options.request_deadline_s = connection_deadline_s;
  options.max_connections = 4;
  server_ = std::make_unique<HttpServer>(options, [body = std::move(body)](httplib::Server& http) {
    http.Get("/metrics", [body](const httplib::Request&, httplib::Response& response) {
      response.set_content(body(), "text/plain; version=0.0.4");
    });
    http.set_error_handler([](const httplib::Request&, httplib::Response& response) {
      if (response.status == 404) {
        response.set_content("only GET /metrics is served here\n", "text/plain");
      }
    });
  });
}

}  // namespace evloc::service
