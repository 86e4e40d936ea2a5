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
                                              "--tracking-threads",
                                              "3",
                                              "--search-threads",
                                              "2",
                                              "--search-priority",
                                              "low",
                                              "--tile-loader-priority",
                                              "idle",
                                              "--stamp-at-step-time",
                                              "off",
                                              "--motion-prior",
                                              "2,0",
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
                                              "--informative-points",
                                              "400",
                                              "--binning",
                                              "2",
                                              "--tau",
                                              "0.02",
                                              "--decay-trail",
                                              "2",
                                              "--hot-pixels",
                                              "on",
                                              "--hot-pixel-window",
                                              "0.05",
                                              "--refractory",
                                              "0.0005",
                                              "--background-activity",
                                              "0.004",
                                              "--metrics",
                                              "127.0.0.1:9464",
                                              "--tls-cert",
                                              "c.pem",
                                              "--tls-key",
                                              "k.pem",
                                              "--auth-tokens",
                                              "tokens.txt",
                                              "--max-points-limit",
                                              "5000",
                                              "--max-steps-per-request",
                                              "400",
                                              "--max-packet-events",
                                              "100000",
                                              "--queue-events",
                                              "200000",
                                              "--max-memory",
                                              "100000000",
                                              "--session-cpu-budget",
                                              "3",
                                              "--session-cpu-grace",
                                              "4",
                                              "--handshake-timeout",
                                              "2",
                                              "--max-streams-per-peer",
                                              "6",
                                              "--max-sessions-per-peer",
                                              "2",
                                              "--max-sessions-per-token",
                                              "1",
                                              "--max-streams-per-connection",
                                              "8",
                                              "--max-connection-age",
                                              "600",
                                              "--max-connection-age-grace",
                                              "60",
                                              "--drain-timeout",
                                              "7",
                                              "--map-keep-dir",
                                              (folder.path() / "kept").string()};
  std::filesystem::create_directories(folder.path() / "kept");
  const ServeCommand command = ParseServeCommandLine(arguments);
  const LocalizerServerOptions& server = command.server;
  EXPECT_EQ(server.maps_dir, folder.path());
  EXPECT_EQ(server.listen_address, "127.0.0.1:0");
  EXPECT_EQ(server.max_sessions, 3);
  EXPECT_EQ(server.threads, 9);
  EXPECT_EQ(server.tracking_threads, 3);
  EXPECT_EQ(server.search_threads, 2);
  EXPECT_EQ(server.search_priority, TrackingPool::BackgroundPriority::kLow);
  EXPECT_NE(server.Describe().find("search-priority: low"), std::string::npos);
  EXPECT_EQ(server.tile_loader_priority, ThreadPriority::kIdle);
  EXPECT_NE(server.Describe().find("tile-loader-priority: idle"), std::string::npos);
  // On by default: the flag turns it off.
  EXPECT_FALSE(server.tracker.stamp_at_step_time);
  EXPECT_NE(server.Describe().find("stamp-at-step-time: off"), std::string::npos);
  EXPECT_EQ(server.tracker.motion_prior_velocity_sigma_mps, 2.0);
  EXPECT_EQ(server.tracker.motion_prior_angular_velocity_sigma_dps, 0.0);
  EXPECT_NE(server.Describe().find("motion-prior: 2 m/s, 0 deg/s\n"), std::string::npos);
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
  EXPECT_EQ(server.tracker.informative_points, 400);
  EXPECT_EQ(server.tracker.binning, 2);
  EXPECT_EQ(server.tracker.decay_time_s, 0.02);
  EXPECT_EQ(server.tracker.decay_trail_px, 2);
  EXPECT_TRUE(server.tracker.event_filter.hot_pixels);
  EXPECT_EQ(server.tracker.event_filter.hot_pixel_window_s, 0.05);
  EXPECT_EQ(server.tracker.event_filter.refractory_period_s, 0.0005);
  EXPECT_EQ(server.tracker.event_filter.background_activity_window_s, 0.004);
  EXPECT_EQ(server.metrics_address, "127.0.0.1:9464");
  EXPECT_EQ(server.tls_cert_file, "c.pem");
  EXPECT_EQ(server.tls_key_file, "k.pem");
  EXPECT_EQ(server.auth_tokens_file, "tokens.txt");
  EXPECT_EQ(server.max_points_limit, 5000);
  EXPECT_EQ(server.session_limits().max_points_limit, 5000);
  EXPECT_EQ(server.session_limits().max_steps_per_request, 400);
  EXPECT_EQ(server.session_limits().max_packet_events, 100000);
  EXPECT_EQ(server.queue_events, 200000);
  EXPECT_EQ(server.max_memory_bytes, 100000000);
  EXPECT_EQ(server.session_cpu_per_second, 3);
  EXPECT_EQ(server.session_cpu_grace_s, 4);
  EXPECT_EQ(server.handshake_timeout_s, 2);
  EXPECT_EQ(server.max_streams_per_peer, 6);
  EXPECT_EQ(server.max_sessions_per_peer, 2);
  EXPECT_EQ(server.max_sessions_per_token, 1);
  EXPECT_EQ(server.max_streams_per_connection, 8);
  EXPECT_EQ(server.max_connection_age_s, 600);
  EXPECT_EQ(server.max_connection_age_grace_s, 60);
  EXPECT_EQ(server.drain_timeout_s, 7);
  EXPECT_NE(server.Describe().find("max-sessions: 3"), std::string::npos);
  EXPECT_NE(server.Describe().find("drain-timeout: 7 s"), std::string::npos);
  EXPECT_TRUE(server.keep_maps);
  EXPECT_EQ(server.map_keep_dir, folder.path() / "kept");
  EXPECT_EQ(server.registry_options().keep_dir, folder.path() / "kept");
  EXPECT_FALSE(
      ParseServeCommandLine({"serve", "--maps", folder.path().string(), "--map-keep-dir", "none"})
          .server.keep_maps);
  EXPECT_NE(server.Describe().find("binning 2\n"), std::string::npos);
  const ServeCommand auto_binning =
      ParseServeCommandLine({"serve", "--maps", folder.path().string(), "--binning", "auto"});
  EXPECT_EQ(auto_binning.server.tracker.binning, tracking::kAutoBinning);
  EXPECT_NE(auto_binning.server.Describe().find("binning auto\n"), std::string::npos);
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
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--tracking-threads", "-1"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--search-threads", "-1"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--search-priority", "high"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--tile-loader-priority", "high"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--stamp-at-step-time", "yes"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--motion-prior", "2"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--motion-prior", "2,-1"}),
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
