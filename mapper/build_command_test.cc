#include "mapper/build_command.h"

#include <gtest/gtest.h>

#include <fstream>
#include <functional>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "core/dataset/testing/middlebury.h"
#include "mapper/map_builder.h"
#include "maps/map.h"
#include "tools/map_accuracy/map_accuracy.h"

namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;

int RunBuild(std::vector<std::string> arguments) {
  arguments.insert(arguments.begin(), "build");
  arguments.push_back("--quiet");
  std::vector<char*> argv;
  for (std::string& argument : arguments) argv.push_back(argument.data());
  return RunBuildCommand(static_cast<int>(argv.size()), argv.data());
}

void WriteImage(const fs::path& path, int width, int height) {
  cv::Mat image(height, width, CV_8U, cv::Scalar(0));
  cv::rectangle(image, cv::Rect(width / 4, height / 4, width / 2, height / 2), cv::Scalar(200),
                cv::FILLED);
  ASSERT_TRUE(cv::imwrite(path.string(), image));
}

TEST(BuildCommand, HelpAndUnknownFlags) {
  EXPECT_EQ(RunBuild({"--help"}), 0);
  EXPECT_EQ(RunBuild({"--images", "x", "--out", "y", "--no-such-flag", "1"}), 2);
  EXPECT_EQ(RunBuild({"--out", "y"}), 2);
  EXPECT_EQ(RunBuild({"--images", "x", "--out", "y", "--matcher", "fancy"}), 2);
}

TEST(BuildCommand, ParsesFlagsIntoOptions) {
  const fs::path directory = evloc::testing::MakeTempDir("build_flags");
  WriteImage(directory / "a.png", 64, 48);
  const BuildCommandLine command_line = ParseBuildCommandLine(
      {"build", "--images", directory.string(), "--out", (directory / "map").string(), "--camera",
       "pinhole:50,51,31.5,23.5", "--matcher", "sequential", "--max-keyframes", "7",
       "--min-keyframes", "5", "--threads", "1", "--voxel-size", "0.002", "--quiet"});
  const MapBuilderOptions& options = command_line.options;
  EXPECT_TRUE(command_line.quiet);
  ASSERT_TRUE(options.camera.has_value());
  EXPECT_EQ(options.camera->width, 64);
  EXPECT_EQ(options.camera->height, 48);
  EXPECT_DOUBLE_EQ(options.camera->fy, 51.0);
  EXPECT_EQ(options.colmap.matcher, MatcherType::kSequential);
  EXPECT_EQ(options.keyframes.max_keyframes, 7);
  EXPECT_EQ(options.keyframes.min_keyframes, 5);
  EXPECT_EQ(options.semidense.num_threads, 1);
  EXPECT_EQ(options.merge.voxel_size, 0.002);
  EXPECT_EQ(options.alignment_limits.max_centre_rms_fraction, 0.1);
  EXPECT_EQ(options.alignment_limits.max_rotation_rms_deg, 5.0);
  EXPECT_FALSE(options.accept_bad_alignment);
  EXPECT_TRUE(options.colmap.deterministic);
  EXPECT_EQ(options.colmap.OrderedStageThreads(), 1);
  const MapBuilderOptions alignment =
      ParseBuildCommandLine({"build", "--images", "x", "--out", "y", "--max-alignment-residual",
                             "0.2", "--max-alignment-rotation", "3", "--accept-bad-alignment",
                             "--fast-nondeterministic", "--threads", "3"})
          .options;
  EXPECT_FALSE(alignment.colmap.deterministic);
  EXPECT_EQ(alignment.colmap.OrderedStageThreads(), 3);
  EXPECT_EQ(alignment.alignment_limits.max_centre_rms_fraction, 0.2);
  EXPECT_EQ(alignment.alignment_limits.max_rotation_rms_deg, 3.0);
  EXPECT_TRUE(alignment.accept_bad_alignment);
  EXPECT_NE(options.command_line.find("--max-keyframes 7"), std::string::npos);
  EXPECT_THROW(ParseCameraFlag("pinhole:1,2,3", 10, 10), InvalidArgumentError);
  EXPECT_THROW(ParseCameraFlag("radtan1,2,3,4", 10, 10), InvalidArgumentError);
  EXPECT_EQ(ParseCameraFlag("radtan:1,2,3,4,0.1,0,0,0,0", 10, 10).distortion.size(), 5u);
  fs::remove_all(directory);
}

TEST(BuildCommand, BadInputsFailWithoutWritingAnything) {
  const fs::path directory = evloc::testing::MakeTempDir("build_errors");
  const fs::path out = directory / "map";
  // Missing and empty image folders.
  EXPECT_EQ(RunBuild({"--images", (directory / "missing").string(), "--out", out.string()}), 1);
  fs::create_directories(directory / "empty");
  EXPECT_EQ(RunBuild({"--images", (directory / "empty").string(), "--out", out.string()}), 1);
  // Unreadable and mixed-size images.
  fs::create_directories(directory / "broken");
  { std::ofstream(directory / "broken" / "a.png") << "not a png"; }
  EXPECT_EQ(RunBuild({"--images", (directory / "broken").string(), "--out", out.string()}), 1);
  fs::create_directories(directory / "mixed");
  WriteImage(directory / "mixed" / "a.png", 64, 48);
  WriteImage(directory / "mixed" / "b.png", 64, 50);
  EXPECT_EQ(RunBuild({"--images", (directory / "mixed").string(), "--out", out.string()}), 1);
  // COLMAP missing.
  fs::create_directories(directory / "good");
  WriteImage(directory / "good" / "a.png", 64, 48);
  WriteImage(directory / "good" / "b.png", 64, 48);
  EXPECT_EQ(RunBuild({"--images", (directory / "good").string(), "--out", out.string(), "--colmap",
                      (directory / "no-colmap").string()}),
            1);
  EXPECT_EQ(RunBuild({"--images", (directory / "good").string(), "--out", out.string(), "--colmap",
                      "evloc-no-such-colmap"}),
            1);
  // Known poses that do not match the images.
  { std::ofstream(directory / "poses.txt") << "a.png 0 0 0 0 0 0 1\nc.png 0 0 0 0 0 0 1\n"; }
  EXPECT_EQ(
      RunBuild({"--images", (directory / "good").string(), "--out", out.string(), "--camera",
                "pinhole:50,50,31.5,23.5", "--known-poses", (directory / "poses.txt").string()}),
      1);
  { std::ofstream(directory / "poses.txt") << "a.png 0 0 0 0 0 0 1\n"; }
  EXPECT_EQ(
      RunBuild({"--images", (directory / "good").string(), "--out", out.string(), "--camera",
                "pinhole:50,50,31.5,23.5", "--known-poses", (directory / "poses.txt").string()}),
      1);
  // Known poses without intrinsics.
  EXPECT_EQ(RunBuild({"--images", (directory / "good").string(), "--out", out.string(),
                      "--known-poses", (directory / "poses.txt").string()}),
            1);
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(directory / "map.colmap-workspace"));
  // A directory that already holds a map is left alone.
  fs::create_directories(out);
  { std::ofstream(out / "map.evmap") << "previous map"; }
  EXPECT_EQ(RunBuild({"--images", (directory / "good").string(), "--out", out.string()}), 1);
  EXPECT_EQ(ReadFileToString(out / "map.evmap"), "previous map");
  fs::remove_all(directory);
}

TEST(BuildCommand, TimeKeyedPosesMayLeaveOutImagesAtTheEnds) {
  const fs::path directory = evloc::testing::MakeTempDir("build_time_keyed");
  fs::create_directories(directory / "images");
  { std::ofstream(directory / "images.txt") << "0.0 a.png\n1.0 b.png\n2.0 c.png\n3.0 d.png\n"; }
  for (const char* name : {"a.png", "b.png", "c.png", "d.png"}) {
    WriteImage(directory / "images" / name, 64, 48);
  }
  const std::vector<InputImage> images =
      ListInputImages(directory / "images", directory / "images.txt");
  // A trajectory from 0.5 s to 3.0 s (ECD slider_depth's starts 22 ms after its first frame).
  { std::ofstream(directory / "tum.txt") << "0.5 0 0 0 0 0 0 1\n3.0 1 0 0 0 0 0 1\n"; }
  EXPECT_TRUE(IsTimeKeyedPoseFile(directory / "tum.txt"));
  const std::map<std::string, Rigid3d> poses = ReadPosesForImages(directory / "tum.txt", images);
  std::vector<std::string> left_out;
  const std::vector<InputImage> kept =
      ImagesWithKnownPoses(images, poses, true, 0.5, "tum.txt", &left_out);
  ASSERT_EQ(kept.size(), 3u);
  EXPECT_EQ(kept[0].name, "b.png");
  EXPECT_EQ(left_out, std::vector<std::string>{"a.png"});
  EXPECT_NEAR(poses.at("b.png").translation.x(), 0.2, 1e-12);
  // Named poses must cover every image; a trajectory must cover at least half of them.
  EXPECT_THROW(ImagesWithKnownPoses(images, poses, false, 0.5, "named.txt", nullptr),
               InvalidArgumentError);
  EXPECT_THROW(ImagesWithKnownPoses(images, poses, true, 0.9, "tum.txt", nullptr),
               InvalidArgumentError);
  { std::ofstream(directory / "named.txt") << "a.png 0 0 0 0 0 0 1\n"; }
  EXPECT_FALSE(IsTimeKeyedPoseFile(directory / "named.txt"));
  fs::remove_all(directory);
}

// The image list and named poses go through core/dataset's strict readers: errors name the file
// and line (or the listed file), nothing is skipped silently.
TEST(BuildCommand, ImageListsAndNamedPosesAreReadStrictly) {
  const fs::path directory = evloc::testing::MakeTempDir("build_strict_lists");
  fs::create_directories(directory / "images");
  WriteImage(directory / "images" / "a.png", 64, 48);
  WriteImage(directory / "images" / "b.png", 64, 48);
  // Paths relative to the image folder or to the list's folder (an ECD images.txt) both resolve.
  { std::ofstream(directory / "images.txt") << "# t path\n0.5 a.png\n1.0 images/b.png\n"; }
  const std::vector<InputImage> images =
      ListInputImages(directory / "images", directory / "images.txt");
  ASSERT_EQ(images.size(), 2u);
  EXPECT_EQ(images[1].name, "b.png");
  EXPECT_EQ(images[1].t_ns, 1'000'000'000);
  const auto error_of = [](const std::function<void()>& run) -> std::string {
    try {
      run();
    } catch (const Error& error) {
      return error.what();
    }
    return "";
  };
  const auto list_error = [&](const std::string& text) {
    { std::ofstream(directory / "bad.txt") << text; }
    return error_of([&] { ListInputImages(directory / "images", directory / "bad.txt"); });
  };
  EXPECT_NE(list_error("0.5 a.png\n0.5 b.png\n").find("line 2"), std::string::npos);
  EXPECT_NE(list_error("0.5,a.png\n").find("line 1"), std::string::npos);
  EXPECT_NE(list_error("0.5 a.png extra\n").find("line 1"), std::string::npos);
  EXPECT_NE(list_error("nan a.png\n").find("line 1"), std::string::npos);
  EXPECT_THROW(ListInputImages(directory / "images", directory / "bad.txt"), ParseError);
  EXPECT_NE(list_error("0.5 missing.png\n").find("missing.png"), std::string::npos);
  EXPECT_THROW(ListInputImages(directory / "images", directory / "bad.txt"), IoError);
  // Named poses: the pose-text rule of core/dataset/pose_text.h, errors naming the line.
  const auto pose_error = [&](const std::string& text) {
    { std::ofstream(directory / "named.txt") << text; }
    return error_of([&] { ReadPosesForImages(directory / "named.txt", images); });
  };
  EXPECT_EQ(pose_error("a.png 0 0 0 0 0 0 1\nb.png 1 0 0 0 0 0.7071068 0.7071068\n"), "");
  EXPECT_NE(pose_error("a.png 0 0 0 0 0 0 1\nb.png 0 0 0 0 0 0 2\n").find("line 2"),
            std::string::npos);
  EXPECT_NE(pose_error("a.png 0 nan 0 0 0 0 1\n").find("line 1"), std::string::npos);
  EXPECT_NE(pose_error("a.png 0 0 0 0 0 0 0\n").find("norm 0"), std::string::npos);
  fs::remove_all(directory);
}

// The short end-to-end run of the default suite: 8 consecutive real templeSparseRing photos (a
// 157.5 degree arc) with their calibrated poses (COLMAP triangulates only), a re-run that reuses
// the COLMAP workspace, and builds in fresh workspaces with 2 and with 1 thread: the same map
// content (content_crc32c) every time (evloc's deterministic matcher, docs/mapper.md
// "Reproducible maps"). The 16-image figures are in map_builder_accuracy_test.cc (long).
TEST(BuildCommand, TempleWithKnownPosesEndToEnd) {
  EVLOC_REQUIRE_SHARED_DATA(parameters, "middlebury/templeSparseRing/templeSR_par.txt");
  const fs::path image_dir = parameters.parent_path();
  std::vector<testing::MiddleburyView> views = testing::ReadMiddleburyParameters(parameters);
  ASSERT_EQ(views.size(), 16u);
  views.resize(8);
  const fs::path directory = evloc::testing::MakeTempDir("build_temple_known");
  testing::WriteNamedPoses(directory / "poses.txt", views);
  {
    std::ofstream list(directory / "images.txt");
    for (size_t i = 0; i < views.size(); ++i) list << i << " " << views[i].name << "\n";
  }
  const Eigen::Matrix3d& k = views[0].calibration;
  const std::string camera = "pinhole:" + std::to_string(k(0, 0)) + "," + std::to_string(k(1, 1)) +
                             "," + std::to_string(k(0, 2)) + "," + std::to_string(k(1, 2));
  const fs::path out = directory / "map";
  const fs::path workspace = directory / "workspace";
  const std::vector<std::string> inputs = {
      "--images",           image_dir.string(),
      "--images-list",      (directory / "images.txt").string(),
      "--camera",           camera,
      "--known-poses",      (directory / "poses.txt").string(),
      "--colmap-workspace", workspace.string()};
  std::vector<std::string> arguments = inputs;
  arguments.insert(arguments.end(), {"--out", out.string()});
  ASSERT_EQ(RunBuild(arguments), 0);
  for (const char* name : {"map.evmap", "map.ply", "preview.png", "report.json",
                           "colmap/images.txt", "colmap/logs/feature_extractor.log"}) {
    EXPECT_TRUE(fs::exists(out / name)) << name;
  }
  const Map map = LoadMap(out / "map.evmap");
  EXPECT_EQ(map.keyframes.size(), 8u);
  // 8 images: 240 points measured with evloc's matcher (394 with its first version; 236 and 240
  // with COLMAP 3.8's matcher, which varies from run to run; docs/mapper.md "Reproducible maps").
  EXPECT_GT(map.size(), 150u);
  // Keyframe poses are the calibrated ones.
  for (const Keyframe& keyframe : map.keyframes) {
    const auto view = std::find_if(views.begin(), views.end(), [&](const auto& candidate) {
      return candidate.name == keyframe.image_name;
    });
    ASSERT_NE(view, views.end());
    EXPECT_LT((keyframe.cam_from_world.translation - view->cam_from_world.translation).norm(),
              1e-9);
    EXPECT_EQ(keyframe.t_ns, static_cast<int64_t>(view - views.begin()) * 1000000000);
  }
  const std::vector<double> distances = KeyframeEdgeDistances(map, image_dir);
  ASSERT_GT(distances.size(), 300u);
  const double median = distances[distances.size() / 2];
  std::cout << "templeSparseRing 8 images, known poses: " << map.size()
            << " points, median edge distance " << median << " px, 90th percentile "
            << distances[distances.size() * 9 / 10] << " px\n";
  EXPECT_LE(median, 1.0);

  // Re-run into another directory: the COLMAP stages are reused.
  const fs::path second = directory / "map2";
  arguments = inputs;
  arguments.insert(arguments.end(), {"--out", second.string()});
  ASSERT_EQ(RunBuild(arguments), 0);
  const std::string report = ReadFileToString(second / "report.json");
  EXPECT_NE(report.find("\"reused\": true"), std::string::npos) << report;
  const uint32_t content = ComputeMapContentChecksum(map);
  EXPECT_EQ(ComputeMapContentChecksum(LoadMap(second / "map.evmap")), content);
  // Fresh workspaces (features and matches computed again) with two and with one thread: the
  // same content.
  for (const char* threads : {"2", "1"}) {
    const fs::path fresh = directory / (std::string("map_fresh") + threads);
    arguments = {"--images",
                 image_dir.string(),
                 "--images-list",
                 (directory / "images.txt").string(),
                 "--camera",
                 camera,
                 "--known-poses",
                 (directory / "poses.txt").string(),
                 "--colmap-workspace",
                 (directory / (std::string("workspace") + threads)).string(),
                 "--out",
                 fresh.string(),
                 "--threads",
                 threads};
    ASSERT_EQ(RunBuild(arguments), 0);
    EXPECT_EQ(ReadFileToString(fresh / "report.json").find("\"reused\": true"), std::string::npos);
    EXPECT_EQ(ComputeMapContentChecksum(LoadMap(fresh / "map.evmap")), content)
        << "fresh workspace, " << threads << " threads";
  }
  std::cout << "templeSparseRing 8 images, known poses: content_crc32c " << std::hex << content
            << std::dec << " (2 threads, reused workspace, fresh with 2 and 1 threads)\n";
  fs::remove_all(directory);
}

// COLMAP estimates the poses of the 16 templeSparseRing photos (calibrated camera): two builds
// in fresh workspaces, with 2 and with 1 thread, give the same map content (about 25 s of CPU
// each).
TEST(BuildCommand, TempleWithEstimatedPosesIsReproducibleInFreshWorkspaces) {
  EVLOC_REQUIRE_SHARED_DATA(parameters, "middlebury/templeSparseRing/templeSR_par.txt");
  const fs::path image_dir = parameters.parent_path();
  const std::vector<testing::MiddleburyView> views = testing::ReadMiddleburyParameters(parameters);
  ASSERT_EQ(views.size(), 16u);
  const fs::path directory = evloc::testing::MakeTempDir("build_temple_estimated");
  const Eigen::Matrix3d& k = views[0].calibration;
  const std::string camera = "pinhole:" + std::to_string(k(0, 0)) + "," + std::to_string(k(1, 1)) +
                             "," + std::to_string(k(0, 2)) + "," + std::to_string(k(1, 2));
  std::vector<uint32_t> contents;
  for (const char* threads : {"2", "1"}) {
    const fs::path out = directory / (std::string("map") + threads);
    ASSERT_EQ(RunBuild({"--images", image_dir.string(), "--camera", camera, "--colmap-workspace",
                        (directory / (std::string("workspace") + threads)).string(), "--out",
                        out.string(), "--threads", threads}),
              0);
    const Map map = LoadMap(out / "map.evmap");
    EXPECT_EQ(map.keyframes.size(), 16u);
    EXPECT_GT(map.size(), 2000u);  // 3423 points measured (3382 with the first matcher)
    contents.push_back(ComputeMapContentChecksum(map));
  }
  EXPECT_EQ(contents[1], contents[0]);
  std::cout << "templeSparseRing 16 images, estimated poses: content_crc32c " << std::hex
            << contents[0] << " (2 threads), " << contents[1] << " (1 thread)" << std::dec << "\n";
  fs::remove_all(directory);
}

}  // namespace
}  // namespace evloc::mapper
