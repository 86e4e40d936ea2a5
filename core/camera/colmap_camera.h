// COLMAP cameras (one line of cameras.txt) and their one conversion to and from evloc cameras,
// shared by the mapper's COLMAP models (mapper/colmap_model.h) and the --calib reader
// (calibration_file.h).
// COLMAP places the centre of the top-left pixel at (0.5, 0.5); evloc places it at (0, 0). The
// converters here shift principal points by 0.5 so that every camera leaving this file follows
// the evloc convention (docs/camera.md, "COLMAP cameras.txt").
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "core/camera/camera.h"

namespace evloc {

// COLMAP's pixel convention minus evloc's: COLMAP places the top-left pixel centre at 0.5.
inline constexpr double kColmapPixelOffset = 0.5;

// One camera of cameras.txt, in COLMAP's own parameterisation and pixel convention.
struct ColmapCamera {
  // COLMAP camera id.
  uint32_t camera_id = 0;
  // COLMAP model name, e.g. "PINHOLE", "OPENCV", "SIMPLE_RADIAL".
  std::string model_name;
  // Image width, pixels.
  int width = 0;
  // Image height, pixels.
  int height = 0;
  // Model parameters in COLMAP order (principal point with top-left pixel centre at 0.5).
  std::vector<double> params;
};

// Parses cameras.txt text: one camera per line `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`, `#`
// comments and blank lines skipped, CRLF accepted. The parameters are not checked against the
// model (CameraFromColmap does). Throws ParseError naming `source` and the line for a malformed
// line, a non-finite number or a duplicate id.
std::map<uint32_t, ColmapCamera> ParseColmapCameras(const std::string& text,
                                                    const std::string& source);

// The evloc camera of a COLMAP camera. Supported models (exactly representable): SIMPLE_PINHOLE,
// PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV (with k4 = k5 = k6 = 0) and OPENCV_FISHEYE.
// Throws InvalidArgumentError for any other model (with the reason), a wrong parameter count, or
// a camera that fails Check().
Camera CameraFromColmap(const ColmapCamera& colmap_camera);

// The COLMAP camera of an evloc camera: PINHOLE, OPENCV (radtan with k3 = 0), FULL_OPENCV (radtan
// with k3 != 0) or OPENCV_FISHEYE. Throws InvalidArgumentError when the camera fails Check().
ColmapCamera ColmapCameraFromCamera(const Camera& camera, uint32_t camera_id);

}  // namespace evloc
