#include "core/camera/undistortion_table.h"

#include <cassert>
#include <string>

#include "core/common/error.h"

namespace evloc {

Camera UndistortionTable::BinnedIdealCamera(const Camera& camera, int binning) {
  if (binning < 1 || binning > 8) {
    throw InvalidArgumentError("UndistortionTable: binning must be 1 to 8, got " +
                               std::to_string(binning) + ".");
  }
  if (binning == 1) return camera.IdealPinhole();
  const double b = binning;
  return Camera::Pinhole((camera.width + binning - 1) / binning,
                         (camera.height + binning - 1) / binning, camera.fx / b, camera.fy / b,
                         (camera.cx + 0.5) / b - 0.5, (camera.cy + 0.5) / b - 0.5);
}

UndistortionTable::UndistortionTable(const Camera& camera, int binning)
    : camera_(camera), ideal_camera_(BinnedIdealCamera(camera, binning)), binning_(binning) {
  camera_.Check();
  entries_.resize(static_cast<size_t>(camera_.width) * camera_.height);
  ForEachPixel(
      camera_, ideal_camera_,
      [this](int x, int y, const Eigen::Vector2f& normalized, const Eigen::Vector2f& ideal_pixel) {
        Entry& entry = entries_[static_cast<size_t>(y) * camera_.width + x];
        entry.normalized = normalized;
        entry.ideal_pixel = ideal_pixel;
        entry.valid = true;
        ++num_valid_;
      });
}

const UndistortionTable::Entry& UndistortionTable::At(int x, int y) const {
  assert(Contains(x, y));
  return entries_[static_cast<size_t>(y) * camera_.width + x];
}

}  // namespace evloc
