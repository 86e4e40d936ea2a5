
#include "mapper/colmap_model.h"

#include <gtest/gtest.h>

#include <fstream>

#include "core/camera/calibration_file.h"
#include "core/camera/testing/ecd_davis240.h"
#include "core/common/error.h"
#include "core/common/test_data.h"
#include "mapper/colmap_runner.h"

namespace evloc::mapper {
namespace {

ColmapModel MakeModel() {
  ColmapModel model;
  model.cameras[1] = ColmapCamera{1, "PINHOLE", 640, 480, {500.0, 510.0, 320.5, 240.5}};
  ColmapImage first;
  first.image_id = 3;
  first.camera_id = 1;
  first.name = "a.png";
  first.cam_from_world =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())),
              Eigen::Vector3d(0.1, -0.2, 0.3));
  first.keypoints = {{10.25, 20.5}, {100.0, 200.0}};
  first.point3d_ids = {7, kNoPoint3D};
  ColmapImage second;
  second.image_id = 5;
  second.camera_id = 1;
  second.name = "b.png";
  second.keypoints = {{11.0, 21.0}};
  second.point3d_ids = {7};
  model.images[3] = first;
  model.images[5] = second;
  ColmapPoint3D point;
  point.point3d_id = 7;
  point.position = Eigen::Vector3d(1.0, 2.0, 3.5);
  point.color = Eigen::Vector3i(10, 20, 30);
  point.error = 0.75;
  point.track = {{3, 0}, {5, 0}};
  model.points[7] = point;
  return model;
}

TEST(ColmapModel, TextRoundTripKeepsEverything) {
  const std::filesystem::path directory = testing::MakeTempDir("colmap_model");
  const ColmapModel model = MakeModel();
  WriteColmapTextModel(directory, model);
  const ColmapModel read = ReadColmapTextModel(directory);
  ASSERT_EQ(read.cameras.size(), 1u);
  EXPECT_EQ(read.cameras.at(1).params, model.cameras.at(1).params);
  ASSERT_EQ(read.images.size(), 2u);
  const ColmapImage& first = read.images.at(3);
  EXPECT_EQ(first.name, "a.png");
  EXPECT_TRUE(first.cam_from_world.rotation.isApprox(model.images.at(3).cam_from_world.rotation));
  EXPECT_TRUE(
      first.cam_from_world.translation.isApprox(model.images.at(3).cam_from_world.translation));
  ASSERT_EQ(first.keypoints.size(), 2u);
  EXPECT_EQ(first.keypoints[0], Eigen::Vector2d(10.25, 20.5));
  EXPECT_EQ(first.point3d_ids[1], kNoPoint3D);
  ASSERT_EQ(read.points.size(), 1u);
  EXPECT_EQ(read.points.at(7).track.size(), 2u);
  EXPECT_DOUBLE_EQ(read.MeanReprojectionError(), 0.75);
  EXPECT_EQ(read.FindImageId("b.png"), 5u);
  EXPECT_EQ(read.FindImageId("c.png"), 0u);
  std::filesystem::remove_all(directory);
}

TEST(ColmapModel, KeypointsShiftByHalfAPixelOnDisk) {
  const std::filesystem::path directory = testing::MakeTempDir("colmap_model_shift");
  WriteColmapTextModel(directory, MakeModel());
  std::ifstream images(directory / "images.txt");
  std::string text((std::istreambuf_iterator<char>(images)), std::istreambuf_iterator<char>());
  // evloc (10.25, 20.5) is COLMAP (10.75, 21).
  EXPECT_NE(text.find("10.75 21 7"), std::string::npos) << text;
  std::filesystem::remove_all(directory);
}

TEST(ColmapModel, MalformedImageLineNamesFileAndLine) {
  const std::filesystem::path directory = testing::MakeTempDir("colmap_model_bad");
  WriteColmapTextModel(directory, MakeModel());
  {
    std::ofstream images(directory / "images.txt");
    images << "# header\n1 1 0 0 0 0 0 0 1\n\n";
  }
  try {
    ReadColmapTextModel(directory);
    FAIL() << "expected ParseError";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("images.txt: line 2"), std::string::npos)
        << error.what();
  }
  std::filesystem::remove_all(directory);
}

TEST(ColmapModel, TrackToUnknownImageIsRejected) {
  const std::filesystem::path directory = testing::MakeTempDir("colmap_model_track");
  ColmapModel model = MakeModel();
  model.points.at(7).track.push_back({99, 0});
  WriteColmapTextModel(directory, model);
  EXPECT_THROW(ReadColmapTextModel(directory), ParseError);
  std::filesystem::remove_all(directory);
}

TEST(ColmapModel, TheCamerasTxtTheMapperWritesIsACalibrationFile) {
  // evloc writes cameras.txt (WriteColmapTextModel, for COLMAP's point_triangulator); --calib
  // reads it back to the same cameras, the radtan one through FULL_OPENCV.
  Camera radtan = testing::EcdDavis240Camera();
  radtan.distortion[4] = 0.0125;
  Camera fisheye = Camera::Pinhole(346, 260, 163.2, 163.5, 172.9, 129.4);
  fisheye.model = CameraModel::kEquidistant;
  fisheye.distortion = {-0.0273, 0.0401, -0.0297, 0.0089};
  ColmapModel model;
  model.cameras[1] = ColmapCameraFromCamera(radtan, 1);
  model.cameras[2] = ColmapCameraFromCamera(fisheye, 2);
  const std::filesystem::path directory = testing::MakeTempDir("colmap_calibration");
  WriteColmapTextModel(directory, model);
  const std::string cameras_txt = (directory / "cameras.txt").string();
  const Camera read_radtan = ReadCalibrationFile(cameras_txt + "#1", 0, 0);
  const Camera read_fisheye = ReadCalibrationFile(cameras_txt + "#2", 0, 0);
  EXPECT_EQ(model.cameras.at(1).model_name, "FULL_OPENCV");
  // The half-pixel shift there and back may change the last bit of the principal point.
  for (const auto& [read, written] : {std::pair{read_radtan, radtan}, {read_fisheye, fisheye}}) {
    EXPECT_EQ(read.model, written.model);
    EXPECT_EQ(read.width, written.width);
    EXPECT_EQ(read.fx, written.fx);
    EXPECT_EQ(read.fy, written.fy);
    EXPECT_NEAR(read.cx, written.cx, 1e-12);
    EXPECT_NEAR(read.cy, written.cy, 1e-12);
    EXPECT_EQ(read.distortion, written.distortion);
  }
  std::filesystem::remove_all(directory);
}

TEST(ColmapRunner, MissingExecutableIsAnIoError) {
  EXPECT_THROW(FindExecutable("evloc-no-such-colmap-binary"), IoError);
  EXPECT_THROW(FindExecutable("/nonexistent/colmap"), IoError);
  EXPECT_NO_THROW(FindExecutable("sh"));
}

// A command that has done its work but does not exit (COLMAP 3.8's feature_extractor after its
// last image, sometimes) is stopped once the grace has passed, with a line in its log; a command
// that exits by itself is not disturbed by the watch.
TEST(ColmapRunner, AWatchedCommandThatHangsAfterItsWorkIsStopped) {
  const std::filesystem::path directory = testing::MakeTempDir("colmap_runner_watch");
  const std::filesystem::path log = directory / "run.log";
  CommandWatch watch;
  watch.done = [&log] {
    std::ifstream stream(log);
    const std::string text((std::istreambuf_iterator<char>(stream)),
                           std::istreambuf_iterator<char>());
    return text.find("Processed file [2/2]") != std::string::npos;
  };
  watch.exit_grace = std::chrono::milliseconds(300);
  const auto start = std::chrono::steady_clock::now();
  EXPECT_THROW(RunLoggedCommand({"/bin/sh", "-c", "echo 'Processed file [2/2]'; exec sleep 60"},
                                log, &watch),
               CommandHungError);
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(20));
  std::ifstream stream(log);
  const std::string text((std::istreambuf_iterator<char>(stream)),
                         std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("did not exit within 300 ms; it was stopped"), std::string::npos) << text;
  // Done and exiting at once, or never done: ordinary runs.
  EXPECT_NO_THROW(RunLoggedCommand({"/bin/sh", "-c", "echo 'Processed file [2/2]'"}, log, &watch));
  CommandWatch never;
  never.done = [] { return false; };
  never.exit_grace = std::chrono::milliseconds(1);
  EXPECT_NO_THROW(RunLoggedCommand({"/bin/sh", "-c", "sleep 1.5"}, log, &never));
  EXPECT_THROW(RunLoggedCommand({"/bin/sh", "-c", "exit 3"}, log, &never), IoError);
  std::filesystem::remove_all(directory);
}

TEST(ColmapRunner, FailedCommandQuotesItsLog) {
  const std::filesystem::path directory = testing::MakeTempDir("colmap_runner_log");
  const std::filesystem::path log = directory / "run.log";
  RunLoggedCommand({"/bin/sh", "-c", "echo first run"}, log);
  try {
    RunLoggedCommand({"/bin/sh", "-c", "echo something broke; exit 3"}, log);
    FAIL() << "expected IoError";
  } catch (const IoError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("exited with status 3"), std::string::npos) << message;
    EXPECT_NE(message.find("something broke"), std::string::npos) << message;
  }
  // The log keeps both runs.
  std::ifstream stream(log);
  std::string text((std::istreambuf_iterator<char>(stream)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("first run"), std::string::npos);
  std::filesystem::remove_all(directory);
}

// A stand-in COLMAP executable that appends its arguments to `<directory>/arguments.txt`.
std::filesystem::path WriteRecordingColmap(const std::filesystem::path& directory) {
  const std::filesystem::path fake = directory / "fake-colmap";
  {
    std::ofstream script(fake);
    script << "#!/bin/sh\necho \"$@\" >> " << (directory / "arguments.txt").string() << "\n";
  }
  std::filesystem::permissions(fake, std::filesystem::perms::owner_all);
  return fake;
}

TEST(ColmapRunner, FixedIntrinsicsAreNotRefinedAndTheModelIsFiltered) {
  const std::filesystem::path directory = testing::MakeTempDir("colmap_runner_arguments");
  ColmapOptions options;
  options.executable = WriteRecordingColmap(directory).string();
  options.camera = Camera::Pinhole(640, 480, 500, 500, 320, 240);
  const ColmapRunner fixed(options, directory / "workspace", directory);
  fixed.Map(directory / "sparse");
  fixed.RefineModel(directory / "sparse" / "0", directory / "refined");
  options.camera.reset();
  const ColmapRunner estimated(options, directory / "workspace", directory);
  estimated.Map(directory / "sparse");
  std::ifstream stream(directory / "arguments.txt");
  std::vector<std::string> lines;
  for (std::string line; std::getline(stream, line);) lines.push_back(line);
  ASSERT_EQ(lines.size(), 6u);
  EXPECT_NE(lines[0].find("mapper "), std::string::npos) << lines[0];
  EXPECT_NE(lines[0].find("--Mapper.ba_refine_focal_length 0"), std::string::npos) << lines[0];
  EXPECT_EQ(lines[0].find("filter_max_reproj_error"), std::string::npos) << lines[0];
  // Two passes (0.5 px, then 0.3 px), each filtering the previous pass's adjusted model; the last
  // one adjusts into the output model.
  const std::string refined = (directory / "refined").string();
  EXPECT_NE(lines[1].find("point_filtering --input_path " + (directory / "sparse" / "0").string() +
                          " --output_path " + refined + ".filtered1 --max_reproj_error 0.5"),
            std::string::npos)
      << lines[1];
  EXPECT_NE(lines[2].find("bundle_adjuster --input_path " + refined + ".filtered1 --output_path " +
                          refined + ".adjusted1"),
            std::string::npos)
      << lines[2];
  EXPECT_NE(lines[2].find("--BundleAdjustment.refine_focal_length 0"), std::string::npos);
  EXPECT_NE(lines[3].find("point_filtering --input_path " + refined + ".adjusted1 --output_path " +
                          refined + ".filtered2 --max_reproj_error 0.3"),
            std::string::npos)
      << lines[3];
  EXPECT_NE(lines[4].find("--input_path " + refined + ".filtered2 --output_path " + refined + " "),
            std::string::npos)
      << lines[4];
  EXPECT_EQ(lines[5].find("ba_refine_focal_length"), std::string::npos) << lines[5];
  std::filesystem::remove_all(directory);

  ColmapOptions bad;
  bad.fixed_camera_refinement_px = {0.0};
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
  bad.fixed_camera_refinement_px = {0.3, 0.5};
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
}

TEST(ColmapRunner, MatcherNamesParse) {
  EXPECT_EQ(ParseMatcherType("auto"), MatcherType::kAuto);
  EXPECT_EQ(ParseMatcherType("sequential"), MatcherType::kSequential);
  EXPECT_EQ(ParseMatcherType("exhaustive"), MatcherType::kExhaustive);
  EXPECT_THROW(ParseMatcherType("vocab_tree"), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::mapper
