#include "core/camera/undistortion_table.h"

#include <cassert>

namespace evloc {

UndistortionTable::UndistortionTable(const Camera& camera)
    : camera_(camera), ideal_camera_(camera.IdealPinhole()) {
  camera_.Check();
  entries_.resize(static_cast<size_t>(camera_.width) * camera_.height);
  for (int y = 0; y < camera_.height; ++y) {
    for (int x = 0; x < camera_.width; ++x) {
      Entry& entry = entries_[static_cast<size_t>(y) * camera_.width + x];
      Eigen::Vector3d ray;
      if (!camera_.Unproject(Eigen::Vector2d(x, y), &ray)) continue;
      entry.normalized = Eigen::Vector2f(static_cast<float>(ray.x()), static_cast<float>(ray.y()));
      entry.ideal_pixel = Eigen::Vector2f(static_cast<float>(camera_.fx * ray.x() + camera_.cx),
                                          static_cast<float>(camera_.fy * ray.y() + camera_.cy));
      entry.valid = true;
      ++num_valid_;
    }
  }
}

const UndistortionTable::Entry& UndistortionTable::At(int x, int y) const {
  assert(Contains(x, y));
  return entries_[static_cast<size_t>(y) * camera_.width + x];
}

}  // namespace evloc
