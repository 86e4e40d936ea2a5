// A per-pixel look-up table that undistorts events in O(1): built once per camera (per session),
// it stores for every integer sensor pixel the undistorted normalised coordinates and the pixel in
// the ideal pinhole camera with the same fx fy cx cy. See docs/camera.md, "Undistortion table".
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/camera/camera.h"

namespace evloc {

// Undistorts integer sensor pixels by table look-up.
class UndistortionTable {
 public:
  // One sensor pixel's undistortion.
  struct Entry {
    // Undistorted normalised coordinates (x/z, y/z) of the pixel's ray.
    Eigen::Vector2f normalized = Eigen::Vector2f::Zero();
    // The same ray as a pixel of the ideal pinhole camera (fx * x/z + cx, fy * y/z + cy); it may
    // lie outside the sensor for strong barrel distortion.
    Eigen::Vector2f ideal_pixel = Eigen::Vector2f::Zero();
    // False when Camera::Unproject fails for this pixel; the coordinates are then zero.
    bool valid = false;
  };

  // Builds the table for every pixel of `camera` (which must pass Check(), else
  // InvalidArgumentError). Costs width * height Newton undistortions. With `binning` b > 1 the
  // ideal pinhole camera is the sensor's binned b x b: ceil(width / b) x ceil(height / b) pixels,
  // focal lengths f / b and principal point (c + 0.5) / b - 0.5, so that each ideal pixel is the
  // centre of a block of b x b sensor pixels (an HD sensor tracked on a coarser image,
  // docs/tracking.md, "Binning"). InvalidArgumentError for b outside 1..8.
  explicit UndistortionTable(const Camera& camera, int binning = 1);

  // The ideal pinhole camera of `camera` binned `binning` x `binning` (the constructor's;
  // InvalidArgumentError for a binning outside 1..8). Without building a table.
  static Camera BinnedIdealCamera(const Camera& camera, int binning);

  // Calls visit(x, y, normalized, ideal_pixel) for every sensor pixel of `camera` whose ray
  // Camera::Unproject finds, in row-major order, with the float values an Entry of a table of
  // `camera` and ideal camera `ideal` holds (Eigen::Vector2f each), without storing them (the
  // tracker's surface needs one look-up per pixel, not the 20-byte entries). `camera` must pass
  // Check().
  template <typename Visit>
  static void ForEachPixel(const Camera& camera, const Camera& ideal, Visit&& visit) {
    for (int y = 0; y < camera.height; ++y) {
      for (int x = 0; x < camera.width; ++x) {
        Eigen::Vector3d ray;
        if (!camera.Unproject(Eigen::Vector2d(x, y), &ray)) continue;
        visit(x, y, Eigen::Vector2f(static_cast<float>(ray.x()), static_cast<float>(ray.y())),
              Eigen::Vector2f(static_cast<float>(ideal.fx * ray.x() + ideal.cx),
                              static_cast<float>(ideal.fy * ray.y() + ideal.cy)));
      }
    }
  }

  // The camera the table was built for.
  const Camera& camera() const { return camera_; }
  // The ideal pinhole camera of ideal_pixel (same size, fx, fy, cx, cy; binned when binning > 1).
  const Camera& ideal_camera() const { return ideal_camera_; }
  // The binning the table was built with (1: none).
  int binning() const { return binning_; }
  // Sensor width, pixels.
  int width() const { return camera_.width; }
  // Sensor height, pixels.
  int height() const { return camera_.height; }
  // Number of pixels whose entry is valid.
  int num_valid() const { return num_valid_; }

  // True when (x, y) is a sensor pixel: 0 <= x < width and 0 <= y < height.
  bool Contains(int x, int y) const {
    return x >= 0 && y >= 0 && x < camera_.width && y < camera_.height;
  }

  // The entry of sensor pixel (x, y); the caller guarantees Contains(x, y) (asserted).
  const Entry& At(int x, int y) const;

  // The entry of pixel (x, y), or nullptr when the pixel is outside the sensor or its entry is
  // not valid.
  const Entry* Find(int x, int y) const {
    if (!Contains(x, y)) return nullptr;
    const Entry& entry = entries_[static_cast<size_t>(y) * camera_.width + x];
    return entry.valid ? &entry : nullptr;
  }

 private:
  Camera camera_;
  Camera ideal_camera_;
  int binning_ = 1;
  // Row-major, width * height entries.
  std::vector<Entry> entries_;
  int num_valid_ = 0;
};

}  // namespace evloc
