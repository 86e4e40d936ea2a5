// The DAVIS240C of the Event Camera Dataset snippets (their calib.txt) as an evloc camera: the
// real, strongly distorted 240x180 sensor the tests build cameras from (the simulator's
// `davis240` preset, tools/sim, is the same calibration).
#pragma once

#include "core/camera/camera.h"

namespace evloc::testing {

// Radial-tangential, 240x180, k3 = 0.
inline Camera EcdDavis240Camera() {
  Camera camera =
      Camera::Pinhole(240, 180, 199.092366542, 198.82882047, 132.192071378, 110.712660011);
  camera.model = CameraModel::kRadialTangential;
  camera.distortion = {-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241,
                       0.0};
  return camera;
}

}  // namespace evloc::testing
