#include "localizer/service/http_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <mutex>

#include "core/common/cli.h"
#include "core/common/error.h"

namespace evloc::service {
namespace {

using Clock = std::chrono::steady_clock;

// How often a waiting read or write looks at the stop flag.
constexpr int kPollMs = 100;

Clock::duration Seconds(double seconds) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
}

std::string OpenSslError() {
  const unsigned long code = ERR_get_error();
  if (code == 0) return "unknown OpenSSL error";
  char text[256];
  ERR_error_string_n(code, text, sizeof(text));
  ERR_clear_error();
  return text;
}

struct BioDeleter {
  void operator()(BIO* bio) const { BIO_free(bio); }
};
struct X509Deleter {
  void operator()(X509* certificate) const { X509_free(certificate); }
};
struct KeyDeleter {
  void operator()(EVP_PKEY* key) const { EVP_PKEY_free(key); }
};

std::unique_ptr<BIO, BioDeleter> MemoryBio(const std::string& text) {
  return std::unique_ptr<BIO, BioDeleter>(
      BIO_new_mem_buf(text.data(), static_cast<int>(text.size())));
}

// A TLS context from PEM text (ReadTlsFiles checked the files already; this checks again).
SSL_CTX* MakeTlsContext(const TlsPem& pem, const std::string& flag) {
  SSL_CTX* context = SSL_CTX_new(TLS_server_method());
  if (context == nullptr) throw IoError(flag + ": cannot create a TLS context: " + OpenSslError());
  const auto fail = [&](const std::string& what) {
    SSL_CTX_free(context);
    throw InvalidArgumentError(flag + ": " + what + ": " + OpenSslError());
  };
  SSL_CTX_set_min_proto_version(context, TLS1_2_VERSION);
  {
    auto bio = MemoryBio(pem.cert);
    std::unique_ptr<X509, X509Deleter> leaf(
        PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
    if (!leaf || SSL_CTX_use_certificate(context, leaf.get()) != 1) {
      fail("the TLS certificate (--tls-cert) is not a PEM certificate");
    }
    while (X509* chain = PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr)) {
      if (SSL_CTX_add_extra_chain_cert(context, chain) != 1) {  // Takes ownership on success.
        X509_free(chain);
        fail("the TLS certificate chain (--tls-cert) cannot be used");
      }
    }
    ERR_clear_error();  // The end of the chain reads as an error.
  }
  {
    auto bio = MemoryBio(pem.key);
    std::unique_ptr<EVP_PKEY, KeyDeleter> key(
        PEM_read_bio_PrivateKey(bio.get(), nullptr, nullptr, nullptr));
    if (!key || SSL_CTX_use_PrivateKey(context, key.get()) != 1 ||
        SSL_CTX_check_private_key(context) != 1) {
      fail("the TLS key (--tls-key) is not a PEM private key of the certificate");
    }
  }
  if (!pem.client_ca.empty()) {
    X509_STORE* store = SSL_CTX_get_cert_store(context);
    auto bio = MemoryBio(pem.client_ca);
    int count = 0;
    while (X509* certificate = PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr)) {
      X509_STORE_add_cert(store, certificate);
      X509_free(certificate);
      ++count;
    }
    ERR_clear_error();
    if (count == 0) fail("the client CA (--tls-client-ca) holds no PEM certificate");
    SSL_CTX_set_verify(context, SSL_VERIFY_PEER | SSL_VERIFY_FAIL_IF_NO_PEER_CERT, nullptr);
  }
  return context;
}

// One accepted connection as httplib's Stream: reads before `read_deadline`, each write within
// `write_timeout`, everything ends when `stop` is set; plaintext or TLS (`ssl`).
class ConnectionStream final : public httplib::Stream {
 public:
  ConnectionStream(int socket, SSL* ssl, Clock::time_point read_deadline,
                   Clock::duration write_timeout, const std::atomic<bool>& stop)
      : socket_(socket),
        ssl_(ssl),
        read_deadline_(read_deadline),
        write_timeout_(write_timeout),
        stop_(stop) {}

  // Runs the TLS handshake within the read deadline; false when it fails or times out.
  bool Handshake() {
    while (true) {
      const int result = SSL_accept(ssl_);
      if (result == 1) return true;
      const int error = SSL_get_error(ssl_, result);
      if (error == SSL_ERROR_WANT_READ) {
        if (!WaitFor(POLLIN, read_deadline_)) return false;
      } else if (error == SSL_ERROR_WANT_WRITE) {
        if (!WaitFor(POLLOUT, read_deadline_)) return false;
      } else {
        ERR_clear_error();
        return false;
      }
    }
  }

  bool is_readable() const override {
    if (ssl_ != nullptr && SSL_pending(ssl_) > 0) return true;
    pollfd descriptor{socket_, POLLIN, 0};
    return ::poll(&descriptor, 1, 0) > 0;
  }
  bool is_writable() const override { return !failed_ && !stop_; }

  ssize_t read(char* data, size_t size) override {
    while (!failed_) {
      ssize_t count;
      int want = POLLIN;
      if (ssl_ != nullptr) {
        count = SSL_read(ssl_, data, static_cast<int>(std::min<size_t>(size, 1 << 30)));
        if (count > 0) return count;
        const int error = SSL_get_error(ssl_, static_cast<int>(count));
        if (error == SSL_ERROR_ZERO_RETURN) return 0;
        if (error == SSL_ERROR_WANT_WRITE) {
          want = POLLOUT;
        } else if (error != SSL_ERROR_WANT_READ) {
          ERR_clear_error();
          break;
        }
      } else {
        count = ::recv(socket_, data, size, MSG_DONTWAIT);
        if (count >= 0) return count;
        if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) break;
      }
      if (!WaitFor(static_cast<short>(want), read_deadline_)) break;
    }
    failed_ = true;
    return -1;
  }

  ssize_t write(const char* data, size_t size) override {
    const Clock::time_point deadline = Clock::now() + write_timeout_;
    size_t sent = 0;
    while (!failed_ && sent < size) {
      int want = POLLOUT;
      if (ssl_ != nullptr) {
        const int count =
            SSL_write(ssl_, data + sent, static_cast<int>(std::min<size_t>(size - sent, 1 << 30)));
        if (count > 0) {
          sent += static_cast<size_t>(count);
          continue;
        }
        const int error = SSL_get_error(ssl_, count);
        if (error == SSL_ERROR_WANT_READ) {
          want = POLLIN;
        } else if (error != SSL_ERROR_WANT_WRITE) {
          ERR_clear_error();
          break;
        }
      } else {
        const ssize_t count =
            ::send(socket_, data + sent, size - sent, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (count > 0) {
          sent += static_cast<size_t>(count);
          continue;
        }
        if (count < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) break;
      }
      if (!WaitFor(static_cast<short>(want), deadline)) break;
    }
    if (sent < size) {
      failed_ = true;
      return -1;
    }
    return static_cast<ssize_t>(size);
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    AddressOf(::getpeername, ip, port);
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    AddressOf(::getsockname, ip, port);
  }
  socket_t socket() const override { return socket_; }

 private:
  // Waits until the socket is ready for `events`, `deadline` passes or the server stops.
  bool WaitFor(short events, Clock::time_point deadline) const {
    while (!stop_) {
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
      if (left <= 0) return false;
      pollfd descriptor{socket_, events, 0};
      const int ready = ::poll(&descriptor, 1, static_cast<int>(std::min<int64_t>(left, kPollMs)));
      if (ready > 0) return (descriptor.revents & (POLLERR | POLLNVAL)) == 0;
      if (ready < 0 && errno != EINTR) return false;
    }
    return false;
  }

  template <typename Function>
  void AddressOf(Function function, std::string& ip, int& port) const {
    sockaddr_storage address{};
    socklen_t length = sizeof(address);
    ip.clear();
    port = 0;
    if (function(socket_, reinterpret_cast<sockaddr*>(&address), &length) != 0) return;
    char text[INET6_ADDRSTRLEN] = {};
    if (address.ss_family == AF_INET) {
      const auto* ipv4 = reinterpret_cast<const sockaddr_in*>(&address);
      inet_ntop(AF_INET, &ipv4->sin_addr, text, sizeof(text));
      port = ntohs(ipv4->sin_port);
    } else if (address.ss_family == AF_INET6) {
      const auto* ipv6 = reinterpret_cast<const sockaddr_in6*>(&address);
      inet_ntop(AF_INET6, &ipv6->sin6_addr, text, sizeof(text));
      port = ntohs(ipv6->sin6_port);
    }
    ip = text;
  }

  int socket_;
  SSL* ssl_;
  Clock::time_point read_deadline_;
  Clock::duration write_timeout_;
  const std::atomic<bool>& stop_;
  bool failed_ = false;
};

// A request held in memory, answered into memory (HandleRawRequest).
class MemoryStream final : public httplib::Stream {
 public:
  explicit MemoryStream(const std::string& request) : request_(request) {}
  bool is_readable() const override { return offset_ < request_.size(); }
  // A streamed response (a content provider) ends after its first piece of body.
  bool is_writable() const override {
    const size_t headers_end = response_.find("\r\n\r\n");
    return headers_end == std::string::npos || response_.size() == headers_end + 4;
  }
  ssize_t read(char* data, size_t size) override {
    const size_t count = std::min(size, request_.size() - offset_);
    std::memcpy(data, request_.data() + offset_, count);
    offset_ += count;
    return static_cast<ssize_t>(count);
  }
  ssize_t write(const char* data, size_t size) override {
    response_.append(data, size);
    return static_cast<ssize_t>(size);
  }
  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    ip = "127.0.0.1";
    port = 1;
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    ip = "127.0.0.1";
    port = 2;
  }
  socket_t socket() const override { return INVALID_SOCKET; }
  const std::string& response() const { return response_; }

 private:
  const std::string& request_;
  size_t offset_ = 0;
  std::string response_;
};

}  // namespace

class HttpServer::Server final : public httplib::Server {
 public:
  explicit Server(const HttpServerOptions& options) : options_(options) {
    // One thread more than the connections allowed: it answers 503 to the next one at once
    // instead of leaving it queued behind long responses (event streams).
    const size_t threads = static_cast<size_t>(options.max_connections) + 1;
    new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
    if (options.tls) tls_context_ = MakeTlsContext(*options.tls, options.flag);
  }
  ~Server() override {
    if (tls_context_ != nullptr) SSL_CTX_free(tls_context_);
  }

  void Stop() {
    stop_ = true;
    stop();
  }
  bool stopping() const { return stop_; }

  std::string HandleRaw(const std::string& request) {
    MemoryStream stream(request);
    bool closed = false;
    process_request(stream, true, closed, nullptr);
    return stream.response();
  }

 private:
  bool process_and_close_socket(socket_t socket) override {
    const Clock::time_point accepted = Clock::now();
    const int flags = ::fcntl(socket, F_GETFL, 0);
    ::fcntl(socket, F_SETFL, flags | O_NONBLOCK);
    const int active = ++active_;
    bool ok = false;
    SSL* ssl = nullptr;
    if (tls_context_ != nullptr) {
      ssl = SSL_new(tls_context_);
      if (ssl != nullptr) SSL_set_fd(ssl, socket);
    }
    {
      ConnectionStream stream(socket, ssl, accepted + Seconds(options_.request_deadline_s),
                              Seconds(options_.write_timeout_s), stop_);
      const bool ready = tls_context_ == nullptr || (ssl != nullptr && stream.Handshake());
      if (ready && active > options_.max_connections) {
        static const std::string kBusy =
            "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\nContent-Length: "
            "37\r\nConnection: close\r\n\r\ntoo many connections; try again later";
        stream.write(kBusy.data(), kBusy.size());
      } else if (ready) {
        bool closed = false;
        ok = process_request(stream, true, closed, nullptr);
      }
    }
    if (ssl != nullptr) {
      SSL_shutdown(ssl);
      SSL_free(ssl);
    }
    --active_;
    ::shutdown(socket, SHUT_RDWR);
    ::close(socket);
    return ok;
  }

  HttpServerOptions options_;
  SSL_CTX* tls_context_ = nullptr;
  std::atomic<bool> stop_{false};
  std::atomic<int> active_{0};
};

void HttpServerOptions::Check() const {
  ParseIpv4ListenAddress(address, flag);
  if (!(request_deadline_s > 0) || !(request_deadline_s <= 3600)) {
    throw InvalidArgumentError(flag + ": the request deadline must be in (0, 3600] s");
  }
  if (!(write_timeout_s > 0) || !(write_timeout_s <= 3600)) {
    throw InvalidArgumentError(flag + ": the write timeout must be in (0, 3600] s");
  }
  if (max_connections < 1 || max_connections > 1024) {
    throw InvalidArgumentError(flag + ": the most connections must be 1 .. 1024");
  }
}

std::pair<std::string, int> ParseIpv4ListenAddress(const std::string& address,
                                                   const std::string& flag) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos) {
    throw InvalidArgumentError(flag + " expects IPV4:PORT (e.g. 127.0.0.1:9464), got '" + address +
                               "'");
  }
  const std::string host =
      address.substr(0, colon) == "localhost" ? "127.0.0.1" : address.substr(0, colon);
  in_addr parsed{};
  if (inet_pton(AF_INET, host.c_str(), &parsed) != 1) {
    throw InvalidArgumentError(flag + ": '" + host + "' is not an IPv4 address");
  }
  const int64_t port = ParseIntegerFlag(flag + " port", address.substr(colon + 1));
  if (port < 0 || port > 65535) throw InvalidArgumentError(flag + ": port out of range");
  return {host, static_cast<int>(port)};
}

HttpServer::HttpServer(const HttpServerOptions& options, const RouteFunction& add_routes) {
  options.Check();
  const auto [host, port] = ParseIpv4ListenAddress(options.address, options.flag);
  server_ = std::make_unique<Server>(options);
  add_routes(*server_);
  if (port == 0) {
    port_ = server_->bind_to_any_port(host);
  } else {
    port_ = server_->bind_to_port(host, port) ? port : -1;
  }
  if (port_ <= 0) {
    throw IoError(options.flag + ": cannot listen on " + options.address + ": " +
                  std::strerror(errno) + " (is the port in use?)");
  }
  thread_ = std::thread([this] { server_->listen_after_bind(); });
  // httplib's stop() does nothing before the listening loop runs: wait for it.
  while (!server_->is_running()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

HttpServer::~HttpServer() {
  server_->Stop();
  thread_.join();
}

bool HttpServer::stopping() const { return server_->stopping(); }

std::string HttpServer::HandleRawRequest(const std::string& request) {
  return server_->HandleRaw(request);
}

}  // namespace evloc::service
