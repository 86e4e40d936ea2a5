// Test helpers for the Middlebury multi-view data (templeSparseRing): calibrated poses (the
// edge-distance measure of docs/mapper.md is KeyframeEdgeDistances in
// tools/map_accuracy/map_accuracy.h).
#pragma once

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"

namespace evloc::testing {

// One calibrated view of a Middlebury `*_par.txt` file: P = K [R | t] maps world to image.
struct MiddleburyView {
  // Image file name.
  std::string name;
  // Calibration matrix.
  Eigen::Matrix3d calibration;
  // The world-to-camera pose [R | t].
  Rigid3d cam_from_world;
};

// Reads `name k11..k33 r11..r33 t1 t2 t3` lines after the count line.
inline std::vector<MiddleburyView> ReadMiddleburyParameters(const std::filesystem::path& path) {
  std::ifstream stream(path);
  int count = 0;
  stream >> count;
  std::vector<MiddleburyView> views;
  for (int i = 0; i < count; ++i) {
    MiddleburyView view;
    stream >> view.name;
    Eigen::Matrix3d rotation;
    Eigen::Vector3d translation;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) stream >> view.calibration(r, c);
    }
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) stream >> rotation(r, c);
    }
    for (int r = 0; r < 3; ++r) stream >> translation(r);
    Matrix3x4d matrix;
    matrix << rotation, translation;
    view.cam_from_world = Rigid3d::FromMatrix(matrix);
    views.push_back(view);
  }
  return views;
}

// Writes `IMAGE_NAME tx ty tz qx qy qz qw` (world_from_cam) lines for --known-poses/--align-to.
inline void WriteNamedPoses(const std::filesystem::path& path,
                            const std::vector<MiddleburyView>& views) {
  std::ofstream stream(path);
  stream.precision(17);
  stream << "# IMAGE_NAME tx ty tz qx qy qz qw (world_from_cam)\n";
  for (const MiddleburyView& view : views) {
    const Rigid3d world_from_cam = view.cam_from_world.Inverse();
    const Eigen::Quaterniond& q = world_from_cam.rotation;
    const Eigen::Vector3d& t = world_from_cam.translation;
    stream << view.name << ' ' << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << q.x() << ' '
           << q.y() << ' ' << q.z() << ' ' << q.w() << '\n';
  }
}

// The pinhole camera of a Middlebury calibration matrix (pixel centres at integers, as the data's
// calibration uses).
inline Camera MiddleburyCamera(const MiddleburyView& view, int width, int height) {
  const Eigen::Matrix3d& k = view.calibration;
  return Camera::Pinhole(width, height, k(0, 0), k(1, 1), k(0, 2), k(1, 2));
}

}  // namespace evloc::testing
