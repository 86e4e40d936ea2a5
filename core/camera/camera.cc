#include "core/camera/camera.h"

#include <yaml-cpp/yaml.h>
#include <Eigen/LU>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <set>
#include <sstream>

#include "core/camera/calibration_text.h"
#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc {
namespace {

using camera_text::FormatDouble;
using camera_text::ParseDouble;
using camera_text::ToLower;

// Newton iterations of Undistort stop when the residual (normalised coordinates, or radians for
// the equidistant angle) falls below this; 1e-12 is far below a micro-pixel for any real lens.
constexpr double kUndistortTolerance = 1e-12;
// Upper bound on Newton iterations; a converging inversion needs fewer than 10.
constexpr int kMaxUndistortIterations = 50;
// Equidistant rays must stay this far (radians) below 90 degrees from the optical axis to be
// representable as a ray with z = 1.
constexpr double kMaxEquidistantAngleMargin = 1e-6;
// Below this radius (normalised coordinates) the equidistant map is the identity to 1e-20.
constexpr double kEquidistantCentreRadius = 1e-10;
// Largest accepted sensor side, pixels.
constexpr int kMaxSensorSide = 65536;

// The radtan distortion, its Jacobian, and whether the radial part is increasing at this radius.
struct DistortionResult {
  Eigen::Vector2d distorted;
  Eigen::Matrix2d jacobian;
  bool monotonic = true;
};

DistortionResult DistortRadialTangential(const std::vector<double>& coefficients,
                                         const Eigen::Vector2d& undistorted) {
  const double k1 = coefficients[0], k2 = coefficients[1], p1 = coefficients[2],
               p2 = coefficients[3], k3 = coefficients[4];
  const double x = undistorted.x(), y = undistorted.y();
  const double xx = x * x, yy = y * y, xy = x * y;
  const double r2 = xx + yy;
  const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const double d_radial_d_r2 = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3);
  DistortionResult result;
  result.distorted.x() = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx);
  result.distorted.y() = y * radial + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy;
  result.jacobian(0, 0) = radial + 2.0 * xx * d_radial_d_r2 + 2.0 * p1 * y + 6.0 * p2 * x;
  result.jacobian(0, 1) = 2.0 * xy * d_radial_d_r2 + 2.0 * p1 * x + 2.0 * p2 * y;
  result.jacobian(1, 0) = 2.0 * xy * d_radial_d_r2 + 2.0 * p1 * x + 2.0 * p2 * y;
  result.jacobian(1, 1) = radial + 2.0 * yy * d_radial_d_r2 + 6.0 * p1 * y + 2.0 * p2 * x;
  // d(r * radial(r)) / dr = radial + 2 r^2 d_radial_d_r2.
  result.monotonic = radial + 2.0 * r2 * d_radial_d_r2 > 0.0;
  return result;
}

// theta_d(theta) = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8) and its
// derivative with respect to theta.
void EquidistantAngle(const std::vector<double>& coefficients, double theta, double* theta_d,
                      double* d_theta_d_d_theta) {
  const double k1 = coefficients[0], k2 = coefficients[1], k3 = coefficients[2],
               k4 = coefficients[3];
  const double t2 = theta * theta;
  *theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))));
  *d_theta_d_d_theta = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
}

DistortionResult DistortEquidistant(const std::vector<double>& coefficients,
                                    const Eigen::Vector2d& undistorted) {
  DistortionResult result;
  const double r = undistorted.norm();
  if (r < kEquidistantCentreRadius) {
    result.distorted = undistorted;
    result.jacobian.setIdentity();
    return result;
  }
  const double theta = std::atan(r);
  double theta_d = 0, d_theta_d_d_theta = 0;
  EquidistantAngle(coefficients, theta, &theta_d, &d_theta_d_d_theta);
  const double scale = theta_d / r;
  // d scale / dr = (theta_d' * dtheta/dr * r - theta_d) / r^2, dtheta/dr = 1 / (1 + r^2).
  const double d_scale_d_r = (d_theta_d_d_theta / (1.0 + r * r) * r - theta_d) / (r * r);
  result.distorted = scale * undistorted;
  // d(scale * u) / du = scale I + (d_scale_d_r / r) u u^T.
  result.jacobian = scale * Eigen::Matrix2d::Identity() +
                    (d_scale_d_r / r) * undistorted * undistorted.transpose();
  result.monotonic = d_theta_d_d_theta > 0.0;
  return result;
}

DistortionResult DistortAny(const Camera& camera, const Eigen::Vector2d& undistorted) {
  switch (camera.model) {
    case CameraModel::kRadialTangential:
      return DistortRadialTangential(camera.distortion, undistorted);
    case CameraModel::kEquidistant:
      return DistortEquidistant(camera.distortion, undistorted);
    case CameraModel::kPinhole:
      break;
  }
  DistortionResult result;
  result.distorted = undistorted;
  result.jacobian.setIdentity();
  return result;
}

// Newton iterations with step halving on Distort(u) = target, starting at u = target.
bool UndistortRadialTangential(const std::vector<double>& coefficients,
                               const Eigen::Vector2d& target, Eigen::Vector2d* undistorted) {
  Eigen::Vector2d estimate = target;
  DistortionResult current = DistortRadialTangential(coefficients, estimate);
  double residual = (current.distorted - target).norm();
  for (int iteration = 0; iteration < kMaxUndistortIterations; ++iteration) {
    if (residual < kUndistortTolerance) break;
    const double determinant = current.jacobian.determinant();
    if (!(std::abs(determinant) > 1e-300)) return false;
    const Eigen::Vector2d step = current.jacobian.inverse() * (target - current.distorted);
    double step_scale = 1.0;
    bool improved = false;
    for (int halving = 0; halving < 30; ++halving) {
      const Eigen::Vector2d candidate = estimate + step_scale * step;
      const DistortionResult next = DistortRadialTangential(coefficients, candidate);
      const double next_residual = (next.distorted - target).norm();
      if (std::isfinite(next_residual) && next_residual < residual) {
        estimate = candidate;
        current = next;
        residual = next_residual;
        improved = true;
        break;
      }
      step_scale *= 0.5;
    }
    if (!improved) break;
  }
  if (!(residual < kUndistortTolerance) || !current.monotonic ||
      !(current.jacobian.determinant() > 0.0)) {
    return false;
  }
  *undistorted = estimate;
  return true;
}

// Solves theta_d(theta) = |target| for theta in [0, 90 degrees) by safeguarded Newton.
bool UndistortEquidistant(const std::vector<double>& coefficients, const Eigen::Vector2d& target,
                          Eigen::Vector2d* undistorted) {
  const double radius_distorted = target.norm();
  if (radius_distorted < kEquidistantCentreRadius) {
    *undistorted = target;
    return true;
  }
  const double max_theta = M_PI / 2.0 - kMaxEquidistantAngleMargin;
  // Bracket [low, high] of the root while Newton steps stay inside it; bisection otherwise.
  double low = 0.0, high = max_theta;
  double theta = std::min(radius_distorted, max_theta);
  double theta_d = 0, derivative = 0;
  bool converged = false;
  for (int iteration = 0; iteration < kMaxUndistortIterations; ++iteration) {
    EquidistantAngle(coefficients, theta, &theta_d, &derivative);
    const double error = theta_d - radius_distorted;
    if (std::abs(error) < kUndistortTolerance) {
      converged = true;
      break;
    }
    if (error < 0) {
      low = theta;
    } else {
      high = theta;
    }
    double next = derivative > 0 ? theta - error / derivative : low - 1.0;
    if (!(next > low && next < high)) next = 0.5 * (low + high);
    if (next == theta) break;
    theta = next;
  }
  if (!converged || !(derivative > 0.0) || !(theta < max_theta)) return false;
  *undistorted = target * (std::tan(theta) / radius_distorted);
  return true;
}

std::string JoinDoubles(const std::vector<double>& values) {
  std::string text = "[";
  for (size_t i = 0; i < values.size(); ++i) {
    if (i > 0) text += ", ";
    text += FormatDouble(values[i]);
  }
  return text + "]";
}

}  // namespace

std::string CameraModelName(CameraModel model) {
  switch (model) {
    case CameraModel::kPinhole:
      return "pinhole";
    case CameraModel::kRadialTangential:
      return "radtan";
    case CameraModel::kEquidistant:
      return "equidistant";
  }
  throw InvalidArgumentError("CameraModelName: unknown camera model value " +
                             std::to_string(static_cast<int>(model)));
}

CameraModel ParseCameraModel(const std::string& name) {
  const std::string lower = ToLower(name);
  if (lower == "pinhole") return CameraModel::kPinhole;
  if (lower == "radtan" || lower == "plumb_bob" || lower == "radial_tangential") {
    return CameraModel::kRadialTangential;
  }
  if (lower == "equidistant" || lower == "fisheye" || lower == "equi" ||
      lower == "kannala_brandt") {
    return CameraModel::kEquidistant;
  }
  throw InvalidArgumentError("unknown camera model '" + name +
                             "' (expected pinhole, radtan, plumb_bob, equidistant, fisheye)");
}

int NumDistortionCoefficients(CameraModel model) {
  switch (model) {
    case CameraModel::kPinhole:
      return 0;
    case CameraModel::kRadialTangential:
      return 5;
    case CameraModel::kEquidistant:
      return 4;
  }
  throw InvalidArgumentError("NumDistortionCoefficients: unknown camera model value " +
                             std::to_string(static_cast<int>(model)));
}

void Camera::Check() const {
  const std::string name = CameraModelName(model);
  if (width <= 0 || height <= 0 || width > kMaxSensorSide || height > kMaxSensorSide) {
    throw InvalidArgumentError("camera size " + std::to_string(width) + " x " +
                               std::to_string(height) + " is invalid (each side in 1.." +
                               std::to_string(kMaxSensorSide) + " pixels)");
  }
  const std::array<std::pair<const char*, double>, 4> intrinsics = {
      {{"fx", fx}, {"fy", fy}, {"cx", cx}, {"cy", cy}}};
  for (const auto& [field, value] : intrinsics) {
    if (!std::isfinite(value)) {
      throw InvalidArgumentError(std::string("camera ") + field + " is not finite");
    }
  }
  if (!(fx > 0) || !(fy > 0)) {
    throw InvalidArgumentError("camera focal lengths must be positive (fx " + FormatDouble(fx) +
                               ", fy " + FormatDouble(fy) + ")");
  }
  const int expected = NumDistortionCoefficients(model);
  if (static_cast<int>(distortion.size()) != expected) {
    throw InvalidArgumentError("camera model " + name + " takes " + std::to_string(expected) +
                               " distortion coefficients, got " +
                               std::to_string(distortion.size()));
  }
  for (size_t i = 0; i < distortion.size(); ++i) {
    if (!std::isfinite(distortion[i])) {
      throw InvalidArgumentError("camera distortion coefficient " + std::to_string(i) +
                                 " is not finite");
    }
  }
}

bool Camera::Distort(const Eigen::Vector2d& undistorted, Eigen::Vector2d* distorted,
                     Eigen::Matrix2d* d_distorted_d_undistorted) const {
  const DistortionResult result = DistortAny(*this, undistorted);
  if (!result.monotonic) return false;
  *distorted = result.distorted;
  if (d_distorted_d_undistorted != nullptr) *d_distorted_d_undistorted = result.jacobian;
  return true;
}

bool Camera::Undistort(const Eigen::Vector2d& distorted, Eigen::Vector2d* undistorted) const {
  switch (model) {
    case CameraModel::kRadialTangential:
      return UndistortRadialTangential(distortion, distorted, undistorted);
    case CameraModel::kEquidistant:
      return UndistortEquidistant(distortion, distorted, undistorted);
    case CameraModel::kPinhole:
      break;
  }
  *undistorted = distorted;
  return true;
}

bool Camera::Project(const Eigen::Vector3d& point_in_cam, Eigen::Vector2d* pixel,
                     Eigen::Matrix<double, 2, 3>* d_pixel_d_point) const {
  const double z = point_in_cam.z();
  if (!(z > kMinDepth)) return false;
  const double inverse_z = 1.0 / z;
  const Eigen::Vector2d normalized(point_in_cam.x() * inverse_z, point_in_cam.y() * inverse_z);
  const DistortionResult result = DistortAny(*this, normalized);
  if (!result.monotonic) return false;
  *pixel = Eigen::Vector2d(fx * result.distorted.x() + cx, fy * result.distorted.y() + cy);
  if (d_pixel_d_point != nullptr) {
    Eigen::Matrix<double, 2, 3> d_normalized_d_point;
    d_normalized_d_point << inverse_z, 0.0, -normalized.x() * inverse_z,  //
        0.0, inverse_z, -normalized.y() * inverse_z;
    const Eigen::Matrix<double, 2, 3> d_distorted_d_point = result.jacobian * d_normalized_d_point;
    d_pixel_d_point->row(0) = fx * d_distorted_d_point.row(0);
    d_pixel_d_point->row(1) = fy * d_distorted_d_point.row(1);
  }
  return true;
}

bool Camera::Unproject(const Eigen::Vector2d& pixel, Eigen::Vector3d* ray_in_cam) const {
  const Eigen::Vector2d distorted((pixel.x() - cx) / fx, (pixel.y() - cy) / fy);
  Eigen::Vector2d undistorted;
  if (!Undistort(distorted, &undistorted)) return false;
  *ray_in_cam = Eigen::Vector3d(undistorted.x(), undistorted.y(), 1.0);
  return true;
}

bool Camera::IsInside(const Eigen::Vector2d& pixel, double margin) const {
  return pixel.x() >= margin && pixel.y() >= margin && pixel.x() <= width - 1 - margin &&
         pixel.y() <= height - 1 - margin;
}

Eigen::Matrix3d Camera::CalibrationMatrix() const {
  Eigen::Matrix3d matrix;
  matrix << fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0;
  return matrix;
}

Camera Camera::IdealPinhole() const { return Pinhole(width, height, fx, fy, cx, cy); }

Camera Camera::Pinhole(int width, int height, double fx, double fy, double cx, double cy) {
  Camera camera;
  camera.model = CameraModel::kPinhole;
  camera.width = width;
  camera.height = height;
  camera.fx = fx;
  camera.fy = fy;
  camera.cx = cx;
  camera.cy = cy;
  return camera;
}

Camera ParseCameraYaml(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& error) {
    throw ParseError::AtLine(source, error.mark.line + 1, "invalid YAML: " + error.msg);
  }
  if (!root.IsMap()) {
    throw ParseError::AtLine(source, root.IsDefined() ? root.Mark().line + 1 : 1,
                             "expected a map with keys model, width, height, intrinsics, "
                             "distortion");
  }
  const int root_line = root.Mark().line + 1;
  static const std::set<std::string> kKnownKeys = {"model", "width", "height", "intrinsics",
                                                   "distortion"};
  for (const auto& entry : root) {
    const std::string key = entry.first.Scalar();
    if (kKnownKeys.count(key) == 0) {
      throw ParseError::AtLine(source, entry.first.Mark().line + 1,
                               "unknown key '" + key +
                                   "' (expected one of model, width, "
                                   "height, intrinsics, distortion)");
    }
  }
  const auto require = [&](const char* key) {
    const YAML::Node node = root[key];
    if (!node.IsDefined() || node.IsNull()) {
      throw ParseError::AtLine(source, root_line, std::string("missing key '") + key + "'");
    }
    return node;
  };
  const auto line_of = [](const YAML::Node& node) { return node.Mark().line + 1; };
  const auto read_int = [&](const char* key) {
    const YAML::Node node = require(key);
    try {
      return node.as<int>();
    } catch (const YAML::Exception&) {
      throw ParseError::AtLine(source, line_of(node),
                               std::string("key '") + key + "': expected an integer");
    }
  };
  const auto read_doubles = [&](const char* key, const YAML::Node& node) {
    if (!node.IsSequence()) {
      throw ParseError::AtLine(source, line_of(node),
                               std::string("key '") + key + "': expected a sequence of numbers");
    }
    std::vector<double> values;
    for (size_t i = 0; i < node.size(); ++i) {
      double value = 0;
      if (!node[i].IsScalar() || !ParseDouble(node[i].Scalar(), &value)) {
        throw ParseError::AtLine(
            source, line_of(node[i]),
            std::string("key '") + key + "' element " + std::to_string(i) + ": expected a number");
      }
      values.push_back(value);
    }
    return values;
  };

  Camera camera;
  const YAML::Node model_node = require("model");
  try {
    camera.model = ParseCameraModel(model_node.Scalar());
  } catch (const InvalidArgumentError& error) {
    throw ParseError::AtLine(source, line_of(model_node),
                             std::string("key 'model': ") + error.what());
  }
  camera.width = read_int("width");
  camera.height = read_int("height");
  const YAML::Node intrinsics_node = require("intrinsics");
  const std::vector<double> intrinsics = read_doubles("intrinsics", intrinsics_node);
  if (intrinsics.size() != 4) {
    throw ParseError::AtLine(source, line_of(intrinsics_node),
                             "key 'intrinsics': expected 4 numbers [fx, fy, cx, cy], got " +
                                 std::to_string(intrinsics.size()));
  }
  camera.fx = intrinsics[0];
  camera.fy = intrinsics[1];
  camera.cx = intrinsics[2];
  camera.cy = intrinsics[3];
  const YAML::Node distortion_node = root["distortion"];
  int distortion_line = root_line;
  if (distortion_node.IsDefined() && !distortion_node.IsNull()) {
    camera.distortion = read_doubles("distortion", distortion_node);
    distortion_line = line_of(distortion_node);
  } else if (camera.model != CameraModel::kPinhole) {
    throw ParseError::AtLine(
        source, root_line,
        "missing key 'distortion' (required for model " + CameraModelName(camera.model) + ")");
  }
  if (static_cast<int>(camera.distortion.size()) != NumDistortionCoefficients(camera.model)) {
    throw ParseError::AtLine(source, distortion_line,
                             "key 'distortion': model " + CameraModelName(camera.model) +
                                 " takes " +
                                 std::to_string(NumDistortionCoefficients(camera.model)) +
                                 " coefficients, got " + std::to_string(camera.distortion.size()));
  }
  try {
    camera.Check();
  } catch (const InvalidArgumentError& error) {
    throw ParseError::AtLine(source, root_line, std::string("invalid camera: ") + error.what());
  }
  return camera;
}

std::string CameraToYaml(const Camera& camera) {
  std::ostringstream text;
  text << "# evloc camera (docs/camera.md): intrinsics [fx, fy, cx, cy] in pixels.\n";
  text << "model: " << CameraModelName(camera.model) << "\n";
  text << "width: " << camera.width << "\n";
  text << "height: " << camera.height << "\n";
  text << "intrinsics: " << JoinDoubles({camera.fx, camera.fy, camera.cx, camera.cy}) << "\n";
  text << "distortion: " << JoinDoubles(camera.distortion) << "\n";
  return text.str();
}

Camera ReadCameraYaml(const std::filesystem::path& path) {
  return ParseCameraYaml(ReadFileToString(path), path.string());
}

void WriteCameraYaml(const std::filesystem::path& path, const Camera& camera) {
  camera.Check();
  WriteFileAtomically(path, CameraToYaml(camera));
}

Camera ReadEcdCalibration(const std::filesystem::path& calib_txt, int width, int height) {
  if (width <= 0 || height <= 0) {
    throw InvalidArgumentError("ReadEcdCalibration: image size " + std::to_string(width) + " x " +
                               std::to_string(height) + " must be positive");
  }
  return ParseEcdCalibration(ReadFileToString(calib_txt), calib_txt.string(), width, height);
}

Camera ParseEcdCalibration(const std::string& content, const std::string& source, int width,
                           int height) {
  if (width <= 0 || height <= 0) {
    throw InvalidArgumentError(source + ": image size " + std::to_string(width) + " x " +
                               std::to_string(height) + " must be positive");
  }
  static const std::array<const char*, 9> kFieldNames = {"fx", "fy", "cx", "cy", "k1",
                                                         "k2", "p1", "p2", "k3"};
  std::istringstream lines(content);
  std::string line;
  int line_number = 0;
  int calibration_line = 0;
  std::vector<double> values;
  while (std::getline(lines, line)) {
    ++line_number;
    std::istringstream fields(line);
    std::vector<std::string> tokens;
    for (std::string token; fields >> token;) tokens.push_back(token);
    if (tokens.empty()) continue;
    if (calibration_line != 0) {
      throw ParseError::AtLine(
          source, line_number,
          "unexpected content after the calibration line " + std::to_string(calibration_line));
    }
    calibration_line = line_number;
    if (tokens.size() != kFieldNames.size()) {
      throw ParseError::AtLine(
          source, line_number,
          "expected 9 fields 'fx fy cx cy k1 k2 p1 p2 k3', got " + std::to_string(tokens.size()));
    }
    for (size_t i = 0; i < tokens.size(); ++i) {
      double value = 0;
      if (!ParseDouble(tokens[i], &value) || !std::isfinite(value)) {
        throw ParseError::AtLine(source, line_number,
                                 "field " + std::to_string(i + 1) + " (" + kFieldNames[i] + "): '" +
                                     tokens[i] + "' is not a finite number");
      }
      values.push_back(value);
    }
  }
  if (calibration_line == 0) {
    throw ParseError::AtLine(source, std::max(line_number, 1),
                             "no calibration line 'fx fy cx cy k1 k2 p1 p2 k3'");
  }
  Camera camera;
  camera.model = CameraModel::kRadialTangential;
  camera.width = width;
  camera.height = height;
  camera.fx = values[0];
  camera.fy = values[1];
  camera.cx = values[2];
  camera.cy = values[3];
  camera.distortion.assign(values.begin() + 4, values.end());
  try {
    camera.Check();
  } catch (const InvalidArgumentError& error) {
    throw ParseError::AtLine(source, calibration_line,
                             std::string("invalid camera: ") + error.what());
  }
  return camera;
}

}  // namespace evloc
