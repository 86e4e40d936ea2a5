// The calibration files people already have, and the one reader behind every --calib flag: evloc
// YAML, ECD calib.txt, Kalibr camchain.yaml (with the rig's extrinsics), ROS camera_info YAML,
// OpenCV FileStorage YAML/XML and COLMAP cameras.txt. The format is detected from the content,
// never from the extension. What each reader takes and refuses: docs/camera.md, "Calibration
// files of other tools".
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"

namespace evloc {

// The calibration file formats evloc reads.
enum class CalibrationFormat {
  // evloc's own camera YAML (model, width, height, intrinsics, distortion).
  kEvlocYaml,
  // Event Camera Dataset calib.txt: one line fx fy cx cy k1 k2 p1 p2 k3, no image size.
  kEcdText,
  // Kalibr camchain.yaml: cam0, cam1, ... with T_cn_cnm1 extrinsics.
  kKalibrCamchain,
  // ROS camera_info YAML (camera_calibration's ost.yaml, camera_calibration_parsers).
  kRosCameraInfo,
  // OpenCV cv::FileStorage YAML (%YAML:1.0, !!opencv-matrix).
  kOpenCvYaml,
  // OpenCV cv::FileStorage XML (<opencv_storage>).
  kOpenCvXml,
  // OpenCV cv::FileStorage JSON ({"camera_matrix": {"type_id": "opencv-matrix", ...}}).
  kOpenCvJson,
  // COLMAP cameras.txt: CAMERA_ID MODEL WIDTH HEIGHT PARAMS[] per line.
  kColmapCameras,
};

// A readable name of a format, e.g. "Kalibr camchain", used in error messages.
std::string CalibrationFormatName(CalibrationFormat format);

// Detects the format of calibration text from its content: OpenCV XML ('<' first), OpenCV YAML
// (the %YAML:1.0 header, or !!opencv-matrix nodes), OpenCV JSON (type_id "opencv-matrix"), COLMAP
// (a first data line CAMERA_ID MODEL
// ...), ECD (a line of numbers), else by the keys of the YAML map (camN: Kalibr; camera_matrix
// with rows/cols/data: ROS; model/intrinsics: evloc). Throws ParseError naming `source` and
// listing the formats when the text looks like none of them.
CalibrationFormat DetectCalibrationFormat(const std::string& text, const std::string& source);

// A --calib value: a file with an optional camera selector after its last '#': "cam1" (or "1")
// picks a camera of a Kalibr camchain, "2" the CAMERA_ID 2 of a COLMAP cameras.txt. A value that
// names an existing file as a whole is never split.
struct CalibrationSpec {
  // The calibration file.
  std::filesystem::path path;
  // The camera selector; empty: the file's default camera (Kalibr cam0, COLMAP its only camera).
  std::string camera;
};

// Splits a --calib value into its file and camera selector. Throws InvalidArgumentError for an
// empty selector ("FILE#").
CalibrationSpec ParseCalibrationSpec(const std::filesystem::path& spec);

// One camera of a calibration file, with its place in the rig.
struct RigCamera {
  // The camera's name in the file: "cam0", "cam1", ... (Kalibr), the CAMERA_ID (COLMAP), the
  // camera_name (ROS) or empty.
  std::string name;
  // The intrinsics.
  Camera camera;
  // p_cam_i = cam_from_cam0 * p_cam0: identity for cam0, Kalibr's T_cn_cnm1 chained for the
  // others; std::nullopt when the file states no extrinsics for this camera (or one before it).
  std::optional<Rigid3d> cam_from_cam0;
  // The ROS topic of the camera's images (Kalibr rostopic), when the file names one.
  std::string rostopic;
};

// The cameras of a Kalibr camchain in their order cam0, cam1, ..., and what the reader ignored.
struct CameraRig {
  // cam0, cam1, ...
  std::vector<RigCamera> cameras;
  // Fields that were read but not used (imu fields, cam_overlaps, unknown keys), one sentence each.
  std::vector<std::string> notes;
};

// Parses a Kalibr camchain (camera_model pinhole with distortion_model radtan, equidistant or
// none). Throws ParseError naming `source`, the line, the camera and the key for a malformed
// file, a refused model (omni, ds, eucm, fov), cameras that are not numbered cam0..camN-1, or an
// extrinsic that is not a rigid 4x4 transform.
CameraRig ParseKalibrCamchain(const std::string& text, const std::string& source);

// Parses a ROS camera_info YAML: image_width, image_height, camera_matrix and
// distortion_coefficients ({rows, cols, data}), distortion_model plumb_bob, rational_polynomial
// (only with k4 = k5 = k6 = 0) or equidistant. Appends what it ignored to `notes` (may be null).
// Throws ParseError naming `source`, the line and the key.
Camera ParseRosCameraInfo(const std::string& text, const std::string& source,
                          std::vector<std::string>* notes);

// Parses an OpenCV FileStorage YAML, XML or JSON calibration with cv::FileStorage: camera_matrix
// (or cameraMatrix, K), distortion_coefficients (or dist_coeffs, distCoeffs, D; 4, 5, 8, 12 or 14
// coefficients with the terms beyond k3 zero; 4 with fisheye_model: 1), image_width and
// image_height (or image_size / imageSize [w, h]). A file without a size takes `width` x
// `height` when both are positive (then `*size_from_file` is set false). Throws ParseError naming
// `source` and the key.
Camera ParseOpenCvCalibration(const std::string& text, const std::string& source, int width,
                              int height, std::vector<std::string>* notes,
                              bool* size_from_file = nullptr);

// A calibration file read through the format detection.
struct Calibration {
  // The detected format.
  CalibrationFormat format = CalibrationFormat::kEvlocYaml;
  // The selected camera.
  RigCamera selected;
  // Every camera of the file (Kalibr: the rig; COLMAP: each CAMERA_ID, without extrinsics; the
  // other formats: the one camera, with cam_from_cam0 = identity).
  std::vector<RigCamera> cameras;
  // True when the file states the image size; false when it came from the caller (ECD, OpenCV
  // files without image_width/image_height).
  bool size_from_file = true;
  // What the reader ignored, one sentence each (e.g. Kalibr's imu fields).
  std::vector<std::string> notes;
};

// Parses calibration text of any format (detected), selecting `camera_selector` (see
// CalibrationSpec). `width` x `height` sizes the formats without a size (0 when unknown). Errors
// name `source`, the format it looked like, and what is wrong: ParseError for content,
// InvalidArgumentError for a selector or a missing size.
Calibration ParseCalibration(const std::string& text, const std::string& source,
                             const std::string& camera_selector, int width, int height);

// Reads the calibration file of a --calib value (FILE or FILE#camera). Throws IoError when it
// cannot be read, and as ParseCalibration.
Calibration ReadCalibration(const std::filesystem::path& spec, int width, int height);

// The reader's notes of `calibration` read from `spec`, each prefixed with the file ("FILE:
// ignored ..."), for a tool to print.
std::vector<std::string> CalibrationNotes(const std::filesystem::path& spec,
                                          const Calibration& calibration);

// The camera of a --calib value (ReadCalibration(spec, width, height).selected.camera): the
// calibration reader of every tool. `notes`, when given, receives CalibrationNotes (appended).
Camera ReadCalibrationFile(const std::filesystem::path& spec, int width, int height,
                           std::vector<std::string>* notes = nullptr);

}  // namespace evloc
