// Runs examples/python/localizer_client.py with /usr/bin/python3 against a real server on
// loopback (skipped, with the reason, when Python lacks grpcio or protobuf, or when the stub
// generator is missing).
#include <gtest/gtest.h>

#include <fstream>

#include <nlohmann/json.hpp>

#include "core/common/test_data.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"

namespace evloc::service {
namespace {

constexpr char kPython[] = "/usr/bin/python3";
constexpr char kPlugin[] = "/usr/bin/grpc_python_plugin";

TEST(PythonClientExample, StreamsEventsAndPrintsPoses) {
  std::string ignored;
  if (::evloc::testing::RunShellCommand(
          std::string(kPython) + " -c 'import grpc, google.protobuf, numpy' 2>&1", &ignored) != 0) {
    GTEST_SKIP() << kPython << " lacks grpcio, protobuf or numpy (Debian: python3-grpcio "
                 << "python3-protobuf python3-numpy): " << ignored;
  }
  if (!std::filesystem::exists(kPlugin)) {
    GTEST_SKIP() << kPlugin << " is missing (Debian: protobuf-compiler-grpc)";
  }
  testing::TemporaryFolder folder;
  testing::WriteTestMap(folder.path() / "maps", testing::kTestMapName, testing::TestMap());
  LocalizerServer server(testing::TestServerOptions(folder.path() / "maps"));

  // The session description and 200 ms of synthetic events.
  const Rigid3d pose = tracking::testing::SmoothMotion(testing::kInitialTimeNs);
  const Camera camera = testing::TestCamera();
  const nlohmann::json session = {
      {"camera",
       {{"model", "pinhole"},
        {"width", camera.width},
        {"height", camera.height},
        {"fx", camera.fx},
        {"fy", camera.fy},
        {"cx", camera.cx},
        {"cy", camera.cy}}},
      {"initial_t_ns", testing::kInitialTimeNs},
      {"initial_world_from_cam",
       {{"t", {pose.translation.x(), pose.translation.y(), pose.translation.z()}},
        {"q", {pose.rotation.w(), pose.rotation.x(), pose.rotation.y(), pose.rotation.z()}}}}};
  std::ofstream(folder.path() / "session.json") << session.dump();
  const EventBuffer events = testing::TestEvents(200'000'000);
  {
    std::ofstream text(folder.path() / "events.txt");
    for (size_t i = 0; i < events.size(); ++i) {
      text << events.t_ns[i] << " " << events.x[i] << " " << events.y[i] << " "
           << static_cast<int>(events.polarity[i]) << "\n";
    }
  }
  std::string output;
  const std::string command =
      std::string(kPython) +
      " examples/python/localizer_client.py --server 127.0.0.1:" + std::to_string(server.port()) +
      " --map " + testing::kTestMapName + " --session '" +
      (folder.path() / "session.json").string() + "' --events '" +
      (folder.path() / "events.txt").string() + "' --rate 200 --protoc '" EVLOC_PROTOC "' 2>&1";
  ASSERT_EQ(::evloc::testing::RunShellCommand(command, &output), 0) << output;
  EXPECT_NE(output.find("session 1: map rectangles"), std::string::npos) << output;
  EXPECT_NE(output.find("end: " + std::to_string(events.size()) + " events"), std::string::npos)
      << output;
  // The session starts at 20 ms; at 200 Hz the steps are at 25, 30, ..., 200 ms (the last one
  // once the end of the stream advances the tracker to the last event): 36, all TRACKING.
  EXPECT_NE(output.find("received 36 poses"), std::string::npos) << output;
  EXPECT_EQ(output.find("LOST "), std::string::npos) << output;
  EXPECT_NE(output.find("(0 LOST)"), std::string::npos) << output;
}

}  // namespace
}  // namespace evloc::service
