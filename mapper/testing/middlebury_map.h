// Test helper: a map with no points whose keyframes are calibrated Middlebury views (pose, image
// name, one pinhole camera from the first view's calibration).
#pragma once

#include <vector>

#include "core/dataset/testing/middlebury.h"
#include "maps/map.h"

namespace evloc::testing {

// The keyframes of `views` (their poses and image names) with one width x height pinhole camera
// from the first view's calibration matrix; no points.
inline Map MiddleburyKeyframeMap(const std::vector<MiddleburyView>& views, int width = 640,
                                 int height = 480) {
  Map map;
  const Eigen::Matrix3d& k = views.at(0).calibration;
  map.cameras.push_back(Camera::Pinhole(width, height, k(0, 0), k(1, 1), k(0, 2), k(1, 2)));
  for (const MiddleburyView& view : views) {
    Keyframe keyframe;
    keyframe.cam_from_world = view.cam_from_world;
    keyframe.image_name = view.name;
    map.keyframes.push_back(keyframe);
  }
  return map;
}

}  // namespace evloc::testing
