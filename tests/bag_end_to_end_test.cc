// A ROS1 bag and an AEDAT4 file work where a dataset works: evloc-sim renders a sequence (with
// events.txt), write_test_bags.py --from-dataset writes it as a bag with Debian's python3-rosbag
// (dvs_msgs/EventArray, sensor_msgs/Image, sensor_msgs/CameraInfo, geometry_msgs/PoseStamped) and
// write_test_aedat4.py --from-dataset as an AEDAT4 file (python3-flatbuffers, LZ4), and
// evloc-track tracks them (--dataset FILE) like the folder, the bag's images in frames mode too.
// Label "long": the render and the Python writers take minutes on a loaded machine
// (docs/event-formats.md, 7.4 and 8.4).
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

// The rendered sequence, once per process (both tests use it; removed at exit); empty when the
// render failed.
const fs::path& RenderedSequence(std::string* output) {
  struct Render {
    fs::path dataset;
    ~Render() {
      if (!dataset.empty()) fs::remove_all(dataset.parent_path());
    }
  };
  static const Render render = [output] {
    const fs::path path = evloc::testing::MakeTempDir("evloc-recording-end-to-end") / "dataset";
    const bool rendered = RunTool(std::string(EVLOC_SIM_BINARY) + " render --out " + path.string() +
                                      " --motion slow --duration 1.5 --seed 3 --events-txt",
                                  output) == 0;
    return Render{rendered ? path : fs::path()};
  }();
  return render.dataset;
}

// Runs the independent writer `script` (core/events/testing) --from-dataset `dataset` into `out`.
int WriteFromDataset(const char* script, const fs::path& dataset, const fs::path& out,
                     std::string* output) {
  return RunTool("/usr/bin/python3 " +
                     (evloc::testing::SourceDir() / "core/events/testing" / script).string() +
                     " --from-dataset " + dataset.string() + " " + out.string(),
                 output);
}

// Tracks `input` (with `flags`) against the sequence's map into DIR/NAME.txt and NAME.json.
void Track(const fs::path& dataset, const fs::path& input, const std::string& flags,
           const fs::path& directory, const std::string& name) {
  std::string output;
  ASSERT_EQ(RunTool(std::string(EVLOC_TRACK_BINARY) + " --map " + (dataset / "gt_map").string() +
                        " --dataset " + input.string() + flags + " --out " +
                        (directory / (name + ".txt")).string() + " --stats " +
                        (directory / (name + ".json")).string() + " --quiet",
                    &output),
            0)
      << output;
}

TEST(BagEndToEnd, ABagOfASequenceTracksLikeItsFolder) {
  std::string output;
  if (RunTool("/usr/bin/python3 -c 'import rosbag, genpy, roslz4, yaml, PIL'", &output) != 0) {
    GTEST_SKIP() << "/usr/bin/python3 lacks rosbag, genpy, roslz4, yaml or PIL: " << output;
  }
  const fs::path dataset = RenderedSequence(&output);
  ASSERT_FALSE(dataset.empty()) << output;
  const fs::path directory = evloc::testing::MakeTempDir("evloc-bag-end-to-end");
  const fs::path bag = directory / "sequence.bag";
  ASSERT_EQ(WriteFromDataset("write_test_bags.py", dataset, bag, &output), 0) << output;
  Track(dataset, dataset, "", directory, "folder");
  Track(dataset, bag, "", directory, "bag");
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
  // Frames mode (Canny-VT) reads the bag's images as it reads the folder's: the same pixels
  // (rgb8 messages of the rendered RGB PNGs, made grey by one conversion), the same poses.
  Track(dataset, dataset, " --mode frames", directory, "folder_frames");
  Track(dataset, bag, " --mode frames", directory, "bag_frames");
  const auto folder_frames = ReadTum(directory / "folder_frames.txt");
  const auto bag_frames = ReadTum(directory / "bag_frames.txt");
  ASSERT_GT(folder_frames.size(), 30u);  // 1.5 s at 30 frames per second
  ASSERT_EQ(folder_frames.size(), bag_frames.size());
  for (size_t i = 0; i < folder_frames.size(); ++i) {
    for (int k = 0; k < 8; ++k) EXPECT_EQ(folder_frames[i][k], bag_frames[i][k]) << "frame " << i;
  }
  const auto frames_stats = nlohmann::json::parse(std::ifstream(directory / "bag_frames.json"));
  EXPECT_EQ(frames_stats["lost_steps"].get<int>(), 0);
  fs::remove_all(directory);
}

TEST(Aedat4EndToEnd, AnAedat4FileOfASequenceTracksLikeItsFolder) {
  std::string output;
  if (RunTool("/usr/bin/python3 -c 'import flatbuffers, lz4.frame, zstandard, numpy, yaml, PIL'",
              &output) != 0) {
    GTEST_SKIP() << "/usr/bin/python3 lacks flatbuffers, lz4, zstandard, numpy, yaml or PIL: "
                 << output;
  }
  const fs::path dataset = RenderedSequence(&output);
  ASSERT_FALSE(dataset.empty()) << output;
  const fs::path directory = evloc::testing::MakeTempDir("evloc-aedat4-end-to-end");
  const fs::path file = directory / "sequence.aedat4";
  ASSERT_EQ(WriteFromDataset("write_test_aedat4.py", dataset, file, &output), 0) << output;
  const std::string side_files = " --calib " + (dataset / "calib.yaml").string() +
                                 " --groundtruth " + (dataset / "groundtruth.txt").string();
  Track(dataset, dataset, "", directory, "folder");
  Track(dataset, file, side_files, directory, "aedat4");
  // The converted folder tracks bit for bit like the file it came from.
  ASSERT_EQ(RunTool(std::string(EVLOC_CONVERT_BINARY) + " --input " + file.string() + " --out " +
                        (directory / "converted").string() + side_files,
                    &output),
            0)
      << output;
  Track(dataset, directory / "converted", "", directory, "converted");
  const auto folder = ReadTum(directory / "folder.txt");
  const auto from_file = ReadTum(directory / "aedat4.txt");
  ASSERT_GT(folder.size(), 100u);
  ASSERT_EQ(folder.size(), from_file.size());
  EXPECT_EQ(from_file, ReadTum(directory / "converted.txt"));
  double largest = 0;
  for (size_t i = 0; i < folder.size(); ++i) {
    EXPECT_EQ(folder[i][0], from_file[i][0]) << "step " << i;
    largest =
        std::max(largest, std::hypot(folder[i][1] - from_file[i][1], folder[i][2] - from_file[i][2],
                                     folder[i][3] - from_file[i][3]));
  }
  // AEDAT4 stores microseconds: the simulator's nanosecond event times are rounded, so the
  // trajectory differs slightly (measured 2026-11-25: at most 4.5 mm over 450 steps).
  EXPECT_LT(largest, 0.01);
  const auto folder_stats = nlohmann::json::parse(std::ifstream(directory / "folder.json"));
  const auto file_stats = nlohmann::json::parse(std::ifstream(directory / "aedat4.json"));
  EXPECT_EQ(folder_stats["measurements"], file_stats["measurements"]);
  EXPECT_EQ(file_stats["lost_steps"].get<int>(), 0);
  // Frames mode on the file's frames stream (BGR frames of the rendered RGB PNGs): bit for bit
  // like its converted folder, and within 1 µs and 1 mm of the original folder's frames.
  Track(dataset, file, side_files + " --mode frames", directory, "aedat4_frames");
  Track(dataset, directory / "converted", " --mode frames", directory, "converted_frames");
  Track(dataset, dataset, " --mode frames", directory, "folder_frames");
  const auto file_frames = ReadTum(directory / "aedat4_frames.txt");
  const auto folder_frames = ReadTum(directory / "folder_frames.txt");
  ASSERT_GT(file_frames.size(), 30u);  // 1.5 s at 30 frames per second
  EXPECT_EQ(file_frames, ReadTum(directory / "converted_frames.txt"));
  ASSERT_EQ(file_frames.size(), folder_frames.size());
  for (size_t i = 0; i < file_frames.size(); ++i) {
    EXPECT_NEAR(file_frames[i][0], folder_frames[i][0], 1e-6) << "frame " << i;
    EXPECT_LT(
        std::hypot(file_frames[i][1] - folder_frames[i][1], file_frames[i][2] - folder_frames[i][2],
                   file_frames[i][3] - folder_frames[i][3]),
        1e-3)
        << "frame " << i;
  }
  fs::remove_all(directory);
}

}  // namespace
