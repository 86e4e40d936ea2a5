// The HTTP server of `evloc-localizer serve --metrics` and `--viewer` (docs/api.md "Metrics",
// docs/viewer.md), on cpp-httplib. httplib reads requests with a timeout per read, so a client
// sending one byte before each timeout could hold a connection (and its thread) forever, and
// stopping waits for every connection; so this server hands httplib its own connection stream:
// the request must arrive within one absolute deadline from accept, every write must finish
// within its own timeout, and a stop ends every read and write within one poll (100 ms). TLS
// (optional, with client certificates for mutual TLS) runs inside that stream on OpenSSL.
// A fixed pool of threads serves the connections; one beyond `max_connections` at once gets
// 503. Library code: throws typed errors.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include <httplib.h>
// httplib includes <resolv.h>, whose macro `_res` breaks Eigen (a parameter name there); nothing
// here uses the resolver state.
#ifdef _res
#undef _res
#endif

#include "localizer/service/auth.h"

namespace evloc::service {

// Options of an HttpServer.
struct HttpServerOptions {
  // Where to listen, IPV4:PORT (port 0: any free port); "localhost" means 127.0.0.1.
  std::string address;
  // The flag the address came from, named in errors (e.g. "--metrics").
  std::string flag = "--metrics";
  // Time from accept to the end of the request's headers (and body), seconds: a slow or silent
  // client is dropped when it passes.
  double request_deadline_s = 2.0;
  // Most time one write of the response may wait for the client, seconds (a client that stops
  // reading an event stream is dropped after it).
  double write_timeout_s = 5.0;
  // Connections served at once (the thread pool's size); more get 503 Service Unavailable.
  int max_connections = 8;
  // TLS material (certificate chain, key, optional client CA); nullopt: plaintext.
  std::optional<TlsPem> tls;

  // Throws InvalidArgumentError naming the first invalid field.
  void Check() const;
};

// Serves the routes that `add_routes` installs on an httplib::Server until destroyed.
class HttpServer {
 public:
  // Installs the routes (Get, ...); called once before listening.
  using RouteFunction = std::function<void(httplib::Server& server)>;

  // Binds and starts serving. Throws InvalidArgumentError for a malformed address or invalid
  // options (also a TLS key that does not match its certificate), IoError when the address
  // cannot be bound.
  HttpServer(const HttpServerOptions& options, const RouteFunction& add_routes);
  // Stops: every connection ends within one poll, then the threads are joined.
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // The port bound.
  int port() const { return port_; }
  // True once the server is stopping (long responses such as event streams end then).
  bool stopping() const;

  // Runs one request given as raw bytes through the routes, as a connection would, and returns
  // the raw response (for the fuzz targets and tests; no socket). A streamed response (server-
  // sent events) ends after its first piece of body.
  std::string HandleRawRequest(const std::string& request);

  // The httplib server with the connection handling described above (defined in the .cc).
  class Server;

 private:
  std::unique_ptr<Server> server_;
  std::thread thread_;
  int port_ = 0;
};

// Splits "HOST:PORT" into an IPv4 host ("localhost" -> 127.0.0.1) and a port 0..65535; throws
// InvalidArgumentError naming `flag` for anything else.
std::pair<std::string, int> ParseIpv4ListenAddress(const std::string& address,
                                                   const std::string& flag);

}  // namespace evloc::service
