#include "core/dataset/rosbag_dataset.h"

#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/events/testing/test_bags.h"

namespace evloc {
namespace {

EventBuffer ReadAll(EventReader* reader) {
  EventBuffer events;
  while (reader->Read(1000, &events) > 0) {
  }
  return events;
}

void ExpectGroundTruthAsWritten(const Trajectory& trajectory, const std::filesystem::path& dir,
                                double tolerance) {
  const auto poses = testing::ReadExpectedLines(dir, "poses");
  ASSERT_EQ(trajectory.size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    const TimedPose& pose = trajectory.poses()[i];
    EXPECT_EQ(pose.t_ns, std::stoll(poses[i][0]));
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(pose.world_from_cam.translation[k], std::stod(poses[i][1 + k]), tolerance);
    }
    EXPECT_NEAR(pose.world_from_cam.rotation.z(), std::stod(poses[i][6]), tolerance);
    EXPECT_NEAR(pose.world_from_cam.rotation.w(), std::stod(poses[i][7]), tolerance);
  }
}

TEST(RecordingFlags, EachFlagSetsItsTopicOrStreamAndOtherFlagsAreLeftToTheCaller) {
  RosbagTopics topics;
  Aedat4DatasetOptions aedat4;
  EXPECT_EQ(topics.events, "/dvs/events");
  EXPECT_EQ(aedat4.events, "events");
  EXPECT_TRUE(ApplyRecordingFlag("--events-topic", "/e", &topics, &aedat4));
  EXPECT_TRUE(ApplyRecordingFlag("--image-topic", "/i", &topics, &aedat4));
  EXPECT_TRUE(ApplyRecordingFlag("--camera-info-topic", "/c", &topics, &aedat4));
  EXPECT_TRUE(ApplyRecordingFlag("--groundtruth-topic", "/g", &topics, &aedat4));
  EXPECT_TRUE(ApplyRecordingFlag("--calib", "c.yaml", &topics, &aedat4));
  EXPECT_TRUE(ApplyRecordingFlag("--groundtruth", "gt.txt", &topics, &aedat4));
  EXPECT_FALSE(ApplyRecordingFlag("--topic", "/x", &topics, &aedat4));
  EXPECT_EQ(topics.events, "/e");
  EXPECT_EQ(topics.image, "/i");
  EXPECT_EQ(topics.camera_info, "/c");
  EXPECT_EQ(topics.groundtruth, "/g");
  EXPECT_EQ(aedat4.events, "/e");
  EXPECT_EQ(aedat4.frames, "/i");
  EXPECT_EQ(aedat4.calibration, "c.yaml");
  EXPECT_EQ(aedat4.groundtruth, "gt.txt");
  for (const char* flag : {"--events-topic", "--image-topic", "--camera-info-topic",
                           "--groundtruth-topic", "--calib", "--groundtruth "}) {
    EXPECT_NE(std::string(kRecordingFlagsUsage).find(flag), std::string::npos) << flag;
  }
}

TEST(RosbagDataset, ReadsTheCameraGroundTruthAndEventsOfABag) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  for (const char* compression : {"none", "bz2", "lz4"}) {
    const auto path = dir / (std::string("test_") + compression + ".bag");
    const Dataset dataset = ReadDataset(path);
    ASSERT_TRUE(dataset.bag);
    EXPECT_EQ(dataset.camera.model, CameraModel::kRadialTangential);
    EXPECT_EQ(dataset.camera.width, 240);
    EXPECT_EQ(dataset.camera.height, 180);
    EXPECT_DOUBLE_EQ(dataset.camera.fx, 199.092366542);
    EXPECT_DOUBLE_EQ(dataset.camera.fy, 198.82882047);
    EXPECT_DOUBLE_EQ(dataset.camera.cx, 132.192071378);
    EXPECT_DOUBLE_EQ(dataset.camera.cy, 110.712660011);
    EXPECT_EQ(dataset.camera.distortion,
              (std::vector<double>{-0.368436311798, 0.150947243557, -0.000296130534385,
                                   -0.000759431726241, 0.0}));
    ASSERT_TRUE(dataset.ground_truth);
    ExpectGroundTruthAsWritten(*dataset.ground_truth, dir, 1e-9);
    EXPECT_EQ(dataset.bag->image_messages, 4u);
    const auto reader = OpenDatasetEvents(dataset);
    EXPECT_EQ(ReadAll(reader.get()), testing::ReadExpectedEvents(dir, "dvs")) << compression;
    // The initial pose is the first ground-truth pose.
    EXPECT_EQ(ResolveInitialPose(dataset, std::nullopt, 0).t_ns, dataset.ground_truth->start_ns());
  }
}

TEST(RosbagDataset, TheTopicsComeFromTheOptions) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  DatasetReaderOptions options;
  options.bag_topics.events = "/packets/mono";
  options.bag_topics.groundtruth = "/vicon/davis";
  const Dataset dataset = ReadDataset(dir / "test_lz4.bag", options);
  EXPECT_FALSE(dataset.ground_truth);
  const auto reader = OpenDatasetEvents(dataset);
  EXPECT_EQ(ReadAll(reader.get()), testing::ReadExpectedEvents(dir, "mono"));
  try {
    ResolveInitialPose(dataset, std::nullopt, 0);
    FAIL() << "no ground truth and no initial pose were accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("no ground-truth topic '/vicon/davis'"),
              std::string::npos)
        << error.what();
    EXPECT_NE(std::string(error.what()).find("/optitrack/davis (geometry_msgs/PoseStamped)"),
              std::string::npos)
        << error.what();
  }
}

TEST(RosbagDataset, MissingOrMistypedTopicsAreErrorsListingTheTopicsPresent) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  DatasetReaderOptions options;
  options.bag_topics.camera_info = "/davis/left/camera_info";
  try {
    ReadDataset(dir / "test_none.bag", options);
    FAIL() << "a missing camera-info topic was accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("no camera-info topic '/davis/left/camera_info'"),
              std::string::npos);
    EXPECT_NE(std::string(error.what()).find("/dvs/camera_info (sensor_msgs/CameraInfo)"),
              std::string::npos)
        << error.what();
  }
  options = {};
  options.bag_topics.image = "/dvs/events";
  EXPECT_THROW(ReadDataset(dir / "test_none.bag", options), InvalidArgumentError);
  options = {};
  options.bag_topics.events = "/dvs/eventz";
  const Dataset dataset = ReadDataset(dir / "test_none.bag", options);
  EXPECT_THROW(OpenDatasetEvents(dataset), InvalidArgumentError);
  options.bag_topics.events = "";
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

TEST(RosbagDataset, TheImagesOfABagComeOneAtATimeAsWrittenAndLikeItsConvertedFolders) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  const Dataset bag = ReadDataset(dir / "test_lz4.bag");
  EXPECT_TRUE(DatasetHasImages(bag));
  std::vector<std::pair<int64_t, cv::Mat>> from_bag;
  ForEachDatasetImage(bag, [&](int64_t t_ns, const cv::Mat& pixels) {
    from_bag.emplace_back(t_ns, pixels.clone());
  });
  const auto images = testing::ReadExpectedLines(dir, "images");
  ASSERT_EQ(from_bag.size(), images.size());
  for (size_t i = 0; i < images.size(); ++i) {
    EXPECT_EQ(from_bag[i].first, std::stoll(images[i][0]));
    ASSERT_EQ(from_bag[i].second.type(), CV_8UC1);
    EXPECT_EQ(static_cast<int64_t>(cv::sum(from_bag[i].second)[0]), std::stoll(images[i][4]));
  }
  // The converted folder hands over the same pixels.
  const auto out = testing::MakeTempDir("bag-images") / "converted";
  ConvertRosbagToDataset(dir / "test_lz4.bag", out, {}, {});
  size_t index = 0;
  ForEachDatasetImage(ReadDataset(out), [&](int64_t t_ns, const cv::Mat& pixels) {
    ASSERT_LT(index, from_bag.size());
    EXPECT_EQ(t_ns, from_bag[index].first);
    EXPECT_EQ(cv::norm(pixels, from_bag[index].second, cv::NORM_INF), 0.0);
    ++index;
  });
  EXPECT_EQ(index, from_bag.size());
  std::filesystem::remove_all(out.parent_path());
  // A bag whose image topic has no messages has no images.
  DatasetReaderOptions options;
  options.bag_topics.image = "/no/images";
  const Dataset without = ReadDataset(dir / "test_lz4.bag", options);
  EXPECT_FALSE(DatasetHasImages(without));
  ForEachDatasetImage(without, [](int64_t, const cv::Mat&) { ADD_FAILURE() << "an image"; });
}

TEST(RosbagDataset, ConvertsABagToADatasetFolderThatReadsBackEqual) {
  EVLOC_REQUIRE_TEST_BAGS(dir);
  const auto out = testing::MakeTempDir("bag-dataset") / "converted";
  const RecordingConversionSummary summary =
      ConvertRosbagToDataset(dir / "test_bz2.bag", out, {}, {});
  const EventBuffer expected = testing::ReadExpectedEvents(dir, "dvs");
  EXPECT_EQ(summary.events, expected.size());
  EXPECT_EQ(summary.images, 4u);
  EXPECT_EQ(summary.poses, 30u);
  const Dataset dataset = ReadDataset(out);
  EXPECT_FALSE(dataset.bag);
  const auto reader = OpenDatasetEvents(dataset);
  EXPECT_EQ(reader->sensor_size(), (SensorSize{240, 180}));
  EXPECT_EQ(ReadAll(reader.get()), expected);
  const Dataset from_bag = ReadDataset(dir / "test_bz2.bag");
  EXPECT_EQ(dataset.camera.distortion, from_bag.camera.distortion);
  EXPECT_DOUBLE_EQ(dataset.camera.fx, from_bag.camera.fx);
  ASSERT_TRUE(dataset.ground_truth);
  ExpectGroundTruthAsWritten(*dataset.ground_truth, dir, 1e-6);
  const auto images = testing::ReadExpectedLines(dir, "images");
  ASSERT_EQ(dataset.images.size(), images.size());
  for (size_t i = 0; i < images.size(); ++i) {
    EXPECT_EQ(dataset.images[i].t_ns, std::stoll(images[i][0]));
    const cv::Mat pixels = cv::imread(dataset.images[i].path.string(), cv::IMREAD_UNCHANGED);
    ASSERT_EQ(pixels.type(), CV_8UC1);
    EXPECT_EQ(pixels.cols, 240);
    EXPECT_EQ(pixels.rows, 180);
    EXPECT_EQ(static_cast<int64_t>(cv::sum(pixels)[0]), std::stoll(images[i][4]));
  }
  // An existing output is not replaced without force.
  EXPECT_THROW(ConvertRosbagToDataset(dir / "test_bz2.bag", out, {}, {}), InvalidArgumentError);
  std::filesystem::remove_all(out.parent_path());
}

}  // namespace
}  // namespace evloc
