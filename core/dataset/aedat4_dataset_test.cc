#include "core/dataset/aedat4_dataset.h"

#include <gtest/gtest.h>

#include <fstream>

#include <opencv2/imgcodecs.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "core/events/testing/test_bags.h"
#include "core/trajectory/tum_io.h"

namespace evloc {
namespace {

// A 346x260 pinhole camera and a three-pose ground truth beside the test files.
DatasetReaderOptions SideFiles(const std::filesystem::path& folder) {
  Camera camera;
  camera.model = CameraModel::kPinhole;
  camera.width = 346;
  camera.height = 260;
  camera.fx = camera.fy = 250.5;
  camera.cx = 172.5;
  camera.cy = 129.5;
  WriteCameraYaml(folder / "davis346.yaml", camera);
  WriteFileAtomically(folder / "gt.txt",
                      "1700000000.000 0 0 0 0 0 0 1\n"
                      "1700000000.010 0.01 0 0 0 0 0 1\n"
                      "1700000000.020 0.02 0 0 0 0 0 1\n");
  DatasetReaderOptions options;
  options.aedat4.calibration = folder / "davis346.yaml";
  options.aedat4.groundtruth = folder / "gt.txt";
  return options;
}

TEST(Aedat4Dataset, ReadsTheEventsWithTheCalibrationAndGroundTruthGiven) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  const auto folder = testing::MakeTempDir("aedat4-dataset");
  const DatasetReaderOptions options = SideFiles(folder);
  for (const char* name : {"test_none.aedat4", "test_lz4.aedat4", "test_zstd.aedat4"}) {
    const Dataset dataset = ReadDataset(dir / name, options);
    ASSERT_TRUE(dataset.aedat4);
    EXPECT_FALSE(dataset.bag);
    EXPECT_TRUE(dataset.aedat4->has_frames);
    EXPECT_EQ(dataset.camera.width, 346);
    EXPECT_DOUBLE_EQ(dataset.camera.fx, 250.5);
    ASSERT_TRUE(dataset.ground_truth);
    EXPECT_EQ(dataset.ground_truth->size(), 3u);
    const auto reader = OpenDatasetEvents(dataset);
    EXPECT_EQ(testing::ReadAllEvents(reader.get(), 1000),
              testing::ReadExpectedEvents(dir, "events"))
        << name;
    EXPECT_EQ(ResolveInitialPose(dataset, std::nullopt, 0).t_ns, 1700000000000000000);
  }
  std::filesystem::remove_all(folder);
}

TEST(Aedat4Dataset, MissingOrMismatchedSideFilesAndStreamsAreErrorsListingTheStreams) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  const auto folder = testing::MakeTempDir("aedat4-dataset");
  const auto expect_error = [&](const DatasetReaderOptions& options, const std::string& what) {
    try {
      OpenDatasetEvents(ReadDataset(dir / "test_lz4.aedat4", options));
      FAIL() << "accepted; expected: " << what;
    } catch (const InvalidArgumentError& error) {
      EXPECT_NE(std::string(error.what()).find(what), std::string::npos) << error.what();
    }
  };
  DatasetReaderOptions options;
  expect_error(options, "holds no camera calibration; give the camera with --calib");
  expect_error(options, "events (id 0, EVTS), frames (id 1, FRME), imu (id 2, IMUS)");
  options = SideFiles(folder);
  options.aedat4.events = "frames";
  expect_error(options, "the events stream 'frames' has type FRME, expected EVTS");
  options = SideFiles(folder);
  options.aedat4.events = "dvs";
  expect_error(options, "has no stream 'dvs'; its streams are: events (id 0, EVTS)");
  options = SideFiles(folder);
  Camera small = ReadCameraYaml(options.aedat4.calibration);
  small.width = 240;
  small.height = 180;
  WriteCameraYaml(folder / "davis240.yaml", small);
  options.aedat4.calibration = folder / "davis240.yaml";
  expect_error(options, "is 240x180 but the events stream 'events' is 346x260");
  // No ground truth and no initial pose.
  options = SideFiles(folder);
  options.aedat4.groundtruth.clear();
  try {
    ResolveInitialPose(ReadDataset(dir / "test_lz4.aedat4", options), std::nullopt, 0);
    FAIL() << "no ground truth and no initial pose were accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("--groundtruth or the initial pose with --init-pose"),
              std::string::npos)
        << error.what();
  }
  std::filesystem::remove_all(folder);
}

TEST(Aedat4Dataset, TheFramesOfAFileComeOneAtATimeAsWrittenAndLikeItsConvertedFolders) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  const auto folder = testing::MakeTempDir("aedat4-frames");
  const DatasetReaderOptions options = SideFiles(folder);
  const Dataset file = ReadDataset(dir / "test_lz4.aedat4", options);
  EXPECT_TRUE(DatasetHasImages(file));
  std::vector<std::pair<int64_t, cv::Mat>> from_file;
  ForEachDatasetImage(file, [&](int64_t t_ns, const cv::Mat& pixels) {
    from_file.emplace_back(t_ns, pixels.clone());
  });
  const auto frames = testing::ReadExpectedLines(dir, "frames");
  ASSERT_EQ(from_file.size(), frames.size());
  bool colour = false;
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(from_file[i].first, std::stoll(frames[i][0]));
    EXPECT_EQ(from_file[i].second.channels(), std::stoi(frames[i][3]));
    const cv::Scalar sum = cv::sum(from_file[i].second);
    EXPECT_EQ(static_cast<int64_t>(sum[0] + sum[1] + sum[2]), std::stoll(frames[i][4]));
    colour = colour || from_file[i].second.channels() == 3;
  }
  EXPECT_TRUE(colour) << "the test file has a BGR frame";
  // The converted folder gives the same grey pixels (ToGray8, the one conversion).
  ConvertRecordingToDataset(dir / "test_lz4.aedat4", folder / "converted", options, {});
  size_t index = 0;
  ForEachDatasetImage(ReadDataset(folder / "converted"), [&](int64_t t_ns, const cv::Mat& pixels) {
    ASSERT_LT(index, from_file.size());
    EXPECT_EQ(t_ns, from_file[index].first);
    EXPECT_EQ(cv::norm(ToGray8(pixels), ToGray8(from_file[index].second), cv::NORM_INF), 0.0);
    ++index;
  });
  EXPECT_EQ(index, from_file.size());
  std::filesystem::remove_all(folder);
}

TEST(Aedat4Dataset, ConvertsToADatasetFolderThatReadsBackEqual) {
  EVLOC_REQUIRE_TEST_AEDAT4(dir);
  const auto folder = testing::MakeTempDir("aedat4-convert");
  const DatasetReaderOptions options = SideFiles(folder);
  const auto out = folder / "converted";
  const RecordingConversionSummary summary =
      ConvertRecordingToDataset(dir / "test_zstd-high.aedat4", out, options, {});
  const EventBuffer expected = testing::ReadExpectedEvents(dir, "events");
  EXPECT_EQ(summary.events, expected.size());
  EXPECT_EQ(summary.dropped_events, 3u);
  EXPECT_EQ(summary.poses, 3u);
  EXPECT_EQ(summary.imu_samples, testing::ReadExpectedLines(dir, "imu").size());
  EXPECT_EQ(summary.triggers, testing::ReadExpectedLines(dir, "triggers").size());
  const Dataset dataset = ReadDataset(out);
  EXPECT_FALSE(dataset.aedat4);
  EXPECT_EQ(testing::ReadAllEvents(OpenDatasetEvents(dataset).get(), 4096), expected);
  EXPECT_EQ(dataset.camera.width, 346);
  ASSERT_TRUE(dataset.ground_truth);
  EXPECT_EQ(dataset.ground_truth->size(), 3u);
  const auto frames = testing::ReadExpectedLines(dir, "frames");
  ASSERT_EQ(dataset.images.size(), frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(dataset.images[i].t_ns, std::stoll(frames[i][0]));
    const cv::Mat pixels = cv::imread(dataset.images[i].path.string(), cv::IMREAD_UNCHANGED);
    EXPECT_EQ(pixels.channels(), std::stoi(frames[i][3]));
    EXPECT_EQ(pixels.cols, 346);
    const cv::Scalar sum = cv::sum(pixels);
    EXPECT_EQ(static_cast<int64_t>(sum[0] + sum[1] + sum[2]), std::stoll(frames[i][4]));
  }
  // imu.txt: seconds, m/s^2 and rad/s.
  const auto imu = testing::ReadExpectedLines(dir, "imu");
  std::ifstream imu_file(out / dataset_files::kImuTxt);
  std::string line;
  std::getline(imu_file, line);
  EXPECT_EQ(line.rfind("# t_s ax ay az", 0), 0u) << line;
  double t_s, ax, ay, az, gx, gy, gz;
  ASSERT_TRUE(imu_file >> t_s >> ax >> ay >> az >> gx >> gy >> gz);
  EXPECT_NEAR(t_s, std::stod(imu[0][0]) * 1e-9, 1e-6);
  EXPECT_NEAR(ax, std::stod(imu[0][2]) * 9.80665, 1e-4);
  EXPECT_NEAR(gz, std::stod(imu[0][7]) * 3.14159265358979 / 180.0, 1e-5);
  ASSERT_TRUE(dataset.info);
  EXPECT_EQ((*dataset.info)["converted_from"], "AEDAT4");
  EXPECT_EQ((*dataset.info)["counts"]["triggers"], summary.triggers);
  // Anything but a bag or an AEDAT4 file is refused.
  EXPECT_THROW(ConvertRecordingToDataset(folder / "gt.txt", folder / "x", options, {}),
               InvalidArgumentError);
  std::filesystem::remove_all(folder);
}

}  // namespace
}  // namespace evloc
