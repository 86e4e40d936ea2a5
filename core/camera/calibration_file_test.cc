#include "core/camera/calibration_file.h"

#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <fstream>
#include <initializer_list>
#include <string>
#include <vector>

#include "core/camera/colmap_camera.h"
#include "core/camera/testing/ecd_davis240.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

std::filesystem::path TestData(const std::string& name) {
  return testing::SourceDir() / "core" / "camera" / "testdata" / name;
}

// The two real DAVIS240C calibrations of the Event Camera Dataset (plumb_bob, k3 = 0).
Camera SliderDepthCamera() {
  Camera camera =
      Camera::Pinhole(240, 180, 335.419462958, 335.352935612, 129.924663379, 99.1864303447);
  camera.model = CameraModel::kRadialTangential;
  camera.distortion = {-0.138592767408, 0.0933736664192, -0.000335586987532, 0.000173720158228,
                       0.0};
  return camera;
}

Camera SnippetsCamera() { return testing::EcdDavis240Camera(); }

// Writes `text` to a fresh temporary file and returns its path.
std::filesystem::path WriteTemp(const std::string& name, const std::string& text) {
  const std::filesystem::path path = testing::MakeTempDir("calibration_file_test") / name;
  WriteFileAtomically(path, text);
  return path;
}

// Expects `body` to throw E with a message holding every fragment.
template <typename E, typename Body>
void ExpectError(const Body& body, std::initializer_list<const char*> fragments) {
  try {
    body();
    ADD_FAILURE() << "no exception; expected one mentioning " << *fragments.begin();
  } catch (const E& error) {
    const std::string message = error.what();
    for (const char* fragment : fragments) {
      EXPECT_NE(message.find(fragment), std::string::npos)
          << "message '" << message << "' lacks '" << fragment << "'";
    }
  }
}

// Points in front of the camera spread over the image, in camera coordinates.
std::vector<cv::Point3d> ViewPoints() {
  std::vector<cv::Point3d> points;
  for (double x = -0.5; x <= 0.51; x += 0.25) {
    for (double y = -0.4; y <= 0.41; y += 0.2) points.emplace_back(x, y, 1.3 + 0.2 * x);
  }
  return points;
}

// Projects ViewPoints with OpenCV from the file's raw numbers (K, D; fisheye or not) and with the
// evloc camera, shifted by `offset` pixels (COLMAP's 0.5), and expects the same pixels.
void ExpectProjectionMatchesOpenCv(const Camera& camera, const cv::Matx33d& k,
                                   const std::vector<double>& d, bool fisheye, double offset,
                                   double tolerance) {
  const std::vector<cv::Point3d> points = ViewPoints();
  std::vector<cv::Point2d> expected;
  if (fisheye) {
    cv::fisheye::projectPoints(points, expected, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), k, d);
  } else {
    cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), k, d, expected);
  }
  for (size_t i = 0; i < points.size(); ++i) {
    Eigen::Vector2d pixel;
    ASSERT_TRUE(camera.Project(Eigen::Vector3d(points[i].x, points[i].y, points[i].z), &pixel));
    EXPECT_NEAR(pixel.x() + offset, expected[i].x, tolerance) << "point " << i;
    EXPECT_NEAR(pixel.y() + offset, expected[i].y, tolerance) << "point " << i;
  }
}

TEST(CalibrationFormat, IsDetectedFromTheContentOfEveryFormat) {
  const std::vector<std::pair<std::string, CalibrationFormat>> files = {
      {"davis_stereo-camchain-imucam.yaml", CalibrationFormat::kKalibrCamchain},
      {"davis240c_ost.yaml", CalibrationFormat::kRosCameraInfo},
      {"davis240c_fisheye_ost.yaml", CalibrationFormat::kRosCameraInfo},
      {"davis240c_out_camera_data.yml", CalibrationFormat::kOpenCvYaml},
      {"davis240c_out_camera_data.xml", CalibrationFormat::kOpenCvXml},
      {"cameras.txt", CalibrationFormat::kColmapCameras}};
  for (const auto& [name, format] : files) {
    EXPECT_EQ(DetectCalibrationFormat(ReadFileToString(TestData(name)), name), format) << name;
  }
  EXPECT_EQ(DetectCalibrationFormat(CameraToYaml(SnippetsCamera()), "cam.yaml"),
            CalibrationFormat::kEvlocYaml);
  EXPECT_EQ(DetectCalibrationFormat("199.092366542 198.82882047 132.192071378 110.712660011 "
                                    "-0.368436311798 0.150947243557 -0.000296130534385 "
                                    "-0.000759431726241 0.0\r\n",
                                    "calib.txt"),
            CalibrationFormat::kEcdText);
  // An OpenCV YAML without its %YAML:1.0 header is recognised by its !!opencv-matrix nodes.
  EXPECT_EQ(DetectCalibrationFormat("camera_matrix: !!opencv-matrix\n  rows: 3\n", "k.yml"),
            CalibrationFormat::kOpenCvYaml);
}

TEST(CalibrationFormat, TheExtensionDoesNotDecide) {
  // A Kalibr camchain saved as .txt and an ECD calibration saved as .yaml read as what they are.
  const std::filesystem::path kalibr =
      WriteTemp("camchain.txt", ReadFileToString(TestData("davis_stereo-camchain-imucam.yaml")));
  EXPECT_EQ(ReadCalibrationFile(kalibr, 0, 0), SliderDepthCamera());
  const std::filesystem::path ecd = WriteTemp(
      "calib.yaml",
      "199.092366542 198.82882047 132.192071378 110.712660011 -0.368436311798 0.150947243557 "
      "-0.000296130534385 -0.000759431726241 0.0\n");
  EXPECT_EQ(ReadCalibrationFile(ecd, 240, 180), SnippetsCamera());
  const Calibration calibration = ReadCalibration(ecd, 240, 180);
  EXPECT_EQ(calibration.format, CalibrationFormat::kEcdText);
  EXPECT_FALSE(calibration.size_from_file);
}

TEST(CalibrationFormat, UnknownContentNamesTheFileAndTheFormatsRead) {
  ExpectError<ParseError>([] { DetectCalibrationFormat("just: a\nmap: of things\n", "x.yaml"); },
                          {"x.yaml", "not a calibration file evloc reads", "Kalibr camchain",
                           "ROS camera_info", "OpenCV FileStorage", "COLMAP", "ECD"});
  ExpectError<ParseError>([] { DetectCalibrationFormat("", "empty.yaml"); },
                          {"empty.yaml", "empty"});
  ExpectError<ParseError>([] { DetectCalibrationFormat("a: [1, 2\n", "broken.yaml"); },
                          {"broken.yaml", "invalid YAML"});
  ExpectError<IoError>([] { ReadCalibrationFile(TestData("absent.yaml"), 0, 0); }, {"absent.yaml"});
}

TEST(CalibrationSpec, SplitsTheCameraSelectorUnlessTheWholeNameExists) {
  const CalibrationSpec plain = ParseCalibrationSpec("dir/camchain.yaml");
  EXPECT_EQ(plain.path, "dir/camchain.yaml");
  EXPECT_EQ(plain.camera, "");
  const CalibrationSpec selected = ParseCalibrationSpec("dir/a#b/camchain.yaml#cam1");
  EXPECT_EQ(selected.path, "dir/a#b/camchain.yaml");
  EXPECT_EQ(selected.camera, "cam1");
  const std::filesystem::path hashed = WriteTemp("odd#name.yaml", CameraToYaml(SnippetsCamera()));
  EXPECT_EQ(ParseCalibrationSpec(hashed).path, hashed);
  EXPECT_EQ(ReadCalibrationFile(hashed, 0, 0), SnippetsCamera());
  ExpectError<InvalidArgumentError>([] { ParseCalibrationSpec("camchain.yaml#"); },
                                    {"camchain.yaml#", "empty camera selector"});
}

TEST(KalibrCamchain, ReadsEveryCameraAndChainsTheExtrinsics) {
  const std::filesystem::path path = TestData("davis_stereo-camchain-imucam.yaml");
  const Calibration calibration = ReadCalibration(path, 0, 0);
  EXPECT_EQ(calibration.format, CalibrationFormat::kKalibrCamchain);
  EXPECT_TRUE(calibration.size_from_file);
  ASSERT_EQ(calibration.cameras.size(), 3u);
  EXPECT_EQ(calibration.selected.name, "cam0");
  EXPECT_EQ(calibration.selected.camera, SliderDepthCamera());
  EXPECT_EQ(calibration.selected.rostopic, "/davis_left/image_raw");

  Camera fisheye = Camera::Pinhole(240, 180, 188.5, 188.1, 121.3, 92.7);
  fisheye.model = CameraModel::kEquidistant;
  fisheye.distortion = {0.0521, -0.0124, 0.0031, -0.00042};
  EXPECT_EQ(calibration.cameras[1].camera, fisheye);
  EXPECT_EQ(calibration.cameras[2].camera, SnippetsCamera());

  // cam_i_from_cam0 = T_ci_ci-1 * ... * T_c1_c0, with the matrices as written in the file.
  Eigen::Matrix4d t10, t21;
  t10 << 0.9999421216214922, -0.0031946653353647925, -0.010273632293607952, -0.10078853127468004,
      0.00317671200200775, 0.9999933995097952, -0.001763359775955202, 0.00017904115217245,
      0.010279197826948635, 0.0017306213445394182, 0.9999456700450263, 0.0023143406823812, 0, 0, 0,
      1;
  t21 << 0, -1, 0, 0.05, 1, 0, 0, 0, 0, 0, 1, 0.01, 0, 0, 0, 1;
  ASSERT_TRUE(calibration.cameras[0].cam_from_cam0.has_value());
  EXPECT_TRUE(calibration.cameras[0].cam_from_cam0->ToMatrix4().isIdentity(0));
  ASSERT_TRUE(calibration.cameras[1].cam_from_cam0.has_value());
  EXPECT_TRUE(calibration.cameras[1].cam_from_cam0->ToMatrix4().isApprox(t10, 1e-12));
  ASSERT_TRUE(calibration.cameras[2].cam_from_cam0.has_value());
  EXPECT_TRUE(calibration.cameras[2].cam_from_cam0->ToMatrix4().isApprox(t21 * t10, 1e-12));
  // A point seen by cam0 lands where the chained transform puts it in cam2.
  const Eigen::Vector3d p_cam0(0.3, -0.2, 2.0);
  const Eigen::Vector4d expected = t21 * t10 * p_cam0.homogeneous();
  EXPECT_LT((*calibration.cameras[2].cam_from_cam0 * p_cam0 - expected.head<3>()).norm(), 1e-12);

  // The imu fields are ignored with a note per camera.
  int imu_notes = 0;
  for (const std::string& note : calibration.notes) {
    if (note.find("imu field 'T_cam_imu' is ignored") != std::string::npos) ++imu_notes;
  }
  EXPECT_EQ(imu_notes, 2);
}

TEST(KalibrCamchain, TheSelectorPicksACamera) {
  const std::string path = TestData("davis_stereo-camchain-imucam.yaml").string();
  EXPECT_EQ(ReadCalibrationFile(path + "#cam2", 0, 0), SnippetsCamera());
  EXPECT_EQ(ReadCalibrationFile(path + "#2", 0, 0), SnippetsCamera());
  EXPECT_EQ(ReadCalibration(path + "#cam1", 0, 0).selected.name, "cam1");
  ExpectError<InvalidArgumentError>(
      [&] { ReadCalibrationFile(path + "#cam5", 0, 0); },
      {"davis_stereo-camchain-imucam.yaml (Kalibr camchain)", "no camera 'cam5'", "cam0..cam2"});
}

TEST(KalibrCamchain, ProjectsAsOpenCv) {
  const Calibration calibration =
      ReadCalibration(TestData("davis_stereo-camchain-imucam.yaml"), 0, 0);
  // cam0: radtan [k1 k2 r1 r2] is OpenCV's 4-coefficient plumb_bob.
  ExpectProjectionMatchesOpenCv(
      calibration.cameras[0].camera,
      cv::Matx33d(335.419462958, 0, 129.924663379, 0, 335.352935612, 99.1864303447, 0, 0, 1),
      {-0.138592767408, 0.0933736664192, -0.000335586987532, 0.000173720158228}, false, 0.0, 1e-9);
  // cam1: equidistant is cv::fisheye.
  ExpectProjectionMatchesOpenCv(calibration.cameras[1].camera,
                                cv::Matx33d(188.5, 0, 121.3, 0, 188.1, 92.7, 0, 0, 1),
                                {0.0521, -0.0124, 0.0031, -0.00042}, true, 0.0, 1e-8);
}

// A one-camera Kalibr chain with the given camera fields.
std::string KalibrCam0(const std::string& fields) { return "cam0:\n" + fields; }

TEST(KalibrCamchain, RefusesWhatItCannotRepresentWithTheReason) {
  const std::string good_tail =
      "  intrinsics: [200, 200, 120, 90]\n  resolution: [240, 180]\n"
      "  distortion_coeffs: [0.1, 0.01, 0.001, 0.001]\n";
  const auto parse = [](const std::string& text) {
    return ParseCalibration(text, "camchain.yaml", "", 0, 0);
  };
  ExpectError<ParseError>(
      [&] {
        parse(
            KalibrCam0("  camera_model: omni\n  distortion_model: radtan\n"
                       "  intrinsics: [0.8, 200, 200, 120, 90]\n  resolution: [240, 180]\n"
                       "  distortion_coeffs: [0.1, 0.01, 0.001, 0.001]\n"));
      },
      {"camchain.yaml (Kalibr camchain)", "line 2", "cam0", "camera_model", "'omni'",
       "not supported", "omnidirectional", "pinhole-radtan"});
  for (const char* model : {"ds", "eucm"}) {
    ExpectError<ParseError>(
        [&] {
          parse(KalibrCam0(std::string("  camera_model: ") + model +
                           "\n  distortion_model: none\n" + good_tail));
        },
        {"Kalibr camchain", "not supported", model});
  }
  ExpectError<ParseError>(
      [&] { parse(KalibrCam0("  camera_model: pinhole\n  distortion_model: fov\n" + good_tail)); },
      {"distortion_model", "'fov'", "not supported", "FOV"});
  ExpectError<ParseError>(
      [&] {
        parse(
            KalibrCam0("  camera_model: pinhole\n  distortion_model: radtan\n"
                       "  intrinsics: [200, 200, 120, 90]\n  resolution: [240, 180]\n"
                       "  distortion_coeffs: [0.1, 0.01, 0.001]\n"));
      },
      {"distortion_coeffs", "radtan takes 4 coefficients, got 3"});
  ExpectError<ParseError>(
      [&] {
        parse(
            KalibrCam0("  camera_model: pinhole\n  distortion_model: radtan\n"
                       "  intrinsics: [200, 200, 120, 90]\n"
                       "  distortion_coeffs: [0.1, 0.01, 0.001, 0.001]\n"));
      },
      {"cam0", "missing key 'resolution'"});
  const std::string cam = "  camera_model: pinhole\n  distortion_model: radtan\n" + good_tail;
  ExpectError<ParseError>([&] { parse("cam0:\n" + cam + "cam2:\n" + cam); },
                          {"'cam2'", "without gaps"});
  ExpectError<ParseError>(
      [&] {
        parse("cam0:\n" + cam + "cam1:\n" + cam +
              "  T_cn_cnm1:\n  - [1, 0, 0, 0]\n  - [0, 2, 0, 0]\n  - [0, 0, 1, 0]\n"
              "  - [0, 0, 0, 1]\n");
      },
      {"cam1", "T_cn_cnm1", "not a rotation"});
  ExpectError<ParseError>(
      [&] {
        parse("cam0:\n" + cam + "cam1:\n" + cam +
              "  T_cn_cnm1:\n  - [1, 0, 0, 0]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n");
      },
      {"cam1", "T_cn_cnm1", "4x4"});
  // A second camera without T_cn_cnm1 is read, with its rig pose unknown and a note.
  const Calibration no_extrinsic = parse("cam0:\n" + cam + "cam1:\n" + cam);
  ASSERT_EQ(no_extrinsic.cameras.size(), 2u);
  EXPECT_FALSE(no_extrinsic.cameras[1].cam_from_cam0.has_value());
  ASSERT_FALSE(no_extrinsic.notes.empty());
  EXPECT_NE(no_extrinsic.notes.back().find("no T_cn_cnm1"), std::string::npos);
  // A Kalibr "none" distortion is a pinhole camera.
  const Calibration pinhole = parse(
      KalibrCam0("  camera_model: pinhole\n  distortion_model: none\n  distortion_coeffs: []\n"
                 "  intrinsics: [200, 201, 120, 90]\n  resolution: [240, 180]\n"));
  EXPECT_EQ(pinhole.selected.camera, Camera::Pinhole(240, 180, 200, 201, 120, 90));
}

TEST(RosCameraInfo, ReadsCameraCalibrationsOstYaml) {
  const Calibration calibration = ReadCalibration(TestData("davis240c_ost.yaml"), 0, 0);
  EXPECT_EQ(calibration.format, CalibrationFormat::kRosCameraInfo);
  EXPECT_EQ(calibration.selected.camera, SnippetsCamera());
  EXPECT_TRUE(calibration.notes.empty());
  ExpectProjectionMatchesOpenCv(
      calibration.selected.camera,
      cv::Matx33d(199.092366542, 0, 132.192071378, 0, 198.82882047, 110.712660011, 0, 0, 1),
      {-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241, 0}, false, 0.0,
      1e-9);

  const Camera fisheye = ReadCalibrationFile(TestData("davis240c_fisheye_ost.yaml"), 0, 0);
  EXPECT_EQ(fisheye.model, CameraModel::kEquidistant);
  EXPECT_EQ(fisheye.width, 346);
  EXPECT_EQ(fisheye.distortion, (std::vector<double>{-0.0273, 0.0401, -0.0297, 0.0089}));
  ExpectProjectionMatchesOpenCv(fisheye, cv::Matx33d(163.2, 0, 172.9, 0, 163.5, 129.4, 0, 0, 1),
                                {-0.0273, 0.0401, -0.0297, 0.0089}, true, 0.0, 1e-8);
}

// A ROS camera_info text with the given distortion model and coefficients.
std::string RosText(const std::string& model, const std::string& coefficients, int count,
                    const std::string& camera_matrix = "200, 0, 120, 0, 201, 90, 0, 0, 1") {
  return "image_width: 240\nimage_height: 180\ncamera_name: test\ncamera_matrix:\n  rows: 3\n"
         "  cols: 3\n  data: [" +
         camera_matrix + "]\ndistortion_model: " + model +
         "\ndistortion_coefficients:\n  rows: 1\n  cols: " + std::to_string(count) + "\n  data: [" +
         coefficients + "]\n";
}

TEST(RosCameraInfo, AcceptsExactFormsAndRefusesTheRestWithTheReason) {
  const auto parse = [](const std::string& text) {
    return ParseCalibration(text, "ost.yaml", "", 0, 0).selected.camera;
  };
  // rational_polynomial with k4 = k5 = k6 = 0 is plumb_bob exactly.
  const Camera rational =
      parse(RosText("rational_polynomial", "0.1, 0.01, 0.001, 0.002, 0.003, 0, 0, 0", 8));
  EXPECT_EQ(rational.model, CameraModel::kRadialTangential);
  EXPECT_EQ(rational.distortion, (std::vector<double>{0.1, 0.01, 0.001, 0.002, 0.003}));
  ExpectError<ParseError>(
      [&] {
        parse(RosText("rational_polynomial", "0.1, 0.01, 0.001, 0.002, 0.003, 0.2, 0, 0", 8));
      },
      {"ost.yaml (ROS camera_info YAML)", "distortion_coefficients", "rational_polynomial",
       "k4 = 0.2", "not zero", "recalibrate"});
  ExpectError<ParseError>([&] { parse(RosText("fov", "0.9", 1)); },
                          {"ROS camera_info", "distortion_model", "'fov'", "not supported"});
  ExpectError<ParseError>([&] { parse(RosText("plumb_bob", "0.1, 0.01, 0.001", 3)); },
                          {"plumb_bob takes 5 coefficients, got 3"});
  ExpectError<ParseError>([&] { parse(RosText("plumb_bob", "0.1, 0.01, 0.001, 0.002, 0", 4)); },
                          {"distortion_coefficients", "rows x cols = 1 x 4", "5 numbers"});
  ExpectError<ParseError>(
      [&] {
        parse(RosText("plumb_bob", "0, 0, 0, 0, 0", 5, "200, 0.5, 120, 0, 201, 90, 0, 0, 1"));
      },
      {"camera_matrix", "skew", "no skew"});
  ExpectError<ParseError>(
      [&] {
        parse(
            "image_width: 240\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
            "  data: [200, 0, 120, 0, 201, 90, 0, 0, 1]\n");
      },
      {"missing key 'image_height'"});
  // Four plumb_bob coefficients (as some converters write) mean k3 = 0.
  EXPECT_EQ(parse(RosText("plumb_bob", "0.1, 0.01, 0.001, 0.002", 4)).distortion,
            (std::vector<double>{0.1, 0.01, 0.001, 0.002, 0.0}));
}

TEST(OpenCvFileStorage, ReadsTheCalibrationSampleOutputInYamlAndXml) {
  const Calibration yaml = ReadCalibration(TestData("davis240c_out_camera_data.yml"), 0, 0);
  EXPECT_EQ(yaml.format, CalibrationFormat::kOpenCvYaml);
  EXPECT_EQ(yaml.selected.camera, SnippetsCamera());
  const Calibration xml = ReadCalibration(TestData("davis240c_out_camera_data.xml"), 0, 0);
  EXPECT_EQ(xml.format, CalibrationFormat::kOpenCvXml);
  EXPECT_EQ(xml.selected.camera, SliderDepthCamera());
  ExpectProjectionMatchesOpenCv(
      xml.selected.camera,
      cv::Matx33d(335.419462958, 0, 129.924663379, 0, 335.352935612, 99.1864303447, 0, 0, 1),
      {-0.138592767408, 0.0933736664192, -0.000335586987532, 0.000173720158228, 0, 0, 0, 0}, false,
      0.0, 1e-9);
}

// Writes a calibration with cv::FileStorage itself, as OpenCV's calibration sample does.
std::filesystem::path WriteWithOpenCv(const std::string& name, const cv::Mat& k, const cv::Mat& d,
                                      bool with_size, int fisheye) {
  const std::filesystem::path path = testing::MakeTempDir("calibration_opencv") / name;
  cv::FileStorage storage(path.string(), cv::FileStorage::WRITE);
  storage << "calibration_time"
          << "Wed 25 Nov 2026";
  if (with_size) storage << "image_width" << 346 << "image_height" << 260;
  storage << "camera_matrix" << k << "distortion_coefficients" << d;
  if (fisheye >= 0) storage << "fisheye_model" << fisheye;
  storage << "avg_reprojection_error" << 0.2;
  storage.release();
  return path;
}

TEST(OpenCvFileStorage, ReadsWhatCvFileStorageWritesExactly) {
  const cv::Mat k = (cv::Mat_<double>(3, 3) << 271.1234567890123, 0, 171.98765432109876, 0,
                     270.55555555555557, 130.1111111111111, 0, 0, 1);
  const cv::Mat d = (cv::Mat_<double>(1, 5) << -0.31234567890123456, 0.10987654321098765,
                     1.2345678901234567e-4, -9.876543210987654e-4, -0.012345678901234567);
  for (const char* name : {"out_camera_data.yml", "out_camera_data.xml", "camera.json"}) {
    const std::filesystem::path path = WriteWithOpenCv(name, k, d, true, -1);
    const Camera camera = ReadCalibrationFile(path, 0, 0);
    EXPECT_EQ(camera.width, 346) << name;
    EXPECT_EQ(camera.height, 260) << name;
    EXPECT_EQ(camera.fx, k.at<double>(0, 0)) << name;
    EXPECT_EQ(camera.fy, k.at<double>(1, 1)) << name;
    EXPECT_EQ(camera.cx, k.at<double>(0, 2)) << name;
    EXPECT_EQ(camera.cy, k.at<double>(1, 2)) << name;
    EXPECT_EQ(camera.distortion, std::vector<double>(d.begin<double>(), d.end<double>())) << name;
    ExpectProjectionMatchesOpenCv(camera, cv::Matx33d(k), std::vector<double>(d), false, 0.0, 1e-9);
  }
  // fisheye_model: 1 with 4 coefficients is the equidistant model.
  const cv::Mat d4 = (cv::Mat_<double>(4, 1) << 0.012, -0.0031, 0.0009, -0.0002);
  const Camera fisheye = ReadCalibrationFile(WriteWithOpenCv("f.yml", k, d4, true, 1), 0, 0);
  EXPECT_EQ(fisheye.model, CameraModel::kEquidistant);
  ExpectProjectionMatchesOpenCv(fisheye, cv::Matx33d(k), std::vector<double>(d4), true, 0.0, 1e-8);
  ExpectError<ParseError>(
      [&] { ReadCalibrationFile(WriteWithOpenCv("f5.yml", k, d, true, 1), 0, 0); },
      {"OpenCV FileStorage YAML", "fisheye_model", "4 coefficients", "got 5"});
}

TEST(OpenCvFileStorage, ASizeOnlyFromTheCallerAndRefusedCoefficients) {
  const cv::Mat k = (cv::Mat_<double>(3, 3) << 200, 0, 120, 0, 201, 90, 0, 0, 1);
  const cv::Mat d = (cv::Mat_<double>(1, 5) << -0.3, 0.1, 0.001, 0.002, 0.0);
  const std::filesystem::path no_size = WriteWithOpenCv("nosize.xml", k, d, false, -1);
  const Calibration sized = ReadCalibration(no_size, 240, 180);
  EXPECT_FALSE(sized.size_from_file);
  EXPECT_EQ(sized.selected.camera.width, 240);
  ExpectError<ParseError>([&] { ReadCalibrationFile(no_size, 0, 0); },
                          {"nosize.xml (OpenCV FileStorage XML)", "no image size", "image_width"});
  cv::Mat d14 = cv::Mat::zeros(14, 1, CV_64F);
  d14.at<double>(0) = -0.3;
  d14.at<double>(12) = 0.01;  // tauX: a tilted sensor
  ExpectError<ParseError>(
      [&] { ReadCalibrationFile(WriteWithOpenCv("tilt.yml", k, d14, true, -1), 0, 0); },
      {"OpenCV FileStorage YAML", "distortion_coefficients", "tauX", "not zero"});
  ExpectError<ParseError>(
      [&] {
        ParseCalibration("%YAML:1.0\nimage_width: 240\nimage_height: 180\n", "x.yml", "", 0, 0);
      },
      {"x.yml (OpenCV FileStorage YAML)", "no camera matrix"});
  ExpectError<ParseError>([&] { ParseCalibration("<opencv_storage><a>", "x.xml", "", 0, 0); },
                          {"x.xml (OpenCV FileStorage XML)", "cv::FileStorage cannot parse"});
  // Found by evloc_calibration_fuzzer: a top-level sequence made cv::FileNode::operator[] throw a
  // cv::Exception past the reader.
  ExpectError<ParseError>([&] { ParseCalibration("%YAML:1.0\n- -\n", "s.yml", "", 0, 0); },
                          {"s.yml (OpenCV FileStorage YAML)", "expected a map"});
  // Found by the fuzzer: OpenCV 4.6's XML parser crashed (null pointer) on NUL bytes in the
  // header; calibration files are text, so a NUL byte is refused before any parser runs.
  const std::string with_nul =
      std::string("<?xml ver=") + std::string(9, '\0') + "0\"?>\n<opencv_storage>\n";
  ExpectError<ParseError>([&] { ParseCalibration(with_nul, "n.xml", "", 0, 0); },
                          {"n.xml", "byte 10", "NUL byte"});
  ExpectError<ParseError>([&] { ParseOpenCvCalibration(with_nul, "n.xml", 0, 0, nullptr); },
                          {"n.xml", "NUL byte"});
  // Found by the fuzzer: a garbled cols made cv::FileNode >> cv::Mat allocate gigabytes.
  ExpectError<ParseError>(
      [&] {
        ParseCalibration(
            "%YAML:1.0\nimage_width: 240\nimage_height: 180\ncamera_matrix: !!opencv-matrix\n"
            "   rows: 3\n   cols: ,1\n   dt: d\n   data: [200, 0, 120, 0, 201, 90, 0, 0, 1]\n",
            "g.yml", "", 0, 0);
      },
      {"g.yml (OpenCV FileStorage YAML)", "camera_matrix", "rows, cols, dt and data"});
  ExpectError<ParseError>(
      [&] {
        ParseCalibration(
            "%YAML:1.0\nimage_width: 240\nimage_height: 180\ncamera_matrix: !!opencv-matrix\n"
            "   rows: 300000\n   cols: 300000\n   dt: d\n   data: [200, 0]\n",
            "h.yml", "", 0, 0);
      },
      {"h.yml (OpenCV FileStorage YAML)", "does not match the 2 numbers"});
}

TEST(ColmapCameras, PicksACameraByIdAndRefusesUnrepresentableModels) {
  const std::string path = TestData("cameras.txt").string();
  ExpectError<InvalidArgumentError>(
      [&] { ReadCalibrationFile(path, 0, 0); },
      {"cameras.txt (COLMAP cameras.txt)", "3 cameras", "CAMERA_ID 1, 2, 3", "FILE#ID"});
  const Calibration calibration = ReadCalibration(path + "#2", 0, 0);
  EXPECT_EQ(calibration.format, CalibrationFormat::kColmapCameras);
  EXPECT_EQ(calibration.selected.name, "2");
  const Camera camera = calibration.selected.camera;
  const Camera expected = SnippetsCamera();
  EXPECT_EQ(camera.model, expected.model);
  EXPECT_EQ(camera.fx, expected.fx);
  EXPECT_NEAR(camera.cx, expected.cx, 1e-12);  // COLMAP's 132.692071378 minus half a pixel
  EXPECT_NEAR(camera.cy, expected.cy, 1e-12);
  EXPECT_EQ(camera.distortion, expected.distortion);
  // In COLMAP's pixel convention the projection is OpenCV's with the file's own numbers.
  ExpectProjectionMatchesOpenCv(
      camera, cv::Matx33d(199.092366542, 0, 132.692071378, 0, 198.82882047, 111.212660011, 0, 0, 1),
      {-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241}, false,
      kColmapPixelOffset, 1e-9);
  // The unrepresentable camera 3 is skipped with a note; selecting it is an error with the reason.
  EXPECT_EQ(calibration.cameras.size(), 2u);
  ExpectError<ParseError>(
      [&] { ReadCalibrationFile(path + "#3", 0, 0); },
      {"COLMAP cameras.txt", "CAMERA_ID 3", "RADIAL_FISHEYE", "not supported", "OPENCV_FISHEYE"});
  ExpectError<InvalidArgumentError>([&] { ReadCalibrationFile(path + "#7", 0, 0); },
                                    {"no CAMERA_ID '7'", "1, 2, 3"});
  EXPECT_EQ(ReadCalibrationFile(path + "#1", 0, 0),
            Camera::Pinhole(640, 480, 512.5, 511.25, 320, 240));
}

TEST(CalibrationFile, OneCameraFormatsRefuseASelectorAndSizelessFilesNeedASize) {
  ExpectError<InvalidArgumentError>(
      [] { ReadCalibrationFile(TestData("davis240c_ost.yaml").string() + "#cam1", 0, 0); },
      {"davis240c_ost.yaml (ROS camera_info YAML)", "one camera", "'#cam1'"});
  const std::string ecd =
      "199.092366542 198.82882047 132.192071378 110.712660011 -0.368436311798 0.150947243557 "
      "-0.000296130534385 -0.000759431726241 0.0\n";
  ExpectError<InvalidArgumentError>([&] { ParseCalibration(ecd, "calib.txt", "", 0, 0); },
                                    {"calib.txt (ECD calib.txt)", "no image size"});
  ExpectError<ParseError>([&] { ParseCalibration("1 2 3 4 5 6 7 8\n", "calib.txt", "", 240, 180); },
                          {"calib.txt (ECD calib.txt)", "line 1", "expected 9 fields"});
  ExpectError<ParseError>(
      [&] { ParseCalibration("model: radtan\nwidth: 240\n", "cam.yaml", "", 0, 0); },
      {"cam.yaml (evloc camera YAML)", "missing key"});
}

}  // namespace
}  // namespace evloc
