// libFuzzer target: every calibration reader behind --calib (docs/reliability.md), through the
// format detection (ParseCalibration): evloc YAML, ECD calib.txt, Kalibr camchain, ROS
// camera_info, OpenCV FileStorage YAML/XML (cv::FileStorage), COLMAP cameras.txt. The first byte
// chooses the camera selector (none, "cam1", "2") and whether an image size is known. Checks: the
// only errors are evloc's typed errors; a camera that is returned passes Check(); its rig has
// the selected camera, and every extrinsic is a finite rigid transform with a unit quaternion.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "core/camera/calibration_file.h"
#include "core/common/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  static const char* const kSelectors[] = {"", "cam1", "2", ""};
  const uint8_t control = data[0];
  const std::string selector = kSelectors[control & 3];
  const int width = (control & 4) != 0 ? 240 : 0;
  const int height = (control & 4) != 0 ? 180 : 0;
  const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
  evloc::Calibration calibration;
  try {
    calibration = evloc::ParseCalibration(text, "fuzz.calib", selector, width, height);
  } catch (const evloc::Error&) {
    return 0;
  }
  calibration.selected.camera.Check();  // throws (and so aborts the fuzzer) when invalid
  bool found = false;
  for (const evloc::RigCamera& camera : calibration.cameras) {
    camera.camera.Check();
    if (camera.name == calibration.selected.name) found = true;
    if (camera.cam_from_cam0) {
      if (!camera.cam_from_cam0->IsFinite()) std::abort();
      if (std::abs(camera.cam_from_cam0->rotation.norm() - 1.0) > 1e-9) std::abort();
    }
  }
  if (!found) std::abort();
  return 0;
}
