#include "localizer/service/metrics_http.h"

#include "core/common/error.h"

#include <gtest/gtest.h>
#include <httplib.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <thread>
#include <vector>

namespace evloc::service {
namespace {

using Clock = std::chrono::steady_clock;

int ConnectTo(int port) {
  const int socket = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  inet_pton(AF_INET, "127.0.0.1", &address.sin_addr);
  if (::connect(socket, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0) {
    ::close(socket);
    return -1;
  }
  return socket;
}

// True when the server closed `socket` (a read returns end of stream or an error).
bool ClosedByServer(int socket) {
  pollfd descriptor{socket, POLLIN, 0};
  if (::poll(&descriptor, 1, 0) <= 0) return false;
  char byte = 0;
  return ::recv(socket, &byte, 1, MSG_DONTWAIT) <= 0;
}

// Sends one byte of a request every 100 ms until the server closes the connection or
// `give_up` passes; returns how long the server kept it open.
Clock::duration TrickleUntilClosed(int socket, Clock::duration give_up) {
  const auto start = Clock::now();
  const std::string request = "GET /metrics HTTP/1.0\r\nX-Padding: " + std::string(200, 'a');
  for (size_t i = 0; Clock::now() - start < give_up; ++i) {
    if (ClosedByServer(socket)) break;
    if (::send(socket, &request[i % request.size()], 1, MSG_NOSIGNAL) != 1) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return Clock::now() - start;
}

// Finding 8 of issue 14: each read had its own 1 s timeout, so a client sending a byte a second
// held the (single) serving thread as long as it liked, blocking scrapes. The connection now has
// one absolute deadline (default 2 s).
TEST(MetricsHttpServer, TricklingClientIsCutAtTheDeadline) {
  MetricsHttpServer server("127.0.0.1:0", [] { return std::string("m 1\n"); });
  const int socket = ConnectTo(server.port());
  ASSERT_GE(socket, 0);
  const auto held = TrickleUntilClosed(socket, std::chrono::seconds(8));
  ::close(socket);
  EXPECT_LT(held, std::chrono::milliseconds(4000))
      << std::chrono::duration<double>(held).count() << " s";
}

// Finding 8: stopping the server (SIGTERM) waited for a slow client; it now returns within a
// poll interval whatever the client does.
TEST(MetricsHttpServer, StopsPromptlyWhileAClientTrickles) {
  auto server = std::make_unique<MetricsHttpServer>(
      "127.0.0.1:0", [] { return std::string("m 1\n"); }, 60.0);
  const int socket = ConnectTo(server->port());
  ASSERT_GE(socket, 0);
  std::thread client([&] { TrickleUntilClosed(socket, std::chrono::seconds(20)); });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const auto start = Clock::now();
  server.reset();
  const auto stopping = Clock::now() - start;
  client.join();
  ::close(socket);
  EXPECT_LT(stopping, std::chrono::milliseconds(1500))
      << std::chrono::duration<double>(stopping).count() << " s";
}

// httplib serves connections from a pool: a client trickling its request does not delay a scrape,
// and the body and content type of /metrics are what the hand-written server sent.
TEST(MetricsHttpServer, ScrapesAreAnsweredWhileAClientTrickles) {
  MetricsHttpServer server("127.0.0.1:0", [] { return std::string("evloc_poses_total 7\n"); });
  const int socket = ConnectTo(server.port());
  ASSERT_GE(socket, 0);
  std::thread client([&] { TrickleUntilClosed(socket, std::chrono::seconds(3)); });
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  httplib::Client scraper("127.0.0.1", server.port());
  const auto start = Clock::now();
  const httplib::Result result = scraper.Get("/metrics");
  const auto took = Clock::now() - start;
  client.join();
  ::close(socket);
  ASSERT_TRUE(result) << httplib::to_string(result.error());
  EXPECT_EQ(result->status, 200);
  EXPECT_EQ(result->body, "evloc_poses_total 7\n");
  EXPECT_EQ(result->get_header_value("Content-Type"), "text/plain; version=0.0.4");
  EXPECT_LT(took, std::chrono::milliseconds(1000));
  const httplib::Result other = scraper.Get("/other");
  ASSERT_TRUE(other);
  EXPECT_EQ(other->status, 404);
  EXPECT_EQ(other->body, "only GET /metrics is served here\n");
}

// Connections beyond the pool (4 for /metrics) are answered 503 at once, not queued behind
// clients that hold theirs.
TEST(MetricsHttpServer, AnswersBusyBeyondItsConnections) {
  MetricsHttpServer server("127.0.0.1:0", [] { return std::string("m 1\n"); });
  std::vector<int> silent;
  for (int i = 0; i < 4; ++i) {
    silent.push_back(ConnectTo(server.port()));
    ASSERT_GE(silent.back(), 0);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  httplib::Client scraper("127.0.0.1", server.port());
  const auto start = Clock::now();
  const httplib::Result result = scraper.Get("/metrics");
  ASSERT_TRUE(result) << httplib::to_string(result.error());
  EXPECT_EQ(result->status, 503);
  EXPECT_LT(Clock::now() - start, std::chrono::milliseconds(1000));
  for (const int socket : silent) ::close(socket);
  // Once the silent clients go away, scrapes are served again.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const httplib::Result later = scraper.Get("/metrics");
  ASSERT_TRUE(later);
  EXPECT_EQ(later->status, 200);
}

TEST(MetricsHttpServer, RefusesABadAddressOrDeadline) {
  const auto body = [] { return std::string(); };
  EXPECT_THROW(MetricsHttpServer("9464", body), InvalidArgumentError);
  EXPECT_THROW(MetricsHttpServer("example.org:9464", body), InvalidArgumentError);
  EXPECT_THROW(MetricsHttpServer("127.0.0.1:70000", body), InvalidArgumentError);
  EXPECT_THROW(MetricsHttpServer("127.0.0.1:0", body, 0.0), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::service
