#include "core/camera/undistortion_table.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "core/camera/testing/ecd_davis240.h"
#include "core/common/error.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

Camera MakeDavisRadialTangential() { return testing::EcdDavis240Camera(); }

Camera MakeWideEquidistant() {
  Camera camera;
  camera.model = CameraModel::kEquidistant;
  camera.width = 424;
  camera.height = 400;
  camera.fx = 143.09;
  camera.fy = 143.19;
  camera.cx = 210.6;
  camera.cy = 200.7;
  camera.distortion = {-0.00743, 0.04404, -0.04176, 0.00763};
  return camera;
}

// Checks every entry of the table against Camera::Unproject; returns the number of valid pixels
// Unproject reports.
int ExpectTableMatchesUnproject(const UndistortionTable& table) {
  const Camera& camera = table.camera();
  int valid = 0;
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      Eigen::Vector3d ray;
      const bool unprojected = camera.Unproject(Eigen::Vector2d(x, y), &ray);
      const UndistortionTable::Entry& entry = table.At(x, y);
      EXPECT_EQ(entry.valid, unprojected) << x << " " << y;
      EXPECT_EQ(table.Find(x, y) != nullptr, unprojected) << x << " " << y;
      if (!unprojected) continue;
      ++valid;
      // Float storage: relative error of a float, no more.
      const double scale = std::max(1.0, ray.head<2>().norm());
      EXPECT_LT((entry.normalized.cast<double>() - ray.head<2>()).norm(), 1e-6 * scale)
          << x << " " << y;
      Eigen::Vector2d ideal_pixel;
      if (!table.ideal_camera().Project(ray, &ideal_pixel)) {
        ADD_FAILURE() << "ideal camera cannot project the ray of " << x << " " << y;
        continue;
      }
      EXPECT_LT((entry.ideal_pixel.cast<double>() - ideal_pixel).norm(),
                1e-6 * std::max(1.0, ideal_pixel.norm()))
          << x << " " << y;
    }
  }
  EXPECT_EQ(table.num_valid(), valid);
  return valid;
}

TEST(UndistortionTable, MatchesUnprojectForRadialTangential) {
  const UndistortionTable table(MakeDavisRadialTangential());
  EXPECT_EQ(table.width(), 240);
  EXPECT_EQ(table.height(), 180);
  EXPECT_EQ(ExpectTableMatchesUnproject(table), 240 * 180);
  // Barrel distortion: undistorted corners spread beyond the sensor in the ideal camera.
  EXPECT_LT(table.At(0, 0).ideal_pixel.x(), 0.0f);
  EXPECT_LT(table.At(0, 0).ideal_pixel.y(), 0.0f);
  EXPECT_GT(table.At(239, 179).ideal_pixel.x(), 239.0f);
}

TEST(UndistortionTable, MarksFisheyeCornersBeyondNinetyDegreesInvalid) {
  const UndistortionTable table(MakeWideEquidistant());
  const int valid = ExpectTableMatchesUnproject(table);
  // theta_d(90 degrees) of this lens, in normalised units: exactly the pixels inside this
  // distorted radius have a ray with z = 1.
  const Camera& camera = table.camera();
  const double t2 = M_PI * M_PI / 4;
  const auto& k = camera.distortion;
  const double limit = M_PI / 2 * (1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))));
  int inside = 0;
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      if (std::hypot((x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy) < limit) ++inside;
    }
  }
  EXPECT_EQ(valid, inside);
  EXPECT_LT(valid, 424 * 400);
  EXPECT_EQ(table.Find(0, 0), nullptr);
  ASSERT_NE(table.Find(210, 200), nullptr);
  EXPECT_LT(table.Find(210, 200)->normalized.norm(), 0.01f);
}

TEST(UndistortionTable, PinholeTableIsTheIdentity) {
  const UndistortionTable table(Camera::Pinhole(64, 48, 50, 50, 31.5, 23.5));
  EXPECT_EQ(table.num_valid(), 64 * 48);
  for (int y = 0; y < 48; ++y) {
    for (int x = 0; x < 64; ++x) {
      EXPECT_NEAR(table.At(x, y).ideal_pixel.x(), x, 1e-5);
      EXPECT_NEAR(table.At(x, y).ideal_pixel.y(), y, 1e-5);
      EXPECT_NEAR(table.At(x, y).normalized.x(), (x - 31.5) / 50, 1e-7);
    }
  }
}

TEST(UndistortionTable, BinnedTableMapsEachBlockOfSensorPixelsToOneIdealPixel) {
  // 65 x 49: the last column and row form partial blocks.
  const Camera sensor = Camera::Pinhole(65, 49, 50, 40, 31.5, 23.5);
  const UndistortionTable table(sensor, 2);
  EXPECT_EQ(table.binning(), 2);
  const Camera& ideal = table.ideal_camera();
  EXPECT_EQ(ideal.width, 33);
  EXPECT_EQ(ideal.height, 25);
  EXPECT_DOUBLE_EQ(ideal.fx, 25);
  EXPECT_DOUBLE_EQ(ideal.fy, 20);
  // The principal point (31.5, 23.5) lies between sensor pixels 31 and 32 (blocks 15 and 16).
  EXPECT_DOUBLE_EQ(ideal.cx, 15.5);
  EXPECT_DOUBLE_EQ(ideal.cy, 11.5);
  for (int y = 0; y < 49; ++y) {
    for (int x = 0; x < 65; ++x) {
      const Eigen::Vector2f pixel = table.At(x, y).ideal_pixel;
      // Sensor pixel x lies at (x + 0.5) / 2 - 0.5 in the binned image: its block x / 2 is the
      // nearest ideal pixel.
      EXPECT_NEAR(pixel.x(), (x + 0.5) / 2 - 0.5, 1e-5);
      EXPECT_NEAR(pixel.y(), (y + 0.5) / 2 - 0.5, 1e-5);
      EXPECT_EQ(std::lround(pixel.x()), x / 2);
      EXPECT_EQ(std::lround(pixel.y()), y / 2);
      // The ray is the sensor pixel's, whatever the binning.
      EXPECT_NEAR(table.At(x, y).normalized.x(), (x - 31.5) / 50, 1e-7);
    }
  }
  // A ray projects through the binned camera to where its sensor pixel lies in the binned image.
  Eigen::Vector2d projected;
  ASSERT_TRUE(ideal.Project(Eigen::Vector3d((40 - 31.5) / 50, (10 - 23.5) / 40, 1), &projected));
  EXPECT_NEAR(projected.x(), 40.5 / 2 - 0.5, 1e-9);
  EXPECT_NEAR(projected.y(), 10.5 / 2 - 0.5, 1e-9);
}

TEST(UndistortionTable, RejectsABinningOutsideOneToEight) {
  const Camera sensor = Camera::Pinhole(64, 48, 50, 50, 31.5, 23.5);
  EXPECT_THROW(UndistortionTable(sensor, 0), InvalidArgumentError);
  EXPECT_THROW(UndistortionTable(sensor, 9), InvalidArgumentError);
  EXPECT_NO_THROW(UndistortionTable(sensor, 8));
}

TEST(UndistortionTable, FindRejectsPixelsOutsideTheSensor) {
  const UndistortionTable table(MakeDavisRadialTangential());
  EXPECT_EQ(table.Find(-1, 0), nullptr);
  EXPECT_EQ(table.Find(0, -1), nullptr);
  EXPECT_EQ(table.Find(240, 0), nullptr);
  EXPECT_EQ(table.Find(0, 180), nullptr);
  EXPECT_FALSE(table.Contains(240, 179));
  EXPECT_TRUE(table.Contains(239, 179));
  EXPECT_NE(table.Find(239, 179), nullptr);
}

TEST(UndistortionTable, RejectsInvalidCamera) {
  Camera camera = MakeDavisRadialTangential();
  camera.fy = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(UndistortionTable table(camera), InvalidArgumentError);
}

TEST(UndistortionTable, BuildsForTheRealSliderDepthCamera) {
  EVLOC_REQUIRE_SHARED_DATA(calib, "ecd/slider_depth/calib.txt");
  const UndistortionTable table(ReadEcdCalibration(calib, 240, 180));
  EXPECT_EQ(ExpectTableMatchesUnproject(table), 240 * 180);
}

}  // namespace
}  // namespace evloc
