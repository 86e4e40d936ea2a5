// Camera models of evloc: pinhole, radial-tangential (OpenCV plumb_bob) and equidistant
// (Kannala-Brandt, OpenCV fisheye), with analytic projection Jacobians, iterative
// back-projection, and evloc's own calibration files (evloc YAML, ECD calib.txt); the files of
// other tools and the format detection of --calib: calibration_file.h.
// Conventions: camera frame x right, y down, z forward; pixel centres at integer coordinates.
// Formulas, parameter order and validity rules: docs/camera.md.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace evloc {

// The lens model of a camera.
enum class CameraModel {
  // Ideal pinhole, no distortion.
  kPinhole,
  // OpenCV plumb_bob: distortion k1 k2 p1 p2 k3.
  kRadialTangential,
  // Kannala-Brandt / OpenCV fisheye with theta = atan(r): distortion k1 k2 k3 k4.
  kEquidistant,
};

// The canonical name of a model: "pinhole", "radtan" or "equidistant".
std::string CameraModelName(CameraModel model);

// Parses a model name (case-insensitive): the canonical names, and the aliases "plumb_bob",
// "radial_tangential" (radtan), "fisheye", "equi", "kannala_brandt" (equidistant). Throws
// InvalidArgumentError for any other name.
CameraModel ParseCameraModel(const std::string& name);

// The number of distortion coefficients a model takes: 0, 5 or 4.
int NumDistortionCoefficients(CameraModel model);

// An intrinsically calibrated camera. A plain value: fill the fields, then call Check().
struct Camera {
  // Projection fails for points with z at or below this depth (metres, or the units of the point).
  static constexpr double kMinDepth = 1e-9;

  // The lens model.
  CameraModel model = CameraModel::kPinhole;
  // Sensor width in pixels.
  int width = 0;
  // Sensor height in pixels.
  int height = 0;
  // Focal length along x, pixels.
  double fx = 0;
  // Focal length along y, pixels.
  double fy = 0;
  // Principal point x, pixels (pixel centres at integers).
  double cx = 0;
  // Principal point y, pixels.
  double cy = 0;
  // Distortion coefficients: radtan k1 k2 p1 p2 k3 (plumb_bob order); equidistant k1 k2 k3 k4;
  // pinhole: empty.
  std::vector<double> distortion;

  // Throws InvalidArgumentError when a field is NaN or infinite, fx or fy <= 0, width or height
  // <= 0 or above 65536, or the distortion count does not match the model.
  void Check() const;

  // Projects a point in camera coordinates to a (distorted) pixel, and optionally the Jacobian of
  // the pixel with respect to the point. Returns false (outputs unspecified) when z <= kMinDepth
  // or the point lies beyond the radius where the lens distortion stops being monotonic.
  bool Project(const Eigen::Vector3d& point_in_cam, Eigen::Vector2d* pixel,
               Eigen::Matrix<double, 2, 3>* d_pixel_d_point = nullptr) const;

  // Back-projects a (distorted) pixel to the ray in camera coordinates with z = 1, inverting the
  // distortion by Newton iterations. Returns false when the iterations do not converge, or the
  // solution lies where the distortion is not monotonic, or (equidistant) the ray angle reaches
  // 90 degrees from the optical axis.
  bool Unproject(const Eigen::Vector2d& pixel, Eigen::Vector3d* ray_in_cam) const;

  // True when the pixel lies in [margin, width-1-margin] x [margin, height-1-margin].
  bool IsInside(const Eigen::Vector2d& pixel, double margin = 0) const;

  // Applies the lens distortion to normalised coordinates (x/z, y/z), giving distorted
  // normalised coordinates, and optionally their 2x2 Jacobian. Returns false outside the
  // monotonic region of the distortion (see Project).
  bool Distort(const Eigen::Vector2d& undistorted, Eigen::Vector2d* distorted,
               Eigen::Matrix2d* d_distorted_d_undistorted = nullptr) const;

  // Inverts Distort by Newton iterations; false when it does not converge (see Unproject).
  bool Undistort(const Eigen::Vector2d& distorted, Eigen::Vector2d* undistorted) const;

  // The 3x3 calibration matrix [fx 0 cx; 0 fy cy; 0 0 1].
  Eigen::Matrix3d CalibrationMatrix() const;

  // The ideal pinhole camera with the same size, focal lengths and principal point.
  Camera IdealPinhole() const;

  // Field-wise equality (exact).
  bool operator==(const Camera& other) const = default;

  // A pinhole camera without distortion.
  static Camera Pinhole(int width, int height, double fx, double fy, double cx, double cy);
};

// Parses a camera from evloc YAML text (docs/camera.md). `source` names the text in errors.
// Throws ParseError naming the source, the line and the key when the text is malformed or the
// camera fails Check().
Camera ParseCameraYaml(const std::string& text, const std::string& source);

// Formats a camera as evloc YAML text, with doubles written to round-trip exactly.
std::string CameraToYaml(const Camera& camera);

// Reads an evloc YAML camera file. Throws IoError when it cannot be read, ParseError when it is
// malformed.
Camera ReadCameraYaml(const std::filesystem::path& path);

// Writes a camera as an evloc YAML file, atomically. Throws InvalidArgumentError when the camera
// fails Check(), IoError when the file cannot be written.
void WriteCameraYaml(const std::filesystem::path& path, const Camera& camera);

// Reads an Event Camera Dataset calib.txt: one line "fx fy cx cy k1 k2 p1 p2 k3" (a radtan
// camera). The file has no image size, so the caller passes it (DAVIS240: 240 x 180). Throws
// IoError when the file cannot be read, ParseError naming the line and field when it is
// malformed, InvalidArgumentError when width or height is not positive.
Camera ReadEcdCalibration(const std::filesystem::path& calib_txt, int width, int height);

// Parses the text of an ECD calib.txt; `source` names it in errors. Throws as ReadEcdCalibration.
Camera ParseEcdCalibration(const std::string& content, const std::string& source, int width,
                           int height);

}  // namespace evloc
