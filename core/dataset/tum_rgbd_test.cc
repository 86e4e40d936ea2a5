#include "core/dataset/tum_rgbd.h"

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/common/error.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

namespace fs = std::filesystem;

// A tiny TUM RGB-D folder written as the benchmark writes its files: header comments, colour and
// depth at their own times (depth 10-25 ms off), depth in 1/5000 m, freiburg1 intrinsics.
fs::path WriteTumSample(const std::string& name) {
  const fs::path root = evloc::testing::MakeTempDir(name);
  fs::create_directories(root / "rgb");
  fs::create_directories(root / "depth");
  std::ofstream rgb(root / "rgb.txt");
  rgb << "# color images\n# file: 'rgbd_dataset_freiburg1_xyz.bag'\n# timestamp filename\n";
  std::ofstream depth(root / "depth.txt");
  depth << "# depth maps\n# file: 'rgbd_dataset_freiburg1_xyz.bag'\n# timestamp filename\n";
  const char* rgb_times[] = {"1305031102.175304", "1305031102.211214", "1305031102.243211",
                             "1305031102.275326"};
  // The third colour frame has no depth within 20 ms; the last depth map is 25 ms late.
  const char* depth_times[] = {"1305031102.160407", "1305031102.226738", "1305031102.300326"};
  for (const char* t : rgb_times) {
    const std::string file = std::string("rgb/") + t + ".png";
    cv::imwrite((root / file).string(), cv::Mat(12, 16, CV_8UC3, cv::Scalar(10, 20, 30)));
    rgb << t << " " << file << "\n";
  }
  for (int i = 0; i < 3; ++i) {
    const std::string file = std::string("depth/") + depth_times[i] + ".png";
    cv::Mat raw(12, 16, CV_16UC1, cv::Scalar(5000 * (i + 1)));  // 1, 2, 3 m
    raw.at<uint16_t>(0, 0) = 0;                                 // a hole
    raw.at<uint16_t>(1, 0) = 7;                                 // 1.4 mm
    cv::imwrite((root / file).string(), raw);
    depth << depth_times[i] << " " << file << "\n";
  }
  std::ofstream(root / "calib.txt")
      << "517.3 516.5 318.6 255.3 0.2624 -0.9531 -0.0054 0.0026 1.1633\n";
  std::ofstream(root / "groundtruth.txt")
      << "# ground truth trajectory\n# file: 'rgbd_dataset_freiburg1_xyz.bag'\n"
         "# timestamp tx ty tz qx qy qz qw\n"
         "1305031098.6659 1.3563 0.6305 1.6380 0.6132 0.5962 -0.3311 -0.3986\n"
         "1305031098.6758 1.3543 0.6306 1.6360 0.6129 0.5966 -0.3316 -0.3980\n";
  return root;
}

TEST(TumRgbd, ReadsAReferenceWrittenFolder) {
  const fs::path root = WriteTumSample("tum_rgbd_sample");
  EXPECT_TRUE(IsTumRgbdFolder(root));
  const Dataset dataset = ReadDataset(root);
  EXPECT_EQ(dataset.layout, DatasetLayout::kTumRgbd);
  EXPECT_EQ(dataset.depth_units_per_metre, 5000.0);
  EXPECT_EQ(dataset.camera.width, 16);
  EXPECT_EQ(dataset.camera.height, 12);
  EXPECT_EQ(dataset.camera.model, CameraModel::kRadialTangential);
  EXPECT_DOUBLE_EQ(dataset.camera.fx, 517.3);
  ASSERT_EQ(dataset.images.size(), 4u);
  ASSERT_EQ(dataset.depth.size(), 3u);
  EXPECT_EQ(dataset.images[0].t_ns, 1305031102'175304000LL);
  EXPECT_EQ(dataset.depth[2].t_ns, 1305031102'300326000LL);
  EXPECT_EQ(dataset.images[1].path, root / "rgb/1305031102.211214.png");
  ASSERT_TRUE(dataset.ground_truth.has_value());
  EXPECT_EQ(dataset.ground_truth->size(), 2u);

  const cv::Mat metres = ReadDepthPng(dataset.depth[1].path, dataset.depth_units_per_metre);
  EXPECT_EQ(metres.type(), CV_32FC1);
  EXPECT_FLOAT_EQ(metres.at<float>(5, 5), 2.0f);
  EXPECT_FLOAT_EQ(metres.at<float>(0, 0), 0.0f);
  EXPECT_FLOAT_EQ(metres.at<float>(1, 0), 7.0f / 5000.0f);

  // Nearest time within 20 ms, each frame used once: rgb 0 <-> depth 0 (14.9 ms), rgb 1 <->
  // depth 1 (15.5 ms; rgb 2 is 16.5 ms from it and loses), rgb 3 <-> depth 2 (25 ms: too far).
  const std::vector<TimeAssociation> pairs =
      AssociateByTime(dataset.images, dataset.depth, kTumAssociationToleranceNs);
  ASSERT_EQ(pairs.size(), 2u);
  EXPECT_EQ(pairs[0].first, 0u);
  EXPECT_EQ(pairs[0].second, 0u);
  EXPECT_EQ(pairs[1].first, 1u);
  EXPECT_EQ(pairs[1].second, 1u);
  // A wider tolerance pairs the last ones too.
  EXPECT_EQ(AssociateByTime(dataset.images, dataset.depth, 30'000'000).size(), 3u);
  fs::remove_all(root);
}

TEST(TumRgbd, GreedyAssociationTakesTheClosestPairFirst) {
  auto at = [](std::initializer_list<int64_t> times) {
    std::vector<TimedFile> files;
    for (int64_t t : times) files.push_back({t, "x"});
    return files;
  };
  // 100 is 4 from 104 and 6 from 94; 110 is 6 from 104 and 14 from 124: the closest pair
  // (100, 104) goes first; 100 and 104 are then used, and (110, 124) is too far at tolerance 10.
  const auto pairs = AssociateByTime(at({100, 110}), at({94, 104, 124}), 10);
  ASSERT_EQ(pairs.size(), 1u);
  EXPECT_EQ(pairs[0].first, 0u);
  EXPECT_EQ(pairs[0].second, 1u);
  // The same times at tolerance 0: only exact matches; equal times associate.
  EXPECT_EQ(AssociateByTime(at({1, 2, 3}), at({2, 3, 4}), 0).size(), 2u);
  EXPECT_TRUE(AssociateByTime({}, at({1}), 5).empty());
  EXPECT_THROW(AssociateByTime(at({1}), at({1}), -1), InvalidArgumentError);
  // Extreme times do not overflow the differences.
  const auto extremes = AssociateByTime(at({INT64_MIN + 1, 0}), at({INT64_MAX}), INT64_MAX);
  ASSERT_EQ(extremes.size(), 1u);
  EXPECT_EQ(extremes[0].first, 1u);
}

TEST(TumRgbd, ErrorsSayWhatToDo) {
  const fs::path root = WriteTumSample("tum_rgbd_errors");
  fs::remove(root / "calib.txt");
  try {
    ReadDataset(root);
    FAIL() << "expected an InvalidArgumentError";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("freiburg1: 517.3"), std::string::npos)
        << error.what();
  }
  std::ofstream(root / "calib.txt") << "517.3 516.5 318.6 255.3 0 0 0 0 0\n";
  std::ofstream(root / "depth.txt", std::ios::app) << "1305031102.1 depth/missing.png\n";
  try {
    ReadDataset(root);
    FAIL() << "expected a ParseError";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("line 7"), std::string::npos) << error.what();
  }
  std::ofstream(root / "depth.txt", std::ios::trunc) << "1305031103 depth/missing.png\n";
  EXPECT_THROW(ReadDataset(root), IoError);
  EXPECT_THROW(ReadDepthPng(root / "rgb" / "1305031102.175304.png", 5000), ParseError);
  EXPECT_THROW(ReadDepthPng(root / "calib.txt", 0.0), InvalidArgumentError);
  fs::remove_all(root);
}

TEST(TumRgbd, ReadsTheRealFreiburg1GroundTruth) {
  EVLOC_REQUIRE_SHARED_DATA(groundtruth, "tum-trajectories/fr1_xyz_groundtruth.txt");
  const fs::path root = WriteTumSample("tum_rgbd_real_gt");
  fs::copy_file(groundtruth, root / "groundtruth.txt", fs::copy_options::overwrite_existing);
  const Dataset dataset = ReadDataset(root);
  ASSERT_TRUE(dataset.ground_truth.has_value());
  // freiburg1_xyz: 30 s of motion capture at 100 Hz.
  EXPECT_GT(dataset.ground_truth->size(), 2900u);
  EXPECT_NEAR((dataset.ground_truth->end_ns() - dataset.ground_truth->start_ns()) * 1e-9, 30.0,
              0.5);
  fs::remove_all(root);
}

}  // namespace
}  // namespace evloc
