#include "localizer/service/metrics_http.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "core/common/cli.h"
#include "core/common/error.h"

namespace evloc::service {

MetricsHttpServer::MetricsHttpServer(const std::string& address, BodyFunction body,
                                     double connection_deadline_s)
    : body_(std::move(body)), connection_deadline_s_(connection_deadline_s) {
  if (!(connection_deadline_s_ > 0)) {
    throw InvalidArgumentError("metrics server: the connection deadline must be positive");
  }
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos) {
    throw InvalidArgumentError("--metrics expects IPV4:PORT (e.g. 127.0.0.1:9464), got '" +
                               address + "'");
  }
  sockaddr_in socket_address{};
  socket_address.sin_family = AF_INET;
  const std::string host =
      address.substr(0, colon) == "localhost" ? "127.0.0.1" : address.substr(0, colon);
  if (inet_pton(AF_INET, host.c_str(), &socket_address.sin_addr) != 1) {
    throw InvalidArgumentError("--metrics: '" + host + "' is not an IPv4 address");
  }
  const int64_t port = ParseIntegerFlag("--metrics port", address.substr(colon + 1));
  if (port < 0 || port > 65535) throw InvalidArgumentError("--metrics: port out of range");
  socket_address.sin_port = htons(static_cast<uint16_t>(port));
  socket_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (socket_ < 0) throw IoError(std::string("--metrics: socket: ") + std::strerror(errno));
  const int yes = 1;
  ::setsockopt(socket_, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  if (::bind(socket_, reinterpret_cast<sockaddr*>(&socket_address), sizeof(socket_address)) != 0 ||
      ::listen(socket_, 8) != 0) {
    const std::string reason = std::strerror(errno);
    ::close(socket_);
    throw IoError("--metrics: cannot listen on " + address + ": " + reason);
  }
  socklen_t length = sizeof(socket_address);
  ::getsockname(socket_, reinterpret_cast<sockaddr*>(&socket_address), &length);
  port_ = ntohs(socket_address.sin_port);
  thread_ = std::thread([this] { Serve(); });
}

MetricsHttpServer::~MetricsHttpServer() {
  stop_ = true;
  thread_.join();
  ::close(socket_);
}

void MetricsHttpServer::Serve() {
  while (!stop_) {
    pollfd descriptor{socket_, POLLIN, 0};
    if (::poll(&descriptor, 1, 100) <= 0) continue;
    const int connection = ::accept4(socket_, nullptr, nullptr, SOCK_CLOEXEC);
    if (connection < 0) continue;
    Answer(connection);
    ::close(connection);
  }
}

bool MetricsHttpServer::WaitFor(int connection, short events) const {
  while (!stop_) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline_ - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd descriptor{connection, events, 0};
    const int ready =
        ::poll(&descriptor, 1, static_cast<int>(std::min<int64_t>(left.count(), 100)));
    if (ready > 0) return true;
    if (ready < 0 && errno != EINTR) return false;
  }
  return false;
}

void MetricsHttpServer::Answer(int connection) {
  // One absolute deadline for the whole exchange: a client trickling bytes cannot extend it.
  deadline_ = std::chrono::steady_clock::now() +
              std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                  std::chrono::duration<double>(connection_deadline_s_));
  std::string request;
  char buffer[1024];
  while (request.find("\r\n\r\n") == std::string::npos && request.size() < 8192) {
    if (!WaitFor(connection, POLLIN)) return;
    const ssize_t received = ::recv(connection, buffer, sizeof(buffer), MSG_DONTWAIT);
    if (received < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) continue;
    if (received <= 0) break;
    request.append(buffer, static_cast<size_t>(received));
  }
  std::string status = "200 OK";
  std::string body;
  if (request.rfind("GET /metrics ", 0) == 0 || request.rfind("GET /metrics?", 0) == 0) {
    body = body_();
  } else {
    status = "404 Not Found";
    body = "only GET /metrics is served here\n";
  }
  const std::string response = "HTTP/1.0 " + status +
                               "\r\nContent-Type: text/plain; version=0.0.4\r\nContent-Length: " +
                               std::to_string(body.size()) + "\r\nConnection: close\r\n\r\n" + body;
  size_t sent = 0;
  while (sent < response.size()) {
    if (!WaitFor(connection, POLLOUT)) return;
    const ssize_t count = ::send(connection, response.data() + sent, response.size() - sent,
                                 MSG_NOSIGNAL | MSG_DONTWAIT);
    if (count < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) continue;
    if (count <= 0) break;
    sent += static_cast<size_t>(count);
  }
}

}  // namespace evloc::service
