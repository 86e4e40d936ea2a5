#include "tools/convert/convert_command.h"

#include <gtest/gtest.h>

#include <sstream>

#include "core/common/cli.h"
#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/events/testing/test_bags.h"

namespace evloc {
namespace {

TEST(ConvertCommand, ParsesEveryFlagIntoItsOption) {
  const ConvertCommandOptions options = ParseConvertCommandLine(
      {"--bag", "a.bag", "--out", "d", "--events-topic", "/e", "--image-topic", "/i",
       "--camera-info-topic", "/c", "--groundtruth-topic", "/g", "--force"});
  EXPECT_EQ(options.input_path, "a.bag");
  EXPECT_EQ(options.out_dir, "d");
  EXPECT_EQ(options.topics.events, "/e");
  EXPECT_EQ(options.topics.image, "/i");
  EXPECT_EQ(options.topics.camera_info, "/c");
  EXPECT_EQ(options.topics.groundtruth, "/g");
  EXPECT_TRUE(options.force);
  EXPECT_THROW(ParseConvertCommandLine({"--bag", "a.bag"}), InvalidArgumentError);
  EXPECT_THROW(ParseConvertCommandLine({"--bag", "a.bag", "--out", "d", "--topic", "x"}),
               UsageError);
  EXPECT_NE(ConvertCommandUsage().find("--groundtruth-topic"), std::string::npos);
  const ConvertCommandOptions aedat4 =
      ParseConvertCommandLine({"--input", "r.aedat4", "--out", "d", "--events-topic", "dvs",
                               "--calib", "c.yaml", "--groundtruth", "gt.txt"});
  EXPECT_EQ(aedat4.input_path, "r.aedat4");
  EXPECT_EQ(aedat4.aedat4.events, "dvs");
  EXPECT_EQ(aedat4.aedat4.calibration, "c.yaml");
  EXPECT_EQ(aedat4.aedat4.groundtruth, "gt.txt");
}

TEST(ConvertCommand, WritesADatasetFolderAndSaysWhatItWrote) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  const auto out = testing::MakeTempDir("convert") / "dataset";
  std::ostringstream log;
  const auto summary = RunConvertCommand(
      ParseConvertCommandLine({"--bag", (dir / "test_lz4.bag").string(), "--out", out.string()}),
      log);
  EXPECT_EQ(summary.events, testing::ReadExpectedEvents(dir, "dvs").size());
  EXPECT_NE(log.str().find(std::to_string(summary.events) + " events (0 dropped"),
            std::string::npos)
      << log.str();
  const Dataset dataset = ReadDataset(out);
  EXPECT_EQ(dataset.images.size(), 4u);
  ASSERT_TRUE(dataset.info);
  EXPECT_EQ((*dataset.info)["topics"]["events"], "/dvs/events");
  std::filesystem::remove_all(out.parent_path());
}

TEST(ConvertCommand, ConvertsAnAedat4FileWithItsCalibration) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  const auto folder = testing::MakeTempDir("convert-aedat4");
  WriteCameraYaml(folder / "cam.yaml", Camera::Pinhole(346, 260, 300, 300, 172.5, 129.5));
  std::ostringstream log;
  const auto summary =
      RunConvertCommand(ParseConvertCommandLine({"--input", (dir / "test_lz4.aedat4").string(),
                                                 "--out", (folder / "dataset").string(), "--calib",
                                                 (folder / "cam.yaml").string()}),
                        log);
  EXPECT_EQ(summary.events, testing::ReadExpectedEvents(dir, "events").size());
  EXPECT_NE(log.str().find(std::to_string(summary.events) + " events (3 dropped"),
            std::string::npos)
      << log.str();
  const Dataset dataset = ReadDataset(folder / "dataset");
  EXPECT_EQ(dataset.images.size(), 4u);
  std::filesystem::remove_all(folder);
}

// A real DVXplorer recording written by DV (core/events/testdata/README.md), converted with the
// DVXplorer's sensor size: every event and IMU sample of the file, in time order, no image.
TEST(ConvertCommand, ConvertsARealDvxplorerRecording) {
  const auto folder = testing::MakeTempDir("convert-dvxplorer");
  WriteCameraYaml(folder / "cam.yaml", Camera::Pinhole(320, 240, 250, 250, 159.5, 119.5));
  std::ostringstream log;
  const auto summary = RunConvertCommand(
      ParseConvertCommandLine(
          {"--input",
           (testing::SourceDir() / "core/events/testdata/dvxplorer_sample.aedat4").string(),
           "--out", (folder / "dataset").string(), "--calib", (folder / "cam.yaml").string()}),
      log);
  // The counts of the independent reader (core/events/testdata/dvxplorer_sample.summary.txt).
  EXPECT_EQ(summary.events, 111954u);
  EXPECT_EQ(summary.dropped_events, 0u);
  EXPECT_EQ(summary.imu_samples, 475u);
  EXPECT_EQ(summary.images, 0u);
  const Dataset dataset = ReadDataset(folder / "dataset");
  EXPECT_EQ(dataset.camera.width, 320);
  EXPECT_TRUE(dataset.images.empty());
  std::filesystem::remove_all(folder);
}

}  // namespace
}  // namespace evloc
