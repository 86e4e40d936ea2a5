#include "localizer/service/serve_command.h"

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "localizer/service/testing/service_fixture.h"

namespace evloc::service {
namespace {

TEST(ServeCommand, EveryFlagReachesItsOption) {
  testing::TemporaryFolder folder;
  const std::vector<std::string> arguments = {"serve",
                                              "--maps",
                                              folder.path().string(),
                                              "--listen",
                                              "127.0.0.1:0",
                                              "--max-sessions",
                                              "3",
                                              "--threads",
                                              "9",
                                              "--max-message-bytes",
                                              "65536",
                                              "--idle-timeout",
                                              "2.5",
                                              "--queue-packets",
                                              "16",
                                              "--backpressure-fraction",
                                              "0.25",
                                              "--max-camera-pixels",
                                              "921600",
                                              "--max-packet-span",
                                              "0.5",
                                              "--max-rate",
                                              "2000",
                                              "--rate",
                                              "250",
                                              "--variant",
                                              "EVT-PR",
                                              "--max-points",
                                              "1000",
                                              "--tau",
                                              "0.02",
                                              "--decay-trail",
                                              "2",
                                              "--metrics",
                                              "127.0.0.1:9464",
                                              "--tls-cert",
                                              "c.pem",
                                              "--tls-key",
                                              "k.pem",
                                              "--auth-tokens",
                                              "tokens.txt"};
  const ServeCommand command = ParseServeCommandLine(arguments);
  const LocalizerServerOptions& server = command.server;
  EXPECT_EQ(server.maps_dir, folder.path());
  EXPECT_EQ(server.listen_address, "127.0.0.1:0");
  EXPECT_EQ(server.max_sessions, 3);
  EXPECT_EQ(server.threads, 9);
  EXPECT_EQ(server.max_message_bytes, 65536);
  EXPECT_EQ(server.idle_timeout_s, 2.5);
  EXPECT_EQ(server.queue_packets, 16);
  EXPECT_EQ(server.backpressure_fraction, 0.25);
  EXPECT_EQ(server.max_camera_pixels, 921600);
  EXPECT_EQ(server.session_limits().max_packet_span_ns, 500'000'000);
  EXPECT_EQ(server.max_step_rate_hz, 2000);
  EXPECT_EQ(server.tracker.step_rate_hz, 250);
  EXPECT_EQ(server.tracker.VariantName(), "EVT-PR");
  EXPECT_EQ(server.tracker.max_points, 1000);
  EXPECT_EQ(server.tracker.decay_time_s, 0.02);
  EXPECT_EQ(server.tracker.decay_trail_px, 2);
  EXPECT_EQ(server.metrics_address, "127.0.0.1:9464");
  EXPECT_EQ(server.tls_cert_file, "c.pem");
  EXPECT_EQ(server.tls_key_file, "k.pem");
  EXPECT_EQ(server.auth_tokens_file, "tokens.txt");
  EXPECT_NE(server.Describe().find("max-sessions: 3"), std::string::npos);
}

TEST(ServeCommand, BadCommandLinesAreRejectedWithTheFlag) {
  testing::TemporaryFolder folder;
  const std::string maps = folder.path().string();
  EXPECT_TRUE(ParseServeCommandLine({"--help"}).help);
  EXPECT_THROW(ParseServeCommandLine({}), InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve"}), InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--bogus", "1"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--max-sessions", "0"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--threads", "3"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--max-camera-pixels", "0"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--max-packet-span", "0"}),
               InvalidArgumentError);
  EXPECT_THROW(
      ParseServeCommandLine({"serve", "--maps", maps, "--rate", "400", "--max-rate", "300"}),
      InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--tls-cert", "c.pem"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps + "/missing"}), InvalidArgumentError);
  try {
    ParseServeCommandLine({"serve", "--maps", maps, "--idle-timeout", "soon"});
    FAIL() << "expected an error";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("--idle-timeout"), std::string::npos);
  }
}

}  // namespace
}  // namespace evloc::service
