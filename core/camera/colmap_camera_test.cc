#include "core/camera/colmap_camera.h"

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc {
namespace {

TEST(ColmapCamera, PixelConventionsDifferByHalfAPixel) {
  const Camera pinhole = CameraFromColmap({1, "PINHOLE", 640, 480, {500, 510, 320.5, 240.5}});
  EXPECT_EQ(pinhole.model, CameraModel::kPinhole);
  EXPECT_DOUBLE_EQ(pinhole.cx, 320.0);
  EXPECT_DOUBLE_EQ(pinhole.cy, 240.0);
  const ColmapCamera back = ColmapCameraFromCamera(pinhole, 4);
  EXPECT_EQ(back.model_name, "PINHOLE");
  EXPECT_EQ(back.camera_id, 4u);
  EXPECT_EQ(back.params, (std::vector<double>{500, 510, 320.5, 240.5}));
}

TEST(ColmapCamera, ModelsMapBothWays) {
  const Camera simple_radial = CameraFromColmap({1, "SIMPLE_RADIAL", 100, 80, {90, 50, 40, 0.1}});
  EXPECT_EQ(simple_radial.model, CameraModel::kRadialTangential);
  EXPECT_EQ(simple_radial.fx, simple_radial.fy);
  EXPECT_EQ(simple_radial.distortion, (std::vector<double>{0.1, 0, 0, 0, 0}));
  const Camera radial = CameraFromColmap({1, "RADIAL", 100, 80, {90, 50, 40, 0.1, -0.02}});
  EXPECT_EQ(radial.distortion, (std::vector<double>{0.1, -0.02, 0, 0, 0}));
  EXPECT_EQ(CameraFromColmap({1, "SIMPLE_PINHOLE", 100, 80, {90, 50.5, 40.5}}),
            Camera::Pinhole(100, 80, 90, 90, 50, 40));

  Camera radtan = Camera::Pinhole(100, 80, 90, 91, 49.5, 39.5);
  radtan.model = CameraModel::kRadialTangential;
  radtan.distortion = {0.1, -0.02, 0.001, 0.002, 0.0};
  EXPECT_EQ(ColmapCameraFromCamera(radtan, 1).model_name, "OPENCV");
  EXPECT_EQ(CameraFromColmap(ColmapCameraFromCamera(radtan, 1)), radtan);
  radtan.distortion[4] = 0.003;
  EXPECT_EQ(ColmapCameraFromCamera(radtan, 1).model_name, "FULL_OPENCV");
  EXPECT_EQ(CameraFromColmap(ColmapCameraFromCamera(radtan, 1)), radtan);

  Camera fisheye = Camera::Pinhole(100, 80, 90, 91, 49.5, 39.5);
  fisheye.model = CameraModel::kEquidistant;
  fisheye.distortion = {0.01, 0.02, 0.03, 0.04};
  EXPECT_EQ(ColmapCameraFromCamera(fisheye, 1).model_name, "OPENCV_FISHEYE");
  EXPECT_EQ(CameraFromColmap(ColmapCameraFromCamera(fisheye, 1)), fisheye);

  EXPECT_THROW(CameraFromColmap({1, "FOV", 100, 80, {90, 90, 50, 40, 0.1}}), InvalidArgumentError);
  EXPECT_THROW(CameraFromColmap({1, "PINHOLE", 100, 80, {90, 50, 40}}), InvalidArgumentError);
  EXPECT_THROW(
      CameraFromColmap({1, "FULL_OPENCV", 100, 80, {90, 90, 50, 40, 0.1, 0, 0, 0, 0, 0.2, 0, 0}}),
      InvalidArgumentError);
  EXPECT_THROW(CameraFromColmap({1, "PINHOLE", 0, 80, {90, 90, 50, 40}}), InvalidArgumentError);
}

TEST(ColmapCamera, ParsesCamerasTxtLines) {
  const auto cameras = ParseColmapCameras(
      "# Camera list with one line of data per camera:\r\n"
      "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\r\n"
      "\r\n"
      "3 PINHOLE 640 480 500 510 320.5 240.5\r\n"
      "1 SIMPLE_RADIAL 100 80 90 50 40 0.1\n",
      "cameras.txt");
  ASSERT_EQ(cameras.size(), 2u);
  EXPECT_EQ(cameras.at(3).model_name, "PINHOLE");
  EXPECT_EQ(cameras.at(3).params, (std::vector<double>{500, 510, 320.5, 240.5}));
  EXPECT_EQ(cameras.at(1).width, 100);
  // Errors name the file and the line.
  const auto expect_error = [](const std::string& text, const std::string& fragment) {
    try {
      ParseColmapCameras(text, "cameras.txt");
      ADD_FAILURE() << "no error for " << text;
    } catch (const ParseError& error) {
      EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos) << error.what();
    }
  };
  expect_error("1 PINHOLE 640\n", "cameras.txt: line 1: expected CAMERA_ID MODEL");
  expect_error("# c\nx PINHOLE 640 480 1 1 1 1\n", "line 2: CAMERA_ID 'x'");
  expect_error("1 PINHOLE 640 480 1 nan 1 1\n", "PARAMS 'nan' is not a finite number");
  expect_error("1 PINHOLE 640 480 1 1 1 1\n1 PINHOLE 640 480 1 1 1 1\n",
               "line 2: duplicate CAMERA_ID 1");
}

}  // namespace
}  // namespace evloc
