#include "core/dataset/dataset.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/common/error.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

namespace fs = std::filesystem;

TEST(Dataset, WriterReaderRoundTrip) {
  const fs::path root = evloc::testing::MakeTempDir("dataset_round_trip");
  const fs::path out = root / "seq";
  const Camera camera = Camera::Pinhole(16, 12, 20, 21, 7.5, 5.5);
  std::vector<TimedPose> poses;
  for (int i = 0; i < 5; ++i) {
    poses.push_back(
        {i * 5'000'000, Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(i * 0.01, 0, 1))});
  }
  {
    DatasetWriter writer(out, {});
    writer.WriteCamera(camera);
    for (int i = 0; i < 3; ++i) {
      writer.AddImage(1'000'000'000LL + i * 33'333'333,
                      cv::Mat(12, 16, CV_8UC3, cv::Scalar(i, 2 * i, 3 * i)));
      cv::Mat depth(12, 16, CV_32FC1, cv::Scalar(1.2341 + i));
      depth.at<float>(0, 0) = 0;
      writer.AddDepth(1'000'000'000LL + i * 33'333'333, depth);
    }
    writer.WriteGroundTruth(Trajectory(poses));
    writer.WriteInfo({{"seed", 4}});
    EXPECT_TRUE(fs::exists(writer.staging_dir()));
    EXPECT_FALSE(fs::exists(out));
    writer.Commit();
  }
  EXPECT_FALSE(fs::exists(root / "seq.partial"));
  EXPECT_FALSE(fs::exists(out / "gt_map"));  // nothing was written there
  const Dataset dataset = ReadDataset(out);
  EXPECT_EQ(dataset.camera, camera);
  ASSERT_EQ(dataset.images.size(), 3u);
  EXPECT_EQ(dataset.images[2].t_ns, 1'000'000'000LL + 2 * 33'333'333);
  EXPECT_EQ(cv::imread(dataset.images[1].path.string(), cv::IMREAD_UNCHANGED).at<cv::Vec3b>(3, 3),
            cv::Vec3b(1, 2, 3));
  ASSERT_EQ(dataset.depth.size(), 3u);
  const cv::Mat depth = ReadDepthPng(dataset.depth[1].path);
  EXPECT_NEAR(depth.at<float>(5, 5), 2.234, 1e-6);  // rounded to millimetres
  EXPECT_EQ(depth.at<float>(0, 0), 0.0f);
  ASSERT_TRUE(dataset.ground_truth.has_value());
  EXPECT_EQ(dataset.ground_truth->size(), 5u);
  EXPECT_EQ(dataset.ground_truth->poses()[3].world_from_cam.translation,
            poses[3].world_from_cam.translation);
  ASSERT_TRUE(dataset.info.has_value());
  EXPECT_EQ((*dataset.info)["seed"], 4);
  EXPECT_FALSE(dataset.events_path.has_value());
  // --calib and --groundtruth (AEDAT4 only) on a dataset folder are refused, not ignored.
  DatasetReaderOptions with_calib;
  with_calib.aedat4.calibration = root / "other.yaml";
  EXPECT_THROW(ReadDataset(out, with_calib), InvalidArgumentError);
  DatasetReaderOptions with_groundtruth;
  with_groundtruth.aedat4.groundtruth = root / "other.txt";
  try {
    ReadDataset(out, with_groundtruth);
    ADD_FAILURE() << "--groundtruth on a dataset folder was accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("AEDAT4 files only"), std::string::npos)
        << error.what();
  }
  fs::remove_all(root);
}

TEST(Dataset, DepthCameraRoundTripWithItsOwnIntrinsicsRateAndExtrinsic) {
  const fs::path root = evloc::testing::MakeTempDir("dataset_depth_camera");
  const fs::path out = root / "seq";
  Camera camera = Camera::Pinhole(16, 12, 20, 21, 7.5, 5.5);
  camera.model = CameraModel::kRadialTangential;
  camera.distortion = {-0.1, 0.02, 0.001, -0.002, 0.0};
  const Camera depth_camera = Camera::Pinhole(20, 15, 18, 18, 9.5, 7.0);
  const Rigid3d event_from_depth(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.02, Eigen::Vector3d(0.3, 1, 0.1).normalized())),
      Eigen::Vector3d(0.05, -0.01, 0.002));
  {
    DatasetWriter writer(out, {});
    writer.WriteCamera(camera);
    EXPECT_THROW(writer.AddDepthCameraFrame(0, cv::Mat(15, 20, CV_32FC1, cv::Scalar(1))),
                 InvalidArgumentError);
    writer.WriteDepthCamera(camera, depth_camera, event_from_depth);
    for (int i = 0; i < 4; ++i) {  // 15 Hz, not the frames' rate
      cv::Mat depth(15, 20, CV_32FC1, cv::Scalar(0.8 + 0.25 * i));
      depth.at<float>(2, 3) = 0;
      writer.AddDepthCameraFrame(10'000'000LL + i * 66'666'667, depth);
    }
    writer.Commit();
  }
  const Dataset dataset = ReadDataset(out);
  ASSERT_TRUE(dataset.depth_camera.has_value());
  EXPECT_EQ(dataset.depth_camera->camera, depth_camera);
  EXPECT_LT(
      (dataset.depth_camera->event_from_depth.translation - event_from_depth.translation).norm(),
      1e-12);
  EXPECT_LT(
      dataset.depth_camera->event_from_depth.rotation.angularDistance(event_from_depth.rotation),
      1e-12);
  ASSERT_EQ(dataset.depth_camera->frames.size(), 4u);
  EXPECT_EQ(dataset.depth_camera->frames[3].t_ns, 10'000'000LL + 3 * 66'666'667);
  const cv::Mat depth = ReadDepthPng(dataset.depth_camera->frames[2].path);
  EXPECT_EQ(depth.cols, 20);
  EXPECT_NEAR(depth.at<float>(5, 5), 1.3, 1e-6);
  EXPECT_EQ(depth.at<float>(2, 3), 0.0f);
  EXPECT_TRUE(dataset.depth.empty());

  // A camchain whose cam0 is not the event camera, or whose depth camera has no extrinsic, is
  // refused, naming the file.
  const std::string camchain = (out / dataset_files::kDepthCamchainYaml).string();
  std::ofstream(camchain) << "cam0:\n  camera_model: pinhole\n  distortion_model: none\n"
                             "  distortion_coeffs: []\n  intrinsics: [20, 21, 7.5, 5.5]\n"
                             "  resolution: [16, 12]\ncam1:\n  camera_model: pinhole\n"
                             "  distortion_model: none\n  distortion_coeffs: []\n"
                             "  intrinsics: [18, 18, 9.5, 7]\n  resolution: [20, 15]\n";
  try {
    ReadDataset(out);
    FAIL() << "a depth camera without T_cn_cnm1 was accepted";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("T_cn_cnm1"), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find("depth_camchain.yaml"), std::string::npos);
  }
  // A radtan k3 cannot be stated in a camchain.
  camera.distortion[4] = 0.01;
  DatasetWriter writer(root / "k3", {});
  EXPECT_THROW(writer.WriteDepthCamera(camera, depth_camera, event_from_depth),
               InvalidArgumentError);
  fs::remove_all(root);
}

TEST(Dataset, RefusesNonEmptyOutputWithoutForceAndReplacesWithForce) {
  const fs::path root = evloc::testing::MakeTempDir("dataset_force");
  const fs::path out = root / "seq";
  fs::create_directories(out);
  std::ofstream(out / "old.txt") << "old";
  EXPECT_THROW(DatasetWriter(out, {}), InvalidArgumentError);
  DatasetWriter writer(out, DatasetWriterOptions{true});
  writer.WriteCamera(Camera::Pinhole(4, 4, 5, 5, 1.5, 1.5));
  // Until the commit the old content is untouched.
  EXPECT_TRUE(fs::exists(out / "old.txt"));
  writer.Commit();
  EXPECT_FALSE(fs::exists(out / "old.txt"));
  EXPECT_TRUE(fs::exists(out / "calib.yaml"));
  fs::remove_all(root);
}

TEST(Dataset, InterruptedRunLeavesNothingThatLooksComplete) {
  const fs::path root = evloc::testing::MakeTempDir("dataset_interrupted");
  const fs::path out = root / "seq";
  {
    DatasetWriter writer(out, {});
    writer.WriteCamera(Camera::Pinhole(4, 4, 5, 5, 1.5, 1.5));
    writer.AddImage(0, cv::Mat(4, 4, CV_8UC1, cv::Scalar(9)));
  }  // destroyed without Commit: an interrupted run
  EXPECT_FALSE(fs::exists(out));
  EXPECT_THROW(ReadDataset(root / "seq.partial"), InvalidArgumentError);
  // The next run starts over and succeeds.
  DatasetWriter writer(out, {});
  writer.WriteCamera(Camera::Pinhole(4, 4, 5, 5, 1.5, 1.5));
  writer.Commit();
  EXPECT_TRUE(fs::exists(out / "images.txt"));
  fs::remove_all(root);
}

TEST(Dataset, ReadsARealEcdFolder) {
  EVLOC_REQUIRE_SHARED_DATA(calib, "ecd/slider_depth/calib.txt");
  const Dataset dataset = ReadDataset(calib.parent_path());
  EXPECT_EQ(dataset.camera.width, 240);
  EXPECT_EQ(dataset.camera.model, CameraModel::kRadialTangential);
  EXPECT_NEAR(dataset.camera.fx, 335.419462958, 1e-9);
  EXPECT_EQ(dataset.images.size(), 87u);
  EXPECT_EQ(dataset.images[1].t_ns, 38'766'001);
  ASSERT_TRUE(dataset.ground_truth.has_value());
  EXPECT_EQ(dataset.ground_truth->size(), 339u);
  const cv::Mat gray = ReadGrayImage(dataset.images[0].path);
  EXPECT_EQ(gray.cols, 240);
  EXPECT_EQ(gray.rows, 180);
}

// A 240x180 camera in ROS camera_info YAML.
constexpr const char* kRosCameraInfo =
    "image_width: 240\nimage_height: 180\n"
    "camera_matrix: {rows: 3, cols: 3, data: [199, 0, 132, 0, 198, 110, 0, 0, 1]}\n"
    "distortion_model: plumb_bob\n"
    "distortion_coefficients: {rows: 1, cols: 5, data: [-0.3, 0.1, 0, 0, 0]}\n";

// A calib.yaml in another tool's format is read through the detection; what its reader ignored
// comes back with the dataset (the tools print it), naming the file.
TEST(Dataset, CalibrationNotesOfTheReaderComeWithTheDataset) {
  const fs::path root = evloc::testing::MakeTempDir("dataset_calibration_notes");
  std::ofstream(root / "calib.yaml") << kRosCameraInfo << "lens_serial: 42\n";
  const Dataset dataset = ReadDataset(root);
  EXPECT_EQ(dataset.camera.width, 240);
  ASSERT_EQ(dataset.calibration_notes.size(), 1u);
  EXPECT_EQ(dataset.calibration_notes[0],
            (root / "calib.yaml").string() + ": unknown key 'lens_serial' is ignored");
  // evloc's own camera YAML has nothing to say.
  DatasetWriter writer(root / "own", {});
  writer.WriteCamera(dataset.camera);
  writer.Commit();
  EXPECT_TRUE(ReadDataset(root / "own").calibration_notes.empty());
  fs::remove_all(root);
}

// A malformed info.json is a ParseError naming the file, also where nlohmann's parser throws
// out_of_range rather than parse_error (a number beyond double's range).
TEST(Dataset, AMalformedInfoJsonIsAParseErrorNamingTheFile) {
  const fs::path root = evloc::testing::MakeTempDir("dataset_info_json");
  std::ofstream(root / "calib.yaml") << kRosCameraInfo;
  EXPECT_NO_THROW(ReadDataset(root));
  for (const std::string& text : {std::string("{\"a\": "), std::string("{\"a\": 4e+4444}")}) {
    std::ofstream(root / "info.json", std::ios::trunc) << text;
    try {
      ReadDataset(root);
      ADD_FAILURE() << "accepted " << text;
    } catch (const ParseError& error) {
      EXPECT_NE(std::string(error.what()).find("info.json"), std::string::npos) << error.what();
    }
  }
  fs::remove_all(root);
}

TEST(Dataset, ListErrorsNameTheLine) {
  const fs::path root = evloc::testing::MakeTempDir("dataset_list");
  std::ofstream(root / "images.txt") << "0.1 a.png\n0.05 b.png\n";
  try {
    ReadTimedFileList(root / "images.txt", root);
    FAIL() << "expected a ParseError";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("line 2"), std::string::npos) << error.what();
  }
  fs::remove_all(root);
}

TEST(Dataset, ToGray8MakesEveryFrameTypeEightBitGrey) {
  cv::Mat grey(3, 4, CV_8UC1);
  cv::randu(grey, 0, 256);
  EXPECT_EQ(cv::norm(ToGray8(grey), grey, cv::NORM_INF), 0.0);
  cv::Mat sixteen;
  grey.convertTo(sixteen, CV_16U, 257.0);
  EXPECT_EQ(cv::norm(ToGray8(sixteen), grey, cv::NORM_INF), 0.0);
  // Colour: 0.299 R + 0.587 G + 0.114 B, truncated; BGR and BGRA alike.
  const cv::Mat bgr(1, 1, CV_8UC3, cv::Scalar(200, 100, 50));  // B, G, R
  EXPECT_EQ(ToGray8(bgr).type(), CV_8UC1);
  EXPECT_EQ(ToGray8(bgr).at<uint8_t>(0, 0), 96);  // 0.114 * 200 + 0.587 * 100 + 0.299 * 50
  EXPECT_EQ(ToGray8(cv::Mat(1, 1, CV_8UC4, cv::Scalar(200, 100, 50, 7))).at<uint8_t>(0, 0), 96);
  // Exactly what cv::imread(IMREAD_GRAYSCALE) reads from a colour PNG (so a folder's frames are
  // what the tools read before ToGray8).
  cv::Mat colour(60, 80, CV_8UC3);
  cv::randu(colour, 0, 256);
  colour(cv::Rect(0, 0, 10, 10)).setTo(cv::Scalar(77, 77, 77));
  const fs::path png = testing::MakeTempDir("to-gray8") / "colour.png";
  ASSERT_TRUE(cv::imwrite(png.string(), colour));
  EXPECT_EQ(cv::norm(ToGray8(colour), cv::imread(png.string(), cv::IMREAD_GRAYSCALE), cv::NORM_INF),
            0.0);
  fs::remove_all(png.parent_path());
  EXPECT_THROW(ToGray8(cv::Mat(2, 2, CV_32FC1)), InvalidArgumentError);
  EXPECT_THROW(ToGray8(cv::Mat(2, 2, CV_8UC2)), InvalidArgumentError);
}

TEST(Dataset, TheImagesOfAFolderComeAsStoredAndAMissingOneIsAnIoError) {
  const fs::path root = testing::MakeTempDir("dataset-images");
  {
    DatasetWriter writer(root / "set", DatasetWriterOptions{});
    Camera camera;
    camera.width = 4;
    camera.height = 3;
    camera.fx = camera.fy = 2;
    camera.cx = 1.5;
    camera.cy = 1;
    writer.WriteCamera(camera);
    writer.AddImage(1'000'000, cv::Mat(3, 4, CV_8UC1, cv::Scalar(9)));
    writer.AddImage(2'000'000, cv::Mat(3, 4, CV_8UC3, cv::Scalar(1, 2, 3)));
    writer.Commit();
  }
  const Dataset dataset = ReadDataset(root / "set");
  EXPECT_TRUE(DatasetHasImages(dataset));
  std::vector<std::pair<int64_t, int>> seen;
  ForEachDatasetImage(dataset, [&](int64_t t_ns, const cv::Mat& pixels) {
    seen.emplace_back(t_ns, pixels.channels());
  });
  EXPECT_EQ(seen, (std::vector<std::pair<int64_t, int>>{{1'000'000, 1}, {2'000'000, 3}}));
  fs::remove(dataset.images[1].path);
  try {
    ForEachDatasetImage(dataset, [](int64_t, const cv::Mat&) {});
    ADD_FAILURE() << "no error for a missing image";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find(dataset.images[1].path.filename().string()),
              std::string::npos)
        << error.what();
  }
  fs::remove_all(root);
}

TEST(ResolveInitialPose, GroundTruthStartElseFirstMeasurement) {
  Dataset dataset;
  dataset.root = "/data/seq";
  const Rigid3d given(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 2, 3));
  // No ground truth: the given pose at the first measurement's time.
  const TimedPose without_truth = ResolveInitialPose(dataset, given, 5'000'000'000);
  EXPECT_EQ(without_truth.t_ns, 5'000'000'000);
  EXPECT_EQ(without_truth.world_from_cam.translation, given.translation);
  // Neither: a clear error naming the dataset.
  try {
    ResolveInitialPose(dataset, std::nullopt, 0);
    FAIL();
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("/data/seq"), std::string::npos);
  }
  // Ground truth: its first pose at its start, unless a pose is given.
  const Rigid3d truth(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-1, 0, 0));
  dataset.ground_truth = Trajectory({{7, truth}, {9, truth}});
  const TimedPose from_truth = ResolveInitialPose(dataset, std::nullopt, 5);
  EXPECT_EQ(from_truth.t_ns, 7);
  EXPECT_EQ(from_truth.world_from_cam.translation, truth.translation);
  EXPECT_EQ(ResolveInitialPose(dataset, given, 5).world_from_cam.translation, given.translation);
}

}  // namespace
}  // namespace evloc
