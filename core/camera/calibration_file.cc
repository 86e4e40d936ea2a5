#include "core/camera/calibration_file.h"

#include <yaml-cpp/yaml.h>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cmath>
#include <cstdint>
#include <set>
#include <sstream>

#include "core/camera/calibration_text.h"
#include "core/camera/colmap_camera.h"
#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc {
namespace {

using camera_text::FormatDouble;
using camera_text::ParseDouble;
using camera_text::ToLower;

// A rotation block of a Kalibr extrinsic may differ from a rotation by this much (Kalibr writes
// about 8 significant digits; a wrong matrix differs by far more).
constexpr double kRotationTolerance = 1e-6;
// Largest side of a matrix read from an OpenCV file (a camera matrix is 3x3, distortion 14x1).
constexpr int kMaxMatrixSide = 16;
// Formats documented in the error of an undetected file.
constexpr char kKnownFormats[] =
    "expected one of: an evloc camera YAML (model, width, height, intrinsics, distortion), a "
    "Kalibr camchain (cam0: camera_model, intrinsics, ...), a ROS camera_info YAML "
    "(camera_matrix: {rows, cols, data}), an OpenCV FileStorage YAML (%YAML:1.0) or XML "
    "(<opencv_storage>), a COLMAP cameras.txt (CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]) or an ECD "
    "calib.txt (fx fy cx cy k1 k2 p1 p2 k3); see docs/camera.md";

// The source as errors name it: the file and the format it was read as.
std::string Label(const std::string& source, CalibrationFormat format) {
  return source + " (" + CalibrationFormatName(format) + ")";
}

int LineOf(const YAML::Node& node) { return node.Mark().line + 1; }

// Helpers that read typed values from a YAML map and throw ParseErrors naming the key.
class YamlFields {
 public:
  YamlFields(std::string source, std::string context)
      : source_(std::move(source)), context_(std::move(context)) {}

  [[noreturn]] void Fail(const YAML::Node& node, const std::string& key,
                         const std::string& what) const {
    throw ParseError::AtLine(source_, node.IsDefined() ? LineOf(node) : 1,
                             context_ + "key '" + key + "': " + what);
  }

  YAML::Node Require(const YAML::Node& map, const std::string& key) const {
    const YAML::Node node = map[key];
    if (!node.IsDefined() || node.IsNull()) {
      throw ParseError::AtLine(source_, LineOf(map), context_ + "missing key '" + key + "'");
    }
    return node;
  }

  double Number(const YAML::Node& node, const std::string& key) const {
    double value = 0;
    if (!node.IsScalar() || !ParseDouble(node.Scalar(), &value) || !std::isfinite(value)) {
      Fail(node, key, "expected a finite number");
    }
    return value;
  }

  int Integer(const YAML::Node& node, const std::string& key) const {
    const double value = Number(node, key);
    if (value != std::floor(value) || std::abs(value) > 1e9) Fail(node, key, "expected an integer");
    return static_cast<int>(value);
  }

  std::vector<double> Numbers(const YAML::Node& node, const std::string& key) const {
    if (!node.IsSequence()) Fail(node, key, "expected a sequence of numbers");
    std::vector<double> values;
    for (size_t i = 0; i < node.size(); ++i) {
      values.push_back(Number(node[i], key + "[" + std::to_string(i) + "]"));
    }
    return values;
  }

  std::string Text(const YAML::Node& node, const std::string& key) const {
    if (!node.IsScalar()) Fail(node, key, "expected a name");
    return node.Scalar();
  }

 private:
  std::string source_;
  std::string context_;
};

YAML::Node LoadYamlMap(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& error) {
    throw ParseError::AtLine(source, error.mark.line + 1, "invalid YAML: " + error.msg);
  }
  if (!root.IsMap()) throw ParseError::AtLine(source, 1, "expected a YAML map");
  return root;
}

// Calibration files are text: a NUL byte means a binary or damaged file. (OpenCV 4.6's XML parser
// dereferences a null pointer on some inputs with NUL bytes: found by the fuzzer.)
void CheckNoNulByte(const std::string& text, const std::string& source) {
  const size_t nul = text.find('\0');
  if (nul != std::string::npos) {
    throw ParseError::AtByte(source, nul, "a NUL byte: a calibration file is text");
  }
}

// Checks a camera built by a reader; a failure becomes a ParseError at `line`.
void CheckCamera(const Camera& camera, const std::string& source, int line,
                 const std::string& context) {
  try {
    camera.Check();
  } catch (const InvalidArgumentError& error) {
    throw ParseError::AtLine(source, line, context + "invalid camera: " + error.what());
  }
}

bool IsInteger(const std::string& token) {
  if (token.empty() || token.size() > 10) return false;
  return std::all_of(token.begin(), token.end(), [](unsigned char c) { return std::isdigit(c); });
}

// The index N of a Kalibr camera key "camN" (1 to 4 digits); -1 for any other key.
int KalibrCameraIndex(const std::string& key) {
  if (key.size() < 4 || key.size() > 7 || key.compare(0, 3, "cam") != 0) return -1;
  if (!IsInteger(key.substr(3))) return -1;
  return std::stoi(key.substr(3));
}

bool IsColmapModelName(const std::string& token) {
  return !token.empty() && std::isupper(static_cast<unsigned char>(token[0])) &&
         std::all_of(token.begin(), token.end(), [](unsigned char c) {
           return std::isupper(c) || std::isdigit(c) || c == '_';
         });
}

// The tag yaml-cpp gives OpenCV's `!!opencv-matrix` nodes.
bool IsOpenCvMatrix(const YAML::Node& node) {
  return node.IsDefined() && node.Tag().find("opencv-matrix") != std::string::npos;
}

// An OpenCV FileStorage JSON matrix: {"type_id": "opencv-matrix", ...}.
bool IsOpenCvJsonMatrix(const YAML::Node& node) {
  if (!node.IsDefined() || !node.IsMap()) return false;
  const YAML::Node type = node["type_id"];
  return type.IsDefined() && type.IsScalar() && type.Scalar() == "opencv-matrix";
}

// Kalibr -----------------------------------------------------------------------------------------

// A Kalibr 4x4 extrinsic as a rigid transform; ParseError when it is not one.
Rigid3d ReadKalibrTransform(const YAML::Node& node, const std::string& key,
                            const YamlFields& fields) {
  if (!node.IsSequence() || node.size() != 4) {
    fields.Fail(node, key, "expected a 4x4 matrix (4 rows of 4 numbers)");
  }
  Eigen::Matrix4d matrix;
  for (int r = 0; r < 4; ++r) {
    const std::vector<double> row = fields.Numbers(node[r], key);
    if (row.size() != 4) fields.Fail(node[r], key, "expected 4 numbers in each row");
    for (int c = 0; c < 4; ++c) matrix(r, c) = row[c];
  }
  if (matrix.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) {
    fields.Fail(node, key, "the last row must be [0, 0, 0, 1]");
  }
  const Eigen::Matrix3d rotation = matrix.topLeftCorner<3, 3>();
  const double orthogonality =
      (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(orthogonality < kRotationTolerance) || !(rotation.determinant() > 0)) {
    fields.Fail(node, key,
                "the 3x3 block is not a rotation (|R^T R - I| = " + FormatDouble(orthogonality) +
                    ", det " + FormatDouble(rotation.determinant()) + ")");
  }
  return Rigid3d(Eigen::Quaterniond(rotation).normalized(), matrix.topRightCorner<3, 1>());
}

RigCamera ReadKalibrCamera(const YAML::Node& node, const std::string& name,
                           const std::string& source, std::vector<std::string>* notes) {
  const YamlFields fields(source, name + ": ");
  if (!node.IsMap()) fields.Fail(node, name, "expected a map of camera fields");
  static const std::set<std::string> kKnown = {
      "camera_model", "intrinsics", "distortion_model", "distortion_coeffs", "resolution",
      "rostopic",     "T_cn_cnm1",  "cam_overlaps",     "T_cam_imu",         "timeshift_cam_imu"};
  for (const auto& entry : node) {
    const std::string key = entry.first.Scalar();
    if (key == "T_cam_imu" || key == "timeshift_cam_imu") {
      notes->push_back(name + ": the imu field '" + key +
                       "' is ignored (evloc uses no IMU; the camera-IMU calibration is not read)");
    } else if (kKnown.count(key) == 0) {
      notes->push_back(name + ": unknown key '" + key + "' is ignored");
    }
  }
  RigCamera rig_camera;
  rig_camera.name = name;
  Camera& camera = rig_camera.camera;
  const YAML::Node model_node = fields.Require(node, "camera_model");
  const std::string model = fields.Text(model_node, "camera_model");
  if (model != "pinhole") {
    std::string reason = "evloc's cameras are pinhole projections";
    if (model == "omni") reason = "the unified omnidirectional model (xi) is not a pinhole";
    if (model == "ds") reason = "the double-sphere model is not a pinhole";
    if (model == "eucm") reason = "the extended unified model is not a pinhole";
    fields.Fail(model_node, "camera_model",
                "'" + model + "' is not supported: " + reason +
                    "; calibrate with Kalibr's pinhole-radtan or pinhole-equi models");
  }
  const YAML::Node intrinsics_node = fields.Require(node, "intrinsics");
  const std::vector<double> intrinsics = fields.Numbers(intrinsics_node, "intrinsics");
  if (intrinsics.size() != 4) {
    fields.Fail(intrinsics_node, "intrinsics",
                "expected 4 numbers [fu, fv, pu, pv] for camera_model pinhole, got " +
                    std::to_string(intrinsics.size()));
  }
  camera.fx = intrinsics[0];
  camera.fy = intrinsics[1];
  camera.cx = intrinsics[2];
  camera.cy = intrinsics[3];
  const YAML::Node distortion_model_node = fields.Require(node, "distortion_model");
  const std::string distortion_model = fields.Text(distortion_model_node, "distortion_model");
  int expected = 0;
  if (distortion_model == "radtan") {
    camera.model = CameraModel::kRadialTangential;
    expected = 4;
  } else if (distortion_model == "equidistant") {
    camera.model = CameraModel::kEquidistant;
    expected = 4;
  } else if (distortion_model == "none") {
    camera.model = CameraModel::kPinhole;
  } else {
    fields.Fail(
        distortion_model_node, "distortion_model",
        "'" + distortion_model + "' is not supported" +
            (distortion_model == "fov" ? " (the FOV model has no radtan or equidistant form)"
                                       : std::string()) +
            "; use radtan, equidistant or none");
  }
  const YAML::Node coefficients_node = node["distortion_coeffs"];
  std::vector<double> coefficients;
  if (coefficients_node.IsDefined() && !coefficients_node.IsNull()) {
    coefficients = fields.Numbers(coefficients_node, "distortion_coeffs");
  } else if (expected > 0) {
    fields.Require(node, "distortion_coeffs");
  }
  if (static_cast<int>(coefficients.size()) != expected) {
    fields.Fail(coefficients_node.IsDefined() ? coefficients_node : node, "distortion_coeffs",
                "distortion_model " + distortion_model + " takes " + std::to_string(expected) +
                    " coefficients, got " + std::to_string(coefficients.size()));
  }
  camera.distortion = coefficients;
  // Kalibr's radtan is [k1, k2, r1, r2]: OpenCV's plumb_bob with k3 = 0.
  if (camera.model == CameraModel::kRadialTangential) camera.distortion.push_back(0.0);
  const YAML::Node resolution_node = fields.Require(node, "resolution");
  if (!resolution_node.IsSequence() || resolution_node.size() != 2) {
    fields.Fail(resolution_node, "resolution", "expected [width, height]");
  }
  camera.width = fields.Integer(resolution_node[0], "resolution");
  camera.height = fields.Integer(resolution_node[1], "resolution");
  CheckCamera(camera, source, LineOf(node), name + ": ");
  const YAML::Node topic = node["rostopic"];
  if (topic.IsDefined() && topic.IsScalar()) rig_camera.rostopic = topic.Scalar();
  return rig_camera;
}

// ROS camera_info ---------------------------------------------------------------------------------

// A {rows, cols, data} matrix of camera_calibration_parsers, checked against its expected shape.
std::vector<double> ReadRosMatrix(const YAML::Node& root, const std::string& key,
                                  const YamlFields& fields, int expected_rows, int expected_cols) {
  const YAML::Node node = fields.Require(root, key);
  if (!node.IsMap()) fields.Fail(node, key, "expected a map {rows, cols, data}");
  const int rows = fields.Integer(fields.Require(node, "rows"), key + ".rows");
  const int cols = fields.Integer(fields.Require(node, "cols"), key + ".cols");
  const YAML::Node data_node = fields.Require(node, "data");
  const std::vector<double> data = fields.Numbers(data_node, key + ".data");
  if (rows < 0 || cols < 0 ||
      static_cast<int64_t>(rows) * cols != static_cast<int64_t>(data.size())) {
    fields.Fail(data_node, key,
                "rows x cols = " + std::to_string(rows) + " x " + std::to_string(cols) +
                    " but data holds " + std::to_string(data.size()) + " numbers");
  }
  if ((expected_rows > 0 && rows != expected_rows) ||
      (expected_cols > 0 && cols != expected_cols)) {
    fields.Fail(node, key,
                "expected a " + std::to_string(expected_rows) + " x " +
                    std::to_string(expected_cols) + " matrix, got " + std::to_string(rows) + " x " +
                    std::to_string(cols));
  }
  return data;
}

// The camera of a 3x3 calibration matrix (row-major) without skew; `fail` reports what is wrong.
template <typename Fail>
void SetIntrinsicsFromMatrix(const std::vector<double>& k, Camera* camera, const Fail& fail) {
  if (k.size() != 9) fail("expected a 3x3 matrix, got " + std::to_string(k.size()) + " numbers");
  if (k[1] != 0.0) {
    fail("the skew K[0][1] = " + FormatDouble(k[1]) +
         " is not zero; evloc's cameras have no skew term");
  }
  if (k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0) {
    fail("expected the form [fx 0 cx; 0 fy cy; 0 0 1]");
  }
  camera->fx = k[0];
  camera->cx = k[2];
  camera->fy = k[4];
  camera->cy = k[5];
}

// Sets the radtan distortion of OpenCV's coefficient vector (k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3
// s4 [tx ty]]]]), accepting the longer forms only when every term beyond k3 is zero; an empty
// vector is a pinhole. Returns an empty string, or why the coefficients are refused.
std::string SetOpenCvDistortion(const std::vector<double>& d, Camera* camera) {
  const size_t n = d.size();
  if (n == 0) {
    camera->model = CameraModel::kPinhole;
    camera->distortion.clear();
    return "";
  }
  if (n != 4 && n != 5 && n != 8 && n != 12 && n != 14) {
    return "expected 4, 5, 8, 12 or 14 coefficients (OpenCV's k1 k2 p1 p2 [k3 [k4 k5 k6 [s1..s4 "
           "[tx ty]]]]), got " +
           std::to_string(n);
  }
  for (size_t i = 5; i < n; ++i) {
    if (d[i] != 0.0) {
      static const char* kNames[] = {"k4", "k5", "k6", "s1", "s2", "s3", "s4", "tauX", "tauY"};
      return std::string("coefficient ") + kNames[i - 5] + " = " + FormatDouble(d[i]) +
             " is not zero: the rational (k4..k6), thin-prism (s1..s4) and tilt terms have no "
             "exact form in the radtan model (k1 k2 p1 p2 k3); recalibrate without them";
    }
  }
  camera->model = CameraModel::kRadialTangential;
  camera->distortion = {d[0], d[1], d[2], d[3], n >= 5 ? d[4] : 0.0};
  return "";
}

// Parses a calibration whose format is already known; errors name `label`.
Calibration ParseDetected(CalibrationFormat format, const std::string& text,
                          const std::string& label, const std::string& selector, int width,
                          int height) {
  Calibration calibration;
  calibration.format = format;
  const auto single_camera = [&](const Camera& camera, const std::string& name) {
    if (!selector.empty()) {
      throw InvalidArgumentError(label + ": the file holds one camera; the camera selector '#" +
                                 selector +
                                 "' applies only to Kalibr camchains and COLMAP "
                                 "cameras.txt");
    }
    calibration.selected = RigCamera{name, camera, Rigid3d::Identity(), ""};
    calibration.cameras = {calibration.selected};
  };
  switch (format) {
    case CalibrationFormat::kEvlocYaml:
      single_camera(ParseCameraYaml(text, label), "");
      break;
    case CalibrationFormat::kEcdText: {
      if (width <= 0 || height <= 0) {
        throw InvalidArgumentError(
            label +
            ": an ECD calib.txt states no image size and none is known here; give the "
            "camera as a file with its size (e.g. an evloc YAML camera, docs/camera.md)");
      }
      calibration.size_from_file = false;
      single_camera(ParseEcdCalibration(text, label, width, height), "");
      break;
    }
    case CalibrationFormat::kKalibrCamchain: {
      CameraRig rig = ParseKalibrCamchain(text, label);
      calibration.notes = std::move(rig.notes);
      std::string wanted = selector.empty() ? "cam0" : selector;
      if (IsInteger(wanted)) wanted = "cam" + wanted;
      for (const RigCamera& camera : rig.cameras) {
        if (camera.name == wanted) calibration.selected = camera;
      }
      if (calibration.selected.name != wanted) {
        throw InvalidArgumentError(label + ": no camera '" + wanted + "' (the file holds cam0.." +
                                   rig.cameras.back().name + "; pick one with FILE#camN)");
      }
      calibration.cameras = std::move(rig.cameras);
      break;
    }
    case CalibrationFormat::kRosCameraInfo:
      single_camera(ParseRosCameraInfo(text, label, &calibration.notes), "");
      break;
    case CalibrationFormat::kOpenCvYaml:
    case CalibrationFormat::kOpenCvXml:
    case CalibrationFormat::kOpenCvJson: {
      single_camera(ParseOpenCvCalibration(text, label, width, height, &calibration.notes,
                                           &calibration.size_from_file),
                    "");
      break;
    }
    case CalibrationFormat::kColmapCameras: {
      const std::map<uint32_t, ColmapCamera> cameras = ParseColmapCameras(text, label);
      if (cameras.empty()) {
        throw ParseError::AtLine(label, 1,
                                 "no camera line 'CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]'");
      }
      std::string ids;
      for (const auto& entry : cameras) {
        ids += (ids.empty() ? "" : ", ") + std::to_string(entry.first);
      }
      uint32_t wanted = cameras.begin()->first;
      if (!selector.empty()) {
        const uint64_t id = IsInteger(selector) ? std::stoull(selector) : 0;
        if (!IsInteger(selector) || id > UINT32_MAX ||
            cameras.count(static_cast<uint32_t>(id)) == 0) {
          throw InvalidArgumentError(label + ": no CAMERA_ID '" + selector + "' (the file holds " +
                                     ids + "; pick one with FILE#ID)");
        }
        wanted = static_cast<uint32_t>(id);
      } else if (cameras.size() > 1) {
        throw InvalidArgumentError(label + ": the file holds " + std::to_string(cameras.size()) +
                                   " cameras (CAMERA_ID " + ids + "); pick one with FILE#ID");
      }
      for (const auto& [id, colmap_camera] : cameras) {
        RigCamera camera;
        camera.name = std::to_string(id);
        try {
          camera.camera = CameraFromColmap(colmap_camera);
        } catch (const InvalidArgumentError& error) {
          // Only the selected camera must be representable; the others are listed when they are.
          if (id == wanted) {
            throw ParseError(label, "CAMERA_ID " + std::to_string(id), error.what());
          }
          calibration.notes.push_back("CAMERA_ID " + std::to_string(id) +
                                      " is skipped: " + error.what());
          continue;
        }
        if (id == wanted) calibration.selected = camera;
        calibration.cameras.push_back(camera);
      }
      break;
    }
  }
  return calibration;
}

}  // namespace

std::string CalibrationFormatName(CalibrationFormat format) {
  switch (format) {
    case CalibrationFormat::kEvlocYaml:
      return "evloc camera YAML";
    case CalibrationFormat::kEcdText:
      return "ECD calib.txt";
    case CalibrationFormat::kKalibrCamchain:
      return "Kalibr camchain";
    case CalibrationFormat::kRosCameraInfo:
      return "ROS camera_info YAML";
    case CalibrationFormat::kOpenCvYaml:
      return "OpenCV FileStorage YAML";
    case CalibrationFormat::kOpenCvXml:
      return "OpenCV FileStorage XML";
    case CalibrationFormat::kOpenCvJson:
      return "OpenCV FileStorage JSON";
    case CalibrationFormat::kColmapCameras:
      return "COLMAP cameras.txt";
  }
  throw InvalidArgumentError("CalibrationFormatName: unknown format value " +
                             std::to_string(static_cast<int>(format)));
}

CalibrationFormat DetectCalibrationFormat(const std::string& text, const std::string& source) {
  CheckNoNulByte(text, source);
  size_t start = text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? 3 : 0;
  start = text.find_first_not_of(" \t\r\n", start);
  if (start == std::string::npos) {
    throw ParseError::AtLine(source, 1, std::string("the file is empty; ") + kKnownFormats);
  }
  if (text[start] == '<') return CalibrationFormat::kOpenCvXml;
  if (text.compare(start, 6, "%YAML:") == 0) return CalibrationFormat::kOpenCvYaml;
  // The first data line decides between the line-based formats and YAML.
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line)) {
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#' || line[first] == '%') continue;
    if (line.find(':') != std::string::npos) break;
    std::istringstream fields(line);
    std::vector<std::string> tokens;
    for (std::string token; fields >> token;) tokens.push_back(token);
    if (tokens.size() >= 4 && IsInteger(tokens[0]) && IsColmapModelName(tokens[1])) {
      return CalibrationFormat::kColmapCameras;
    }
    double value = 0;
    if (std::all_of(tokens.begin(), tokens.end(),
                    [&](const std::string& token) { return ParseDouble(token, &value); })) {
      return CalibrationFormat::kEcdText;
    }
    break;
  }
  YAML::Node loaded;
  try {
    loaded = YAML::Load(text);
  } catch (const YAML::Exception& error) {
    throw ParseError::AtLine(
        source, error.mark.line + 1,
        "not a calibration file evloc reads (invalid YAML: " + error.msg + "); " + kKnownFormats);
  }
  const YAML::Node& root = loaded;
  if (root.IsMap()) {
    bool has_evloc_key = false;
    for (const auto& entry : root) {
      const std::string key = entry.first.IsScalar() ? entry.first.Scalar() : std::string();
      if (KalibrCameraIndex(key) >= 0 && entry.second.IsMap()) {
        return CalibrationFormat::kKalibrCamchain;
      }
      if (key == "model" || key == "intrinsics") has_evloc_key = true;
    }
    for (const char* key : {"camera_matrix", "cameraMatrix", "K", "M1"}) {
      if (IsOpenCvMatrix(root[key])) return CalibrationFormat::kOpenCvYaml;
      if (IsOpenCvJsonMatrix(root[key])) return CalibrationFormat::kOpenCvJson;
    }
    const YAML::Node camera_matrix = root["camera_matrix"];
    if (camera_matrix.IsDefined() && camera_matrix.IsMap() && camera_matrix["data"].IsDefined()) {
      return CalibrationFormat::kRosCameraInfo;
    }
    if (has_evloc_key) return CalibrationFormat::kEvlocYaml;
  }
  throw ParseError::AtLine(source, 1,
                           std::string("not a calibration file evloc reads; ") + kKnownFormats);
}

CalibrationSpec ParseCalibrationSpec(const std::filesystem::path& spec) {
  const std::string text = spec.string();
  const size_t hash = text.rfind('#');
  std::error_code error;
  if (hash == std::string::npos || std::filesystem::exists(spec, error)) return {spec, ""};
  if (hash + 1 == text.size()) {
    throw InvalidArgumentError("calibration '" + text +
                               "': empty camera selector after '#' (use FILE#cam1 for a Kalibr "
                               "camera, FILE#ID for a COLMAP camera)");
  }
  return {text.substr(0, hash), text.substr(hash + 1)};
}

CameraRig ParseKalibrCamchain(const std::string& text, const std::string& source) {
  const YAML::Node root = LoadYamlMap(text, source);
  CameraRig rig;
  std::map<int, std::pair<std::string, YAML::Node>> by_index;
  for (const auto& entry : root) {
    const std::string key = entry.first.Scalar();
    const int index = KalibrCameraIndex(key);
    if (index >= 0) {
      if (by_index.count(index) != 0) {
        throw ParseError::AtLine(source, LineOf(entry.first),
                                 "camera '" + key + "' repeats '" + by_index[index].first + "'");
      }
      by_index[index] = {key, entry.second};
    } else {
      rig.notes.push_back("top-level key '" + key + "' is ignored");
    }
  }
  if (by_index.empty()) throw ParseError::AtLine(source, 1, "no camera key cam0");
  int expected_index = 0;
  for (const auto& [index, entry] : by_index) {
    const auto& [name, node] = entry;
    if (index != expected_index) {
      throw ParseError::AtLine(source, LineOf(node),
                               "camera '" + name + "' follows cam" +
                                   std::to_string(expected_index - 1) +
                                   ": cameras must be numbered cam0, cam1, ... without gaps");
    }
    RigCamera camera = ReadKalibrCamera(node, name, source, &rig.notes);
    const YamlFields fields(source, name + ": ");
    const YAML::Node extrinsic = node["T_cn_cnm1"];
    if (index == 0) {
      if (extrinsic.IsDefined()) {
        rig.notes.push_back("cam0: T_cn_cnm1 is ignored (cam0 is the rig's reference)");
      }
      camera.cam_from_cam0 = Rigid3d::Identity();
    } else if (!extrinsic.IsDefined() || extrinsic.IsNull()) {
      rig.notes.push_back(name + ": no T_cn_cnm1, so its pose in the rig is unknown");
    } else {
      const Rigid3d cam_from_previous = ReadKalibrTransform(extrinsic, "T_cn_cnm1", fields);
      const std::optional<Rigid3d>& previous = rig.cameras.back().cam_from_cam0;
      if (previous) camera.cam_from_cam0 = cam_from_previous * *previous;
    }
    rig.cameras.push_back(std::move(camera));
    ++expected_index;
  }
  return rig;
}

Camera ParseRosCameraInfo(const std::string& text, const std::string& source,
                          std::vector<std::string>* notes) {
  std::vector<std::string> ignored;
  if (notes == nullptr) notes = &ignored;
  const YAML::Node root = LoadYamlMap(text, source);
  const YamlFields fields(source, "");
  static const std::set<std::string> kKnown = {"image_width",          "image_height",
                                               "camera_name",          "camera_matrix",
                                               "distortion_model",     "distortion_coefficients",
                                               "rectification_matrix", "projection_matrix"};
  for (const auto& entry : root) {
    const std::string key = entry.first.Scalar();
    if (kKnown.count(key) == 0) notes->push_back("unknown key '" + key + "' is ignored");
  }
  Camera camera;
  camera.width = fields.Integer(fields.Require(root, "image_width"), "image_width");
  camera.height = fields.Integer(fields.Require(root, "image_height"), "image_height");
  const std::vector<double> k = ReadRosMatrix(root, "camera_matrix", fields, 3, 3);
  SetIntrinsicsFromMatrix(k, &camera, [&](const std::string& what) {
    fields.Fail(root["camera_matrix"], "camera_matrix", what);
  });
  std::string model = "plumb_bob";
  if (root["distortion_model"].IsDefined()) {
    model = fields.Text(root["distortion_model"], "distortion_model");
  } else {
    notes->push_back(
        "no distortion_model: read as plumb_bob (camera_calibration_parsers' default)");
  }
  const std::vector<double> d = ReadRosMatrix(root, "distortion_coefficients", fields, 0, 0);
  const YAML::Node d_node = root["distortion_coefficients"];
  if (model == "plumb_bob" || model == "rational_polynomial") {
    const size_t wanted = model == "plumb_bob" ? 5 : 8;
    if (!d.empty() && d.size() != wanted && !(model == "plumb_bob" && d.size() == 4)) {
      fields.Fail(d_node, "distortion_coefficients",
                  "distortion_model " + model + " takes " + std::to_string(wanted) +
                      " coefficients, got " + std::to_string(d.size()));
    }
    const std::string refused = SetOpenCvDistortion(d, &camera);
    if (!refused.empty()) {
      fields.Fail(d_node, "distortion_coefficients", "distortion_model " + model + ": " + refused);
    }
  } else if (model == "equidistant") {
    if (d.size() != 4) {
      fields.Fail(d_node, "distortion_coefficients",
                  "distortion_model equidistant takes 4 coefficients k1..k4, got " +
                      std::to_string(d.size()));
    }
    camera.model = CameraModel::kEquidistant;
    camera.distortion = d;
  } else {
    fields.Fail(root["distortion_model"], "distortion_model",
                "'" + model +
                    "' is not supported (use plumb_bob, rational_polynomial with k4 = "
                    "k5 = k6 = 0, or equidistant)");
  }
  if (root["rectification_matrix"].IsDefined()) {
    const std::vector<double> r = ReadRosMatrix(root, "rectification_matrix", fields, 3, 3);
    if (r != std::vector<double>{1, 0, 0, 0, 1, 0, 0, 0, 1}) {
      notes->push_back(
          "rectification_matrix is not the identity (a stereo camera): evloc uses the raw "
          "camera_matrix and distortion; the rectification and projection_matrix are ignored");
    }
  }
  if (root["projection_matrix"].IsDefined()) {
    ReadRosMatrix(root, "projection_matrix", fields, 3, 4);
  }
  CheckCamera(camera, source, 1, "");
  return camera;
}

namespace {

// ParseOpenCvCalibration without the guard that turns OpenCV's exceptions into ParseErrors.
Camera ReadOpenCvCalibration(const std::string& text, const std::string& source, int width,
                             int height, std::vector<std::string>* notes, bool* size_from_file) {
  cv::FileStorage storage;
  try {
    if (!storage.open(text, cv::FileStorage::READ | cv::FileStorage::MEMORY) ||
        !storage.isOpened()) {
      throw ParseError(source, "line 1", "cv::FileStorage cannot parse it");
    }
  } catch (const cv::Exception& error) {
    throw ParseError(source, "content", "cv::FileStorage cannot parse it: " + error.err);
  }
  const cv::FileNode root = storage.root();
  if (!root.isMap()) {
    throw ParseError(source, "root", "expected a map of named values at the top level");
  }
  const auto find = [&](std::initializer_list<const char*> keys, std::string* found) {
    for (const char* key : keys) {
      const cv::FileNode node = root[key];
      if (!node.empty()) {
        *found = key;
        return node;
      }
    }
    return cv::FileNode();
  };
  const auto fail = [&](const std::string& key, const std::string& what) {
    throw ParseError(source, "key '" + key + "'", what);
  };
  const auto read_matrix = [&](const cv::FileNode& node, const std::string& key) {
    cv::Mat matrix;
    try {
      if (node.isSeq()) {
        std::vector<double> values;
        node >> values;
        matrix = cv::Mat(values, true);
      } else {
        // cv::FileNode >> cv::Mat trusts rows and cols (a garbled "cols" allocated gigabytes under
        // the fuzzer): check the matrix node before OpenCV reads it.
        if (!node.isMap() || !node["rows"].isInt() || !node["cols"].isInt() ||
            !node["dt"].isString() || !node["data"].isSeq()) {
          fail(key, "expected a matrix with rows, cols, dt and data (!!opencv-matrix)");
        }
        const int rows = node["rows"].operator int();
        const int cols = node["cols"].operator int();
        const std::string dt = node["dt"].string();
        if (rows < 0 || cols < 0 || rows > kMaxMatrixSide || cols > kMaxMatrixSide ||
            static_cast<size_t>(rows) * cols != node["data"].size()) {
          fail(key, "rows x cols = " + std::to_string(rows) + " x " + std::to_string(cols) +
                        " does not match the " + std::to_string(node["data"].size()) +
                        " numbers of data (at most " + std::to_string(kMaxMatrixSide) + " x " +
                        std::to_string(kMaxMatrixSide) + ")");
        }
        if (dt.size() != 1 || std::string("ucwsifd").find(dt[0]) == std::string::npos) {
          fail(key, "dt '" + dt + "' is not a one-channel element type (d, f, i, ...)");
        }
        node >> matrix;
      }
    } catch (const cv::Exception& error) {
      fail(key, "expected a matrix (!!opencv-matrix / type_id=\"opencv-matrix\"): " + error.err);
    }
    if (matrix.empty() && !(node.isSeq() && node.size() == 0)) {
      fail(key, "expected a matrix (!!opencv-matrix / type_id=\"opencv-matrix\")");
    }
    if (matrix.channels() != 1) fail(key, "expected a one-channel matrix");
    cv::Mat as_double;
    matrix.convertTo(as_double, CV_64F);
    std::vector<double> values(as_double.begin<double>(), as_double.end<double>());
    for (const double value : values) {
      if (!std::isfinite(value)) fail(key, "holds a number that is not finite");
    }
    return values;
  };
  const auto read_int = [&](const cv::FileNode& node, const std::string& key) {
    if (!node.isInt() && !node.isReal()) fail(key, "expected an integer");
    const double value = node.real();
    if (value != std::floor(value) || std::abs(value) > 1e9) fail(key, "expected an integer");
    return static_cast<int>(value);
  };
  Camera camera;
  std::string k_key, d_key;
  const cv::FileNode k_node = find({"camera_matrix", "cameraMatrix", "Camera_Matrix", "K"}, &k_key);
  if (k_node.empty()) {
    throw ParseError(source, "root",
                     "no camera matrix (expected a key camera_matrix, cameraMatrix or K)");
  }
  const std::vector<double> k = read_matrix(k_node, k_key);
  SetIntrinsicsFromMatrix(k, &camera, [&](const std::string& what) { fail(k_key, what); });
  const cv::FileNode d_node =
      find({"distortion_coefficients", "dist_coeffs", "distCoeffs", "Distortion_Coefficients", "D"},
           &d_key);
  if (d_node.empty()) {
    throw ParseError(source, "root",
                     "no distortion (expected a key distortion_coefficients, dist_coeffs or "
                     "distCoeffs; write an empty matrix for a pinhole camera)");
  }
  const std::vector<double> d = read_matrix(d_node, d_key);
  const cv::FileNode fisheye = root["fisheye_model"];
  if (!fisheye.empty() && read_int(fisheye, "fisheye_model") != 0) {
    if (d.size() != 4) {
      fail(d_key, "fisheye_model: 1 takes 4 coefficients k1..k4 (cv::fisheye), got " +
                      std::to_string(d.size()));
    }
    camera.model = CameraModel::kEquidistant;
    camera.distortion = d;
  } else {
    const std::string refused = SetOpenCvDistortion(d, &camera);
    if (!refused.empty()) fail(d_key, refused);
  }
  const cv::FileNode width_node = root["image_width"];
  const cv::FileNode height_node = root["image_height"];
  std::string size_key;
  const cv::FileNode size_node = find({"image_size", "imageSize"}, &size_key);
  if (!width_node.empty() || !height_node.empty()) {
    if (width_node.empty()) fail("image_width", "missing (image_height is given)");
    if (height_node.empty()) fail("image_height", "missing (image_width is given)");
    camera.width = read_int(width_node, "image_width");
    camera.height = read_int(height_node, "image_height");
  } else if (!size_node.empty()) {
    if (!size_node.isSeq() || size_node.size() != 2) fail(size_key, "expected [width, height]");
    camera.width = read_int(size_node[0], size_key);
    camera.height = read_int(size_node[1], size_key);
  } else if (width > 0 && height > 0) {
    camera.width = width;
    camera.height = height;
    if (size_from_file != nullptr) *size_from_file = false;
    notes->push_back("no image_width/image_height: the image size " + std::to_string(width) + "x" +
                     std::to_string(height) + " is taken from the input");
  } else {
    throw ParseError(source, "root",
                     "no image size (expected image_width and image_height, or image_size "
                     "[width, height])");
  }
  try {
    camera.Check();
  } catch (const InvalidArgumentError& error) {
    throw ParseError(source, "root", std::string("invalid camera: ") + error.what());
  }
  return camera;
}

}  // namespace

Camera ParseOpenCvCalibration(const std::string& text, const std::string& source, int width,
                              int height, std::vector<std::string>* notes, bool* size_from_file) {
  std::vector<std::string> ignored;
  if (notes == nullptr) notes = &ignored;
  if (size_from_file != nullptr) *size_from_file = true;
  CheckNoNulByte(text, source);
  try {
    return ReadOpenCvCalibration(text, source, width, height, notes, size_from_file);
  } catch (const cv::Exception& error) {
    // cv::FileNode asserts on unexpected node types (a sequence where a map is read, ...).
    throw ParseError(source, "content", "cv::FileStorage cannot read it: " + error.err);
  }
}

Calibration ParseCalibration(const std::string& text, const std::string& source,
                             const std::string& camera_selector, int width, int height) {
  const CalibrationFormat format = DetectCalibrationFormat(text, source);
  return ParseDetected(format, text, Label(source, format), camera_selector, width, height);
}

Calibration ReadCalibration(const std::filesystem::path& spec, int width, int height) {
  const CalibrationSpec parsed = ParseCalibrationSpec(spec);
  return ParseCalibration(ReadFileToString(parsed.path), parsed.path.string(), parsed.camera, width,
                          height);
}

std::vector<std::string> CalibrationNotes(const std::filesystem::path& spec,
                                          const Calibration& calibration) {
  const std::string file = ParseCalibrationSpec(spec).path.string();
  std::vector<std::string> notes;
  for (const std::string& note : calibration.notes) notes.push_back(file + ": " + note);
  return notes;
}

Camera ReadCalibrationFile(const std::filesystem::path& spec, int width, int height,
                           std::vector<std::string>* notes) {
  Calibration calibration = ReadCalibration(spec, width, height);
  if (notes != nullptr) {
    for (std::string& note : CalibrationNotes(spec, calibration)) notes->push_back(std::move(note));
  }
  return calibration.selected.camera;
}

}  // namespace evloc
