// A ROS1 bag works where a dataset works: evloc-sim renders a sequence (with events.txt),
// write_test_bags.py --from-dataset writes it as a bag with Debian's python3-rosbag
// (dvs_msgs/EventArray, sensor_msgs/CameraInfo, geometry_msgs/PoseStamped), and evloc-track
// tracks the bag (--dataset FILE.bag) to the same trajectory as the folder. Label "long": the
// render and the Python writer take minutes on a loaded machine (docs/event-formats.md, 7.4).
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/common/test_data.h"

namespace {

namespace fs = std::filesystem;

int RunTool(const std::string& command, std::string* output) {
  const int status = evloc::testing::RunShellCommand(command + " 2>&1", output);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::vector<std::vector<double>> ReadTum(const fs::path& path) {
  std::ifstream file(path);
  std::vector<std::vector<double>> rows;
  std::string line;
  while (std::getline(file, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    std::vector<double> row(8);
    for (double& value : row) fields >> value;
    rows.push_back(row);
  }
  return rows;
}

TEST(BagEndToEnd, ABagOfASequenceTracksLikeItsFolder) {
  std::string output;
  if (RunTool("/usr/bin/python3 -c 'import rosbag, genpy, roslz4, yaml'", &output) != 0) {
    GTEST_SKIP() << "/usr/bin/python3 lacks rosbag, genpy, roslz4 or yaml: " << output;
  }
  const fs::path directory = evloc::testing::MakeTempDir("evloc-bag-end-to-end");
  const fs::path dataset = directory / "dataset";
  ASSERT_EQ(RunTool(std::string(EVLOC_SIM_BINARY) + " render --out " + dataset.string() +
                        " --motion slow --duration 1.5 --seed 3 --events-txt",
                    &output),
            0)
      << output;
  const fs::path bag = directory / "sequence.bag";
  ASSERT_EQ(
      RunTool(
          "/usr/bin/python3 " +
              (evloc::testing::SourceDir() / "core/events/testing/write_test_bags.py").string() +
              " --from-dataset " + dataset.string() + " " + bag.string(),
          &output),
      0)
      << output;
  for (const char* name : {"folder", "bag"}) {
    const fs::path input = std::string(name) == "bag" ? bag : dataset;
    ASSERT_EQ(RunTool(std::string(EVLOC_TRACK_BINARY) + " --map " + (dataset / "gt_map").string() +
                          " --dataset " + input.string() + " --out " +
                          (directory / (std::string(name) + ".txt")).string() + " --stats " +
                          (directory / (std::string(name) + ".json")).string() + " --quiet",
                      &output),
              0)
        << output;
  }
  const auto folder = ReadTum(directory / "folder.txt");
  const auto from_bag = ReadTum(directory / "bag.txt");
  ASSERT_GT(folder.size(), 100u);
  ASSERT_EQ(folder.size(), from_bag.size());
  double largest = 0;
  for (size_t i = 0; i < folder.size(); ++i) {
    EXPECT_EQ(folder[i][0], from_bag[i][0]) << "step " << i;
    for (int k = 1; k < 8; ++k)
      largest = std::max(largest, std::abs(folder[i][k] - from_bag[i][k]));
  }
  // Measured identical (2026-11-25): the same events, camera and ground truth, bit for bit.
  EXPECT_EQ(largest, 0.0);
  const auto folder_stats = nlohmann::json::parse(std::ifstream(directory / "folder.json"));
  const auto bag_stats = nlohmann::json::parse(std::ifstream(directory / "bag.json"));
  EXPECT_EQ(folder_stats["measurements"], bag_stats["measurements"]);
  EXPECT_EQ(bag_stats["lost_steps"].get<int>(), 0);
  fs::remove_all(directory);
}

}  // namespace
