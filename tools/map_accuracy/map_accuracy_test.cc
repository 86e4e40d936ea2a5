#include "tools/map_accuracy/map_accuracy.h"

#include <sys/wait.h>

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <string>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/dataset/dataset.h"

namespace evloc::mapper {
namespace {

// A row of edge points every 1 cm on the plane z = 2 m, gradients along +y.
Map MakeEdgeMap(double z_offset) {
  Map map;
  for (int i = -40; i <= 40; ++i) {
    map.positions.emplace_back(0.01f * static_cast<float>(i), 0.0f,
                               static_cast<float>(2.0 + z_offset));
    map.gradients.emplace_back(0.0f, 1.0f, 0.0f);
  }
  return map;
}

// A fronto-parallel view of the plane z = 2 m from the origin.
DepthView MakePlaneView() {
  DepthView view;
  view.camera = Camera::Pinhole(64, 48, 50.0, 50.0, 31.5, 23.5);
  view.cam_from_world = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d::Zero());
  view.depth_m = cv::Mat(48, 64, CV_32F, cv::Scalar(2.0f));
  return view;
}

TEST(MapAccuracy, ExactMapHasNoError) {
  const Map reference = MakeEdgeMap(0.0);
  const MapAccuracy accuracy =
      MeasureMapAccuracy(reference, reference, {MakePlaneView()}, MapAccuracyOptions());
  EXPECT_EQ(accuracy.num_points, reference.size());
  EXPECT_GT(accuracy.num_depth_compared, 0u);
  EXPECT_NEAR(accuracy.median_depth_error_m, 0.0, 1e-6);
  EXPECT_NEAR(accuracy.median_edge_distance_m, 0.0, 1e-6);
  EXPECT_DOUBLE_EQ(accuracy.edge_within_fraction, 1.0);
  EXPECT_NEAR(accuracy.median_gradient_angle_deg, 0.0, 1e-3);
  EXPECT_NEAR(accuracy.median_image_gradient_angle_deg, 0.0, 1e-3);
}

TEST(MapAccuracy, MeasuresOffsetsAndGradientAngles) {
  const Map reference = MakeEdgeMap(0.0);
  Map shifted = MakeEdgeMap(0.03);  // 3 cm behind the plane.
  // Points half-way between reference samples lie on the reference edge segment.
  for (Eigen::Vector3f& position : shifted.positions) position.x() += 0.005f;
  for (Eigen::Vector3f& gradient : shifted.gradients) gradient = Eigen::Vector3f(1.0f, 1.0f, 0.0f);
  for (Eigen::Vector3f& gradient : shifted.gradients) gradient.normalize();
  const MapAccuracy accuracy =
      MeasureMapAccuracy(shifted, reference, {MakePlaneView()}, MapAccuracyOptions());
  EXPECT_NEAR(accuracy.median_depth_error_m, 0.03, 1e-5);
  EXPECT_DOUBLE_EQ(accuracy.depth_within_fraction, 0.0);
  EXPECT_NEAR(accuracy.median_edge_distance_m, 0.03, 1e-5);
  EXPECT_NEAR(accuracy.median_gradient_angle_deg, 45.0, 1e-3);
  EXPECT_NEAR(accuracy.median_image_gradient_angle_deg, 45.0, 0.1);
}

TEST(MapAccuracy, RejectsEmptyMapsAndBadOptions) {
  const Map reference = MakeEdgeMap(0.0);
  EXPECT_THROW(MeasureMapAccuracy(Map(), reference, {}, MapAccuracyOptions()),
               InvalidArgumentError);
  MapAccuracyOptions options;
  options.within_m = 0.0;
  EXPECT_THROW(MeasureMapAccuracy(reference, reference, {}, options), InvalidArgumentError);
}

// Depth views come from core/dataset's reader: every stride-th depth map, posed by the ground
// truth, and a malformed depth.txt is an error naming its line (it used to be skipped).
TEST(MapAccuracy, ReadsDepthViewsThroughTheDatasetReader) {
  const std::filesystem::path root = evloc::testing::MakeTempDir("map_accuracy_views");
  const std::filesystem::path out = root / "seq";
  {
    DatasetWriter writer(out, {});
    writer.WriteCamera(Camera::Pinhole(8, 6, 10, 10, 3.5, 2.5));
    std::vector<TimedPose> poses;
    for (int i = 0; i <= 4; ++i) {
      poses.push_back({i * 100'000'000LL,
                       Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * i, 0, 0))});
    }
    writer.WriteGroundTruth(Trajectory(poses));
    for (int i = 0; i < 5; ++i) {
      writer.AddDepth(i * 100'000'000LL, cv::Mat(6, 8, CV_32FC1, cv::Scalar(1.0 + i)));
    }
    writer.AddDepth(900'000'000LL, cv::Mat(6, 8, CV_32FC1, cv::Scalar(9.0)));  // after the truth
    writer.Commit();
  }
  const std::vector<DepthView> every_other = ReadDatasetDepthViews(out, 2);
  ASSERT_EQ(every_other.size(), 3u);  // depth maps 0, 2, 4 (6, at 0.9 s, has no pose)
  EXPECT_EQ(every_other[1].t_ns, 200'000'000);
  EXPECT_NEAR(every_other[1].depth_m.at<float>(3, 3), 3.0f, 1e-6);
  EXPECT_NEAR(every_other[1].cam_from_world.translation.x(), -0.2, 1e-12);
  EXPECT_EQ(ReadDatasetDepthViews(out).size(), 5u);
  EXPECT_THROW(ReadDatasetDepthViews(out, 0), InvalidArgumentError);
  { std::ofstream(out / "depth.txt", std::ios::app) << "1.0\n"; }
  try {
    ReadDatasetDepthViews(out);
    FAIL() << "expected a ParseError";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("depth.txt"), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find("line 7"), std::string::npos) << error.what();
  }
  std::filesystem::remove_all(root);
}

#ifdef EVLOC_MAP_ACCURACY_BINARY
// The command line parses its flags with core/common/cli.h: bad values are usage errors (exit 2).
TEST(MapAccuracyCommandLine, RejectsMissingAndNonFiniteValues) {
  const auto run = [](const std::string& arguments) {
    const std::string command =
        std::string(EVLOC_MAP_ACCURACY_BINARY) + " " + arguments + " >/dev/null 2>&1";
    const int status = std::system(command.c_str());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  };
  EXPECT_EQ(run("--help"), 0);
  EXPECT_EQ(run("--map m --dataset d --within nan"), 2);
  EXPECT_EQ(run("--map m --dataset d --within inf"), 2);
  EXPECT_EQ(run("--map m --dataset d --within 0.01cm"), 2);
  EXPECT_EQ(run("--map m --dataset d --depth-stride 0"), 2);
  EXPECT_EQ(run("--map m --dataset"), 2);
  EXPECT_EQ(run("--map m --dataset d --bogus 1"), 2);
  EXPECT_EQ(run("--map m"), 2);
  // A well-formed command line on a missing map is a run-time error (exit 1), not a usage error.
  EXPECT_EQ(run("--map /nonexistent/map --dataset /nonexistent/seq --within 0.01"), 1);
}
#endif

}  // namespace
}  // namespace evloc::mapper
