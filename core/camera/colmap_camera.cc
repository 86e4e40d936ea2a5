#include "core/camera/colmap_camera.h"

#include <charconv>
#include <cmath>
#include <sstream>

#include "core/camera/calibration_text.h"
#include "core/common/error.h"
#include "core/common/text_lines.h"

namespace evloc {
namespace {

// Number of parameters of each supported COLMAP model; -1 for a model evloc does not represent.
int NumColmapParams(const std::string& model_name) {
  if (model_name == "SIMPLE_PINHOLE") return 3;
  if (model_name == "PINHOLE") return 4;
  if (model_name == "SIMPLE_RADIAL") return 4;
  if (model_name == "RADIAL") return 5;
  if (model_name == "OPENCV") return 8;
  if (model_name == "FULL_OPENCV") return 12;
  if (model_name == "OPENCV_FISHEYE") return 8;
  return -1;
}

// Why a COLMAP model that evloc does not read cannot be represented by evloc's camera models.
std::string UnsupportedColmapModelReason(const std::string& model_name) {
  if (model_name == "SIMPLE_RADIAL_FISHEYE" || model_name == "RADIAL_FISHEYE" ||
      model_name == "THIN_PRISM_FISHEYE" || model_name == "RAD_TAN_THIN_PRISM_FISHEYE") {
    return "its fisheye polynomial or thin-prism terms differ from the equidistant model "
           "k1..k4 (use OPENCV_FISHEYE)";
  }
  if (model_name == "FOV") return "the FOV (arctan) distortion has no radtan or equidistant form";
  if (model_name == "SIMPLE_DIVISION" || model_name == "DIVISION") {
    return "the division model has no radtan or equidistant form";
  }
  return "evloc represents only pinhole, radial-tangential and equidistant lenses";
}

}  // namespace

std::map<uint32_t, ColmapCamera> ParseColmapCameras(const std::string& text,
                                                    const std::string& source) {
  std::map<uint32_t, ColmapCamera> cameras;
  ForEachDataLine(text, [&](int64_t line_number, const std::string& line) {
    std::istringstream fields(line);
    std::vector<std::string> tokens;
    for (std::string token; fields >> token;) tokens.push_back(token);
    if (tokens.size() < 4) {
      throw ParseError::AtLine(source, line_number,
                               "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got " +
                                   std::to_string(tokens.size()) + " fields");
    }
    const auto parse_integer = [&](const std::string& token, const char* field, auto* value) {
      const auto result = std::from_chars(token.data(), token.data() + token.size(), *value);
      if (result.ec != std::errc() || result.ptr != token.data() + token.size()) {
        throw ParseError::AtLine(source, line_number,
                                 std::string(field) + " '" + token + "' is not a valid integer");
      }
    };
    ColmapCamera camera;
    parse_integer(tokens[0], "CAMERA_ID", &camera.camera_id);
    camera.model_name = tokens[1];
    parse_integer(tokens[2], "WIDTH", &camera.width);
    parse_integer(tokens[3], "HEIGHT", &camera.height);
    for (size_t k = 4; k < tokens.size(); ++k) {
      double value = 0.0;
      if (!camera_text::ParseDouble(tokens[k], &value) || !std::isfinite(value)) {
        throw ParseError::AtLine(source, line_number,
                                 "PARAMS '" + tokens[k] + "' is not a finite number");
      }
      camera.params.push_back(value);
    }
    if (!cameras.emplace(camera.camera_id, camera).second) {
      throw ParseError::AtLine(source, line_number,
                               "duplicate CAMERA_ID " + std::to_string(camera.camera_id));
    }
  });
  return cameras;
}

Camera CameraFromColmap(const ColmapCamera& colmap_camera) {
  const std::string& name = colmap_camera.model_name;
  const int expected = NumColmapParams(name);
  if (expected < 0) {
    throw InvalidArgumentError("COLMAP camera model " + name +
                               " is not supported: " + UnsupportedColmapModelReason(name) +
                               " (use PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, "
                               "FULL_OPENCV or OPENCV_FISHEYE)");
  }
  const std::vector<double>& p = colmap_camera.params;
  if (static_cast<int>(p.size()) != expected) {
    throw InvalidArgumentError("COLMAP camera model " + name + " takes " +
                               std::to_string(expected) + " parameters, got " +
                               std::to_string(p.size()));
  }
  Camera camera;
  camera.width = colmap_camera.width;
  camera.height = colmap_camera.height;
  const bool single_focal = name == "SIMPLE_PINHOLE" || name == "SIMPLE_RADIAL" || name == "RADIAL";
  if (single_focal) {
    camera.fx = camera.fy = p[0];
    camera.cx = p[1] - kColmapPixelOffset;
    camera.cy = p[2] - kColmapPixelOffset;
  } else {
    camera.fx = p[0];
    camera.fy = p[1];
    camera.cx = p[2] - kColmapPixelOffset;
    camera.cy = p[3] - kColmapPixelOffset;
  }
  if (name == "SIMPLE_PINHOLE" || name == "PINHOLE") {
    camera.model = CameraModel::kPinhole;
  } else if (name == "SIMPLE_RADIAL") {
    camera.model = CameraModel::kRadialTangential;
    camera.distortion = {p[3], 0.0, 0.0, 0.0, 0.0};
  } else if (name == "RADIAL") {
    camera.model = CameraModel::kRadialTangential;
    camera.distortion = {p[3], p[4], 0.0, 0.0, 0.0};
  } else if (name == "OPENCV") {
    camera.model = CameraModel::kRadialTangential;
    camera.distortion = {p[4], p[5], p[6], p[7], 0.0};
  } else if (name == "FULL_OPENCV") {
    if (p[9] != 0.0 || p[10] != 0.0 || p[11] != 0.0) {
      throw InvalidArgumentError(
          "COLMAP FULL_OPENCV cameras with rational coefficients k4..k6 are not supported (the "
          "radtan model has no rational denominator; only k4 = k5 = k6 = 0 is exact)");
    }
    camera.model = CameraModel::kRadialTangential;
    camera.distortion = {p[4], p[5], p[6], p[7], p[8]};
  } else {
    camera.model = CameraModel::kEquidistant;
    camera.distortion = {p[4], p[5], p[6], p[7]};
  }
  camera.Check();
  return camera;
}

ColmapCamera ColmapCameraFromCamera(const Camera& camera, uint32_t camera_id) {
  camera.Check();
  ColmapCamera colmap_camera;
  colmap_camera.camera_id = camera_id;
  colmap_camera.width = camera.width;
  colmap_camera.height = camera.height;
  colmap_camera.params = {camera.fx, camera.fy, camera.cx + kColmapPixelOffset,
                          camera.cy + kColmapPixelOffset};
  const std::vector<double>& d = camera.distortion;
  switch (camera.model) {
    case CameraModel::kPinhole:
      colmap_camera.model_name = "PINHOLE";
      break;
    case CameraModel::kRadialTangential:
      if (d[4] == 0.0) {
        colmap_camera.model_name = "OPENCV";
        colmap_camera.params.insert(colmap_camera.params.end(), {d[0], d[1], d[2], d[3]});
      } else {
        colmap_camera.model_name = "FULL_OPENCV";
        colmap_camera.params.insert(colmap_camera.params.end(),
                                    {d[0], d[1], d[2], d[3], d[4], 0.0, 0.0, 0.0});
      }
      break;
    case CameraModel::kEquidistant:
      colmap_camera.model_name = "OPENCV_FISHEYE";
      colmap_camera.params.insert(colmap_camera.params.end(), {d[0], d[1], d[2], d[3]});
      break;
  }
  return colmap_camera;
}

}  // namespace evloc
