#include "core/camera/camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/camera/testing/ecd_davis240.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

Camera MakeRadialTangential() {
  // DAVIS240C of the ECD snippets, with a non-zero k3 so that every coefficient is exercised.
  Camera camera = testing::EcdDavis240Camera();
  camera.distortion[4] = -0.01;
  return camera;
}

Camera MakeEquidistant() {
  // A wide fisheye (about 230 degrees across the diagonal): the corners lie beyond 90 degrees.
  Camera camera;
  camera.model = CameraModel::kEquidistant;
  camera.width = 848;
  camera.height = 800;
  camera.fx = 286.1807;
  camera.fy = 286.3758;
  camera.cx = 421.2319;
  camera.cy = 401.4395;
  camera.distortion = {-0.00743, 0.04404, -0.04176, 0.00763};
  return camera;
}

std::vector<Camera> AllCameras() {
  return {Camera::Pinhole(640, 480, 520.0, 515.0, 319.5, 239.5), MakeRadialTangential(),
          MakeEquidistant()};
}

// Distorted normalised radius of the equidistant camera at angle theta from the axis.
double EquidistantDistortedRadius(const Camera& camera, double theta) {
  const auto& k = camera.distortion;
  const double t2 = theta * theta;
  return theta * (1 + k[0] * t2 + k[1] * t2 * t2 + k[2] * t2 * t2 * t2 + k[3] * t2 * t2 * t2 * t2);
}

// Number of pixels (x, y), both multiples of `stride`, whose ray is less than 90 degrees off the
// optical axis of an equidistant camera with monotonic theta_d.
int CountPixelsWithinNinetyDegrees(const Camera& camera, int stride) {
  const double limit = EquidistantDistortedRadius(camera, M_PI / 2);
  int count = 0;
  for (int y = 0; y < camera.height; y += stride) {
    for (int x = 0; x < camera.width; x += stride) {
      const double radius = std::hypot((x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy);
      if (radius < limit) ++count;
    }
  }
  return count;
}

TEST(CameraModel, NamesAndAliases) {
  EXPECT_EQ(CameraModelName(CameraModel::kPinhole), "pinhole");
  EXPECT_EQ(CameraModelName(CameraModel::kRadialTangential), "radtan");
  EXPECT_EQ(CameraModelName(CameraModel::kEquidistant), "equidistant");
  for (CameraModel model :
       {CameraModel::kPinhole, CameraModel::kRadialTangential, CameraModel::kEquidistant}) {
    EXPECT_EQ(ParseCameraModel(CameraModelName(model)), model);
  }
  EXPECT_EQ(ParseCameraModel("plumb_bob"), CameraModel::kRadialTangential);
  EXPECT_EQ(ParseCameraModel("RadTan"), CameraModel::kRadialTangential);
  EXPECT_EQ(ParseCameraModel("fisheye"), CameraModel::kEquidistant);
  EXPECT_EQ(ParseCameraModel("equi"), CameraModel::kEquidistant);
  EXPECT_THROW(ParseCameraModel("omni"), InvalidArgumentError);
  EXPECT_THROW(ParseCameraModel(""), InvalidArgumentError);
  EXPECT_EQ(NumDistortionCoefficients(CameraModel::kPinhole), 0);
  EXPECT_EQ(NumDistortionCoefficients(CameraModel::kRadialTangential), 5);
  EXPECT_EQ(NumDistortionCoefficients(CameraModel::kEquidistant), 4);
}

TEST(Camera, CheckAcceptsValidCameras) {
  for (const Camera& camera : AllCameras()) EXPECT_NO_THROW(camera.Check());
}

TEST(Camera, CheckRejectsInvalidFields) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const Camera valid = MakeRadialTangential();
  std::vector<std::pair<std::string, Camera>> invalid;
  const auto add = [&](const std::string& what, auto modify) {
    Camera camera = valid;
    modify(camera);
    invalid.emplace_back(what, camera);
  };
  add("NaN fx", [&](Camera& c) { c.fx = nan; });
  add("infinite fy", [&](Camera& c) { c.fy = inf; });
  add("NaN cx", [&](Camera& c) { c.cx = nan; });
  add("infinite cy", [&](Camera& c) { c.cy = -inf; });
  add("zero fx", [](Camera& c) { c.fx = 0; });
  add("negative fy", [](Camera& c) { c.fy = -200; });
  add("zero width", [](Camera& c) { c.width = 0; });
  add("negative height", [](Camera& c) { c.height = -1; });
  add("huge width", [](Camera& c) { c.width = 1 << 20; });
  add("NaN distortion", [&](Camera& c) { c.distortion[2] = nan; });
  add("4 radtan coefficients", [](Camera& c) { c.distortion.pop_back(); });
  add("equidistant with 5", [](Camera& c) { c.model = CameraModel::kEquidistant; });
  add("pinhole with 5", [](Camera& c) { c.model = CameraModel::kPinhole; });
  for (const auto& [what, camera] : invalid) {
    EXPECT_THROW(camera.Check(), InvalidArgumentError) << what;
  }
  Camera equidistant = MakeEquidistant();
  equidistant.distortion.push_back(0.0);
  EXPECT_THROW(equidistant.Check(), InvalidArgumentError);
}

TEST(Camera, CentrePixelUnprojectsToOpticalAxis) {
  for (const Camera& camera : AllCameras()) {
    Eigen::Vector3d ray;
    ASSERT_TRUE(camera.Unproject(Eigen::Vector2d(camera.cx, camera.cy), &ray))
        << CameraModelName(camera.model);
    EXPECT_LT((ray - Eigen::Vector3d(0, 0, 1)).norm(), 1e-15) << CameraModelName(camera.model);
    Eigen::Vector2d pixel;
    ASSERT_TRUE(camera.Project(Eigen::Vector3d(0, 0, 2.5), &pixel));
    EXPECT_LT((pixel - Eigen::Vector2d(camera.cx, camera.cy)).norm(), 1e-12);
  }
}

TEST(Camera, UnprojectThenProjectRoundTripsOverTheImage) {
  for (const Camera& camera : AllCameras()) {
    int converged = 0, total = 0;
    double max_error = 0;
    for (int y = 0; y < camera.height; y += 3) {
      for (int x = 0; x < camera.width; x += 3) {
        const Eigen::Vector2d pixel(x, y);
        ++total;
        Eigen::Vector3d ray;
        if (!camera.Unproject(pixel, &ray)) continue;
        ++converged;
        EXPECT_EQ(ray.z(), 1.0);
        Eigen::Vector2d reprojected;
        ASSERT_TRUE(camera.Project(ray * 3.7, &reprojected)) << pixel.transpose();
        max_error = std::max(max_error, (reprojected - pixel).norm());
      }
    }
    EXPECT_LT(max_error, 1e-8) << CameraModelName(camera.model);
    if (camera.model != CameraModel::kEquidistant) {
      EXPECT_EQ(converged, total) << CameraModelName(camera.model);
    } else {
      // The fisheye corners lie beyond 90 degrees and cannot be rays with z = 1: exactly the
      // pixels outside the circle of distorted radius theta_d(90 degrees) fail.
      EXPECT_EQ(converged, CountPixelsWithinNinetyDegrees(camera, 3));
      EXPECT_LT(converged, total);
    }
  }
}

TEST(Camera, ProjectThenUnprojectRoundTripsRandomPoints) {
  std::mt19937 rng(7);
  for (const Camera& camera : AllCameras()) {
    std::uniform_real_distribution<double> pixel_x(0, camera.width - 1);
    std::uniform_real_distribution<double> pixel_y(0, camera.height - 1);
    std::uniform_real_distribution<double> depth(0.2, 20.0);
    int tested = 0;
    for (int i = 0; i < 2000; ++i) {
      // A random point whose pixel is inside the image: unproject a random pixel, scale by depth.
      Eigen::Vector3d ray;
      if (!camera.Unproject(Eigen::Vector2d(pixel_x(rng), pixel_y(rng)), &ray)) continue;
      const Eigen::Vector3d point = ray * depth(rng);
      Eigen::Vector2d pixel;
      ASSERT_TRUE(camera.Project(point, &pixel));
      Eigen::Vector3d back;
      ASSERT_TRUE(camera.Unproject(pixel, &back));
      EXPECT_LT((back - point / point.z()).norm(), 1e-9 * std::max(1.0, back.norm()))
          << CameraModelName(camera.model) << " " << point.transpose();
      ++tested;
    }
    EXPECT_GT(tested, 1500) << CameraModelName(camera.model);
  }
}

TEST(Camera, EquidistantHandlesLargeAngles) {
  const Camera camera = MakeEquidistant();
  for (double degrees : {10.0, 45.0, 80.0, 88.0, 89.9}) {
    const double theta = degrees * M_PI / 180.0;
    const double radius = EquidistantDistortedRadius(camera, theta);
    const Eigen::Vector2d pixel(camera.cx + camera.fx * radius * 0.6,
                                camera.cy + camera.fy * radius * 0.8);
    Eigen::Vector3d ray;
    ASSERT_TRUE(camera.Unproject(pixel, &ray)) << degrees;
    const double angle = std::atan2(ray.head<2>().norm(), ray.z());
    EXPECT_NEAR(angle, theta, 1e-9) << degrees;
    Eigen::Vector2d reprojected;
    ASSERT_TRUE(camera.Project(ray.normalized(), &reprojected));
    EXPECT_LT((reprojected - pixel).norm(), 1e-6) << degrees;
  }
  // Beyond 90 degrees there is no ray with z = 1.
  const double beyond = EquidistantDistortedRadius(camera, 95.0 * M_PI / 180.0);
  Eigen::Vector3d ray;
  EXPECT_FALSE(camera.Unproject(Eigen::Vector2d(camera.cx + camera.fx * beyond, camera.cy), &ray));
}

TEST(Camera, ProjectRejectsPointsBehindTheCamera) {
  for (const Camera& camera : AllCameras()) {
    Eigen::Vector2d pixel;
    EXPECT_FALSE(camera.Project(Eigen::Vector3d(0.1, 0.2, 0.0), &pixel));
    EXPECT_FALSE(camera.Project(Eigen::Vector3d(0.1, 0.2, -1.0), &pixel));
    EXPECT_FALSE(camera.Project(Eigen::Vector3d(0.0, 0.0, 1e-12), &pixel));
    EXPECT_FALSE(camera.Project(Eigen::Vector3d(0.0, 0.0, std::numeric_limits<double>::quiet_NaN()),
                                &pixel));
    // 87 degrees off-axis: a pinhole and the fisheye still project it; the radtan polynomial
    // has folded back long before (its k3 < 0 dominates), so it refuses.
    EXPECT_EQ(camera.Project(Eigen::Vector3d(0.01, 0.02, 1e-3), &pixel),
              camera.model != CameraModel::kRadialTangential)
        << CameraModelName(camera.model);
  }
}

TEST(Camera, RadialTangentialRejectsPointsBeyondTheFold) {
  // r (1 - 0.5 r^2) increases up to r = sqrt(2/3) = 0.816, where it reaches 0.544.
  Camera camera = Camera::Pinhole(640, 480, 300, 300, 320, 240);
  camera.model = CameraModel::kRadialTangential;
  camera.distortion = {-0.5, 0, 0, 0, 0};
  Eigen::Vector2d pixel;
  EXPECT_TRUE(camera.Project(Eigen::Vector3d(0.8, 0, 1), &pixel));
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(0.9, 0, 1), &pixel));
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(1.5, 0, 1), &pixel));
  Eigen::Vector3d ray;
  EXPECT_TRUE(camera.Unproject(Eigen::Vector2d(320 + 300 * 0.54, 240), &ray));
  EXPECT_LT(ray.x(), 0.817);
  // No undistorted point reaches a distorted radius of 0.56.
  EXPECT_FALSE(camera.Unproject(Eigen::Vector2d(320 + 300 * 0.56, 240), &ray));
}

TEST(Camera, AnalyticJacobianMatchesCentralDifferences) {
  std::mt19937 rng(11);
  for (const Camera& camera : AllCameras()) {
    std::uniform_real_distribution<double> pixel_x(0, camera.width - 1);
    std::uniform_real_distribution<double> pixel_y(0, camera.height - 1);
    std::uniform_real_distribution<double> depth(0.3, 8.0);
    std::vector<Eigen::Vector3d> points = {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1e-9, 0, 2),
                                           Eigen::Vector3d(1e-4, -2e-4, 1.0)};
    while (points.size() < 300) {
      Eigen::Vector3d ray;
      if (camera.Unproject(Eigen::Vector2d(pixel_x(rng), pixel_y(rng)), &ray)) {
        points.push_back(ray * depth(rng));
      }
    }
    double max_error = 0;
    for (const Eigen::Vector3d& point : points) {
      Eigen::Vector2d pixel;
      Eigen::Matrix<double, 2, 3> analytic;
      ASSERT_TRUE(camera.Project(point, &pixel, &analytic));
      Eigen::Vector2d pixel_without_jacobian;
      ASSERT_TRUE(camera.Project(point, &pixel_without_jacobian));
      EXPECT_EQ(pixel, pixel_without_jacobian);
      Eigen::Matrix<double, 2, 3> numeric;
      const double step = 1e-6 * point.z();
      for (int axis = 0; axis < 3; ++axis) {
        Eigen::Vector2d plus, minus;
        ASSERT_TRUE(camera.Project(point + step * Eigen::Vector3d::Unit(axis), &plus));
        ASSERT_TRUE(camera.Project(point - step * Eigen::Vector3d::Unit(axis), &minus));
        numeric.col(axis) = (plus - minus) / (2 * step);
      }
      const double error = (analytic - numeric).norm() / std::max(1.0, numeric.norm());
      max_error = std::max(max_error, error);
      EXPECT_LT(error, 1e-6) << CameraModelName(camera.model) << " at " << point.transpose()
                             << "\nanalytic\n"
                             << analytic << "\nnumeric\n"
                             << numeric;
    }
    RecordProperty(CameraModelName(camera.model) + "_max_relative_jacobian_error",
                   std::to_string(max_error));
  }
}

TEST(Camera, DistortJacobianMatchesCentralDifferences) {
  for (const Camera& camera : AllCameras()) {
    for (const Eigen::Vector2d& undistorted :
         {Eigen::Vector2d(0.3, -0.2), Eigen::Vector2d(-0.6, 0.45), Eigen::Vector2d(1e-7, 2e-7)}) {
      Eigen::Vector2d distorted;
      Eigen::Matrix2d analytic;
      ASSERT_TRUE(camera.Distort(undistorted, &distorted, &analytic));
      Eigen::Matrix2d numeric;
      const double step = 1e-7;
      for (int axis = 0; axis < 2; ++axis) {
        Eigen::Vector2d plus, minus;
        ASSERT_TRUE(camera.Distort(undistorted + step * Eigen::Vector2d::Unit(axis), &plus));
        ASSERT_TRUE(camera.Distort(undistorted - step * Eigen::Vector2d::Unit(axis), &minus));
        numeric.col(axis) = (plus - minus) / (2 * step);
      }
      EXPECT_LT((analytic - numeric).norm(), 1e-7) << CameraModelName(camera.model);
      Eigen::Vector2d back;
      ASSERT_TRUE(camera.Undistort(distorted, &back));
      EXPECT_LT((back - undistorted).norm(), 1e-12);
    }
  }
}

TEST(Camera, RadialTangentialMatchesOpenCvProjectPoints) {
  const Camera camera = MakeRadialTangential();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> lateral(-0.8, 0.8);
  std::uniform_real_distribution<double> depth(0.5, 10.0);
  std::vector<cv::Point3d> points;
  for (int i = 0; i < 500; ++i) {
    const double z = depth(rng);
    points.emplace_back(lateral(rng) * z, lateral(rng) * z * 0.75, z);
  }
  cv::Mat camera_matrix =
      (cv::Mat_<double>(3, 3) << camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1);
  cv::Mat distortion(camera.distortion, true);
  std::vector<cv::Point2d> expected;
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera_matrix, distortion,
                    expected);
  ASSERT_EQ(expected.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    Eigen::Vector2d pixel;
    ASSERT_TRUE(camera.Project(Eigen::Vector3d(points[i].x, points[i].y, points[i].z), &pixel));
    EXPECT_NEAR(pixel.x(), expected[i].x, 1e-9);
    EXPECT_NEAR(pixel.y(), expected[i].y, 1e-9);
  }
}

TEST(Camera, EquidistantMatchesOpenCvFisheyeProjectPoints) {
  const Camera camera = MakeEquidistant();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> lateral(-3.0, 3.0);
  std::uniform_real_distribution<double> depth(0.5, 10.0);
  std::vector<cv::Point3d> points;
  for (int i = 0; i < 500; ++i) {
    const double z = depth(rng);
    points.emplace_back(lateral(rng) * z, lateral(rng) * z, z);
  }
  cv::Mat camera_matrix =
      (cv::Mat_<double>(3, 3) << camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1);
  cv::Mat distortion(camera.distortion, true);
  std::vector<cv::Point2d> expected;
  cv::fisheye::projectPoints(points, expected, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0),
                             camera_matrix, distortion);
  ASSERT_EQ(expected.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    Eigen::Vector2d pixel;
    ASSERT_TRUE(camera.Project(Eigen::Vector3d(points[i].x, points[i].y, points[i].z), &pixel));
    EXPECT_NEAR(pixel.x(), expected[i].x, 1e-8);
    EXPECT_NEAR(pixel.y(), expected[i].y, 1e-8);
  }
}

TEST(Camera, IsInsideUsesPixelCentresAndMargin) {
  const Camera camera = Camera::Pinhole(240, 180, 200, 200, 119.5, 89.5);
  EXPECT_TRUE(camera.IsInside(Eigen::Vector2d(0, 0)));
  EXPECT_TRUE(camera.IsInside(Eigen::Vector2d(239, 179)));
  EXPECT_FALSE(camera.IsInside(Eigen::Vector2d(239.01, 100)));
  EXPECT_FALSE(camera.IsInside(Eigen::Vector2d(-0.01, 100)));
  EXPECT_FALSE(camera.IsInside(Eigen::Vector2d(100, 179.5)));
  EXPECT_FALSE(camera.IsInside(Eigen::Vector2d(1.5, 100), 2));
  EXPECT_TRUE(camera.IsInside(Eigen::Vector2d(2, 177), 2));
  EXPECT_FALSE(camera.IsInside(Eigen::Vector2d(2, 177.5), 2));
}

TEST(Camera, PinholeFactoryAndMatrices) {
  const Camera camera = Camera::Pinhole(320, 240, 250, 260, 160.5, 120.5);
  EXPECT_NO_THROW(camera.Check());
  EXPECT_EQ(camera.model, CameraModel::kPinhole);
  EXPECT_TRUE(camera.distortion.empty());
  const Eigen::Vector3d point(0.3, -0.1, 2.0);
  Eigen::Vector2d pixel;
  ASSERT_TRUE(camera.Project(point, &pixel));
  const Eigen::Vector3d homogeneous = camera.CalibrationMatrix() * point;
  EXPECT_LT((pixel - homogeneous.head<2>() / homogeneous.z()).norm(), 1e-12);
  const Camera ideal = MakeRadialTangential().IdealPinhole();
  EXPECT_EQ(ideal.model, CameraModel::kPinhole);
  EXPECT_EQ(ideal.fx, MakeRadialTangential().fx);
  EXPECT_EQ(ideal.width, 240);
}

TEST(CameraYaml, RoundTripsExactly) {
  const auto directory = testing::MakeTempDir("evloc-camera-yaml");
  std::vector<Camera> cameras = AllCameras();
  Camera awkward = MakeRadialTangential();
  awkward.fx = 1.0 / 3.0 * 600;
  awkward.distortion = {0.1, -1e-17, 5e-324, std::nextafter(0.2, 1.0), -0.0};
  cameras.push_back(awkward);
  for (size_t i = 0; i < cameras.size(); ++i) {
    const auto path = directory / ("camera" + std::to_string(i) + ".yaml");
    WriteCameraYaml(path, cameras[i]);
    const Camera read = ReadCameraYaml(path);
    EXPECT_EQ(read, cameras[i]) << ReadFileToString(path);
  }
  std::filesystem::remove_all(directory);
}

TEST(CameraYaml, ParsesTheDocumentedExample) {
  const Camera camera = ParseCameraYaml(
      "model: plumb_bob\n"
      "width: 240\n"
      "height: 180\n"
      "intrinsics: [199.092366542, 198.82882047, 132.192071378, 110.712660011]\n"
      "distortion: [-0.368436311798, 0.150947243557, -0.000296130534385, "
      "-0.000759431726241, 0.0]\n",
      "example.yaml");
  EXPECT_EQ(camera.model, CameraModel::kRadialTangential);
  EXPECT_EQ(camera.width, 240);
  EXPECT_EQ(camera.height, 180);
  EXPECT_EQ(camera.cy, 110.712660011);
  ASSERT_EQ(camera.distortion.size(), 5u);
  EXPECT_EQ(camera.distortion[1], 0.150947243557);
  const Camera pinhole =
      ParseCameraYaml("model: pinhole\nwidth: 10\nheight: 8\nintrinsics: [5, 5, 4.5, 3.5]\n", "p");
  EXPECT_EQ(pinhole, Camera::Pinhole(10, 8, 5, 5, 4.5, 3.5));
}

// Expects ParseCameraYaml(text) to throw a ParseError whose message contains every fragment.
void ExpectYamlError(const std::string& text, const std::vector<std::string>& fragments) {
  try {
    ParseCameraYaml(text, "bad.yaml");
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const ParseError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("bad.yaml"), std::string::npos) << message;
    for (const std::string& fragment : fragments) {
      EXPECT_NE(message.find(fragment), std::string::npos) << message << " lacks " << fragment;
    }
  }
}

TEST(CameraYaml, ErrorsNameTheFileLineAndKey) {
  const std::string size = "width: 240\nheight: 180\n";
  const std::string intrinsics = "intrinsics: [200, 200, 120, 90]\n";
  const std::string distortion = "distortion: [0, 0, 0, 0, 0]\n";
  ExpectYamlError(size + intrinsics + distortion, {"missing key 'model'"});
  ExpectYamlError("model: radtan\n" + size + distortion, {"missing key 'intrinsics'"});
  ExpectYamlError("model: radtan\n" + size + intrinsics, {"missing key 'distortion'"});
  ExpectYamlError("model: radtan\nwidth: 240\n" + intrinsics + distortion,
                  {"missing key 'height'"});
  ExpectYamlError("model: omni\n" + size + intrinsics + distortion, {"line 1", "'model'", "omni"});
  ExpectYamlError("model: radtan\nwidth: wide\nheight: 180\n" + intrinsics + distortion,
                  {"line 2", "'width'"});
  ExpectYamlError("model: radtan\n" + size + "intrinsics: [200, 200, 120]\n" + distortion,
                  {"line 4", "'intrinsics'", "4 numbers"});
  ExpectYamlError("model: radtan\n" + size + "intrinsics: [200, x, 120, 90]\n" + distortion,
                  {"line 4", "'intrinsics' element 1"});
  ExpectYamlError("model: radtan\n" + size + intrinsics + "distortion: [0, 0, 0, 0]\n",
                  {"line 5", "'distortion'", "takes 5"});
  ExpectYamlError("model: equidistant\n" + size + intrinsics + distortion,
                  {"'distortion'", "takes 4"});
  ExpectYamlError("model: radtan\n" + size + intrinsics + distortion + "distorsion: [1]\n",
                  {"line 6", "unknown key 'distorsion'"});
  ExpectYamlError("model: radtan\n" + size + "intrinsics: [0, 200, 120, 90]\n" + distortion,
                  {"invalid camera", "focal"});
  ExpectYamlError("model: radtan\nwidth: 0\nheight: 180\n" + intrinsics + distortion,
                  {"invalid camera", "size"});
  ExpectYamlError("model: radtan\n" + size + "intrinsics: [.nan, 200, 120, 90]\n" + distortion,
                  {"line 4", "'intrinsics' element 0"});
  ExpectYamlError("model: radtan\n" + size + "intrinsics: [nan, 200, 120, 90]\n" + distortion,
                  {"invalid camera", "fx", "not finite"});
  ExpectYamlError("model: [radtan\n", {"invalid YAML"});
  ExpectYamlError("- 1\n- 2\n", {"expected a map"});
  ExpectYamlError("", {"expected a map"});
}

TEST(CameraYaml, MissingFileIsAnIoErrorAndInvalidCameraIsNotWritten) {
  const auto directory = testing::MakeTempDir("evloc-camera-yaml");
  EXPECT_THROW(ReadCameraYaml(directory / "absent.yaml"), IoError);
  Camera invalid = MakeRadialTangential();
  invalid.fx = 0;
  EXPECT_THROW(WriteCameraYaml(directory / "invalid.yaml", invalid), InvalidArgumentError);
  EXPECT_FALSE(std::filesystem::exists(directory / "invalid.yaml"));
  std::filesystem::remove_all(directory);
}

TEST(EcdCalibration, ReadsSliderDepth) {
  EVLOC_REQUIRE_SHARED_DATA(calib, "ecd/slider_depth/calib.txt");
  const Camera camera = ReadEcdCalibration(calib, 240, 180);
  EXPECT_EQ(camera.model, CameraModel::kRadialTangential);
  EXPECT_EQ(camera.width, 240);
  EXPECT_EQ(camera.height, 180);
  EXPECT_EQ(camera.fx, 335.419462958);
  EXPECT_EQ(camera.fy, 335.352935612);
  EXPECT_EQ(camera.cx, 129.924663379);
  EXPECT_EQ(camera.cy, 99.1864303447);
  const std::vector<double> expected_distortion = {-0.138592767408, 0.0933736664192,
                                                   -0.000335586987532, 0.000173720158228, 0.0};
  EXPECT_EQ(camera.distortion, expected_distortion);
  // Every sensor pixel of this lens undistorts and reprojects.
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      Eigen::Vector3d ray;
      ASSERT_TRUE(camera.Unproject(Eigen::Vector2d(x, y), &ray)) << x << " " << y;
    }
  }
}

TEST(EcdCalibration, ReadsEverySnippetCalibration) {
  EVLOC_REQUIRE_SHARED_DATA(first, "ecd/snippets/boxes_rotation/calib.txt");
  int read = 0;
  for (const auto& entry : std::filesystem::directory_iterator(first.parent_path().parent_path())) {
    const auto calib = entry.path() / "calib.txt";
    if (!std::filesystem::exists(calib)) continue;
    // Most snippet files end with CRLF: the reader must not care.
    const Camera camera = ReadEcdCalibration(calib, 240, 180);
    EXPECT_EQ(camera.fx, 199.092366542) << calib;
    EXPECT_EQ(camera.cy, 110.712660011) << calib;
    ASSERT_EQ(camera.distortion.size(), 5u);
    EXPECT_EQ(camera.distortion[0], -0.368436311798) << calib;
    EXPECT_EQ(camera.distortion[3], -0.000759431726241) << calib;
    ++read;
  }
  EXPECT_EQ(read, 8);
}

// Writes `content` to a temporary calib.txt and expects ReadEcdCalibration to throw a ParseError
// whose message contains every fragment.
void ExpectEcdError(const std::string& content, const std::vector<std::string>& fragments) {
  const auto directory = testing::MakeTempDir("evloc-ecd-calib");
  const auto path = directory / "calib.txt";
  WriteFileAtomically(path, content);
  try {
    ReadEcdCalibration(path, 240, 180);
    ADD_FAILURE() << "no error for: " << content;
  } catch (const ParseError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find(path.string()), std::string::npos) << message;
    for (const std::string& fragment : fragments) {
      EXPECT_NE(message.find(fragment), std::string::npos) << message << " lacks " << fragment;
    }
  }
  std::filesystem::remove_all(directory);
}

TEST(EcdCalibration, ErrorsNameTheLineAndField) {
  ExpectEcdError("200 200 120 90 -0.3 0.1 0 0\n", {"line 1", "expected 9 fields", "got 8"});
  ExpectEcdError("\n200 200 abc 90 -0.3 0.1 0 0 0\n", {"line 2", "field 3 (cx)", "'abc'"});
  ExpectEcdError("200 200 120 90 -0.3 0.1 0 0 nan\n", {"line 1", "field 9 (k3)"});
  ExpectEcdError("200 200 120 90 -0.3 0.1 0 0 0\n1 2 3\n", {"line 2", "unexpected content"});
  ExpectEcdError("200 -200 120 90 -0.3 0.1 0 0 0\n", {"line 1", "invalid camera"});
  ExpectEcdError("", {"no calibration line"});
  ExpectEcdError(" \r\n\r\n", {"no calibration line"});
}

TEST(EcdCalibration, RejectsBadSizeAndMissingFile) {
  const auto directory = testing::MakeTempDir("evloc-ecd-calib");
  const auto path = directory / "calib.txt";
  WriteFileAtomically(path, "200 200 120 90 -0.3 0.1 0 0 0\r\n");
  EXPECT_EQ(ReadEcdCalibration(path, 240, 180).cx, 120.0);
  EXPECT_THROW(ReadEcdCalibration(path, 0, 180), InvalidArgumentError);
  EXPECT_THROW(ReadEcdCalibration(path, 240, -1), InvalidArgumentError);
  EXPECT_THROW(ReadEcdCalibration(directory / "absent.txt", 240, 180), IoError);
  std::filesystem::remove_all(directory);
}

}  // namespace
}  // namespace evloc
