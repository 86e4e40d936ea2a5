#include "maps/synthetic_map.h"

#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "core/common/error.h"
#include "maps/visibility.h"

namespace evloc {

void CorridorMapOptions::Check() const {
  for (const auto& [value, name] :
       {std::pair{length_m, "length_m"}, std::pair{width_m, "width_m"},
        std::pair{height_m, "height_m"},
        std::pair{keyframe_visibility_depth_m, "keyframe_visibility_depth_m"}}) {
    if (!std::isfinite(value) || value <= 0.0) {
      throw InvalidArgumentError(std::string("corridor map ") + name + " must be finite and > 0");
    }
  }
  if (num_points >= kNoKeyframe) {
    throw InvalidArgumentError("corridor map num_points must be below 2^32 - 1");
  }
  camera.Check();
}

Rigid3d CorridorCameraPose(double x_m) {
  Eigen::Matrix3d world_from_cam_rotation;
  // Columns: camera x (right) = world -y, camera y (down) = world -z, camera z (forward) = +x.
  world_from_cam_rotation.col(0) = -Eigen::Vector3d::UnitY();
  world_from_cam_rotation.col(1) = -Eigen::Vector3d::UnitZ();
  world_from_cam_rotation.col(2) = Eigen::Vector3d::UnitX();
  return Rigid3d(Eigen::Quaterniond(world_from_cam_rotation), Eigen::Vector3d(x_m, 0.0, 0.0));
}

Map MakeCorridorMap(const CorridorMapOptions& options) {
  options.Check();
  std::mt19937 random(options.seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const float length = static_cast<float>(options.length_m);
  const float half_width = static_cast<float>(options.width_m / 2);
  const float half_height = static_cast<float>(options.height_m / 2);

  Map map;
  map.Reserve(options.num_points);
  for (size_t i = 0; i < options.num_points; ++i) {
    // Face 0, 1: walls y = -+half_width; face 2, 3: floor and ceiling z = -+half_height.
    const int face = static_cast<int>(i % 4);
    const float x = unit(random) * length;
    const float across = 2.0f * unit(random) - 1.0f;
    const float angle = unit(random) * 6.2831853f;
    Eigen::Vector3f position, gradient;
    if (face < 2) {
      position = {x, face == 0 ? -half_width : half_width, across * half_height};
      gradient = {std::cos(angle), 0.0f, std::sin(angle)};
    } else {
      position = {x, across * half_width, face == 2 ? -half_height : half_height};
      gradient = {std::cos(angle), std::sin(angle), 0.0f};
    }
    map.AddPoint(position, gradient, 0.01f + 0.05f * unit(random), 0.1f + unit(random));
  }
  if (options.num_keyframes == 0) return map;

  map.cameras.push_back(options.camera);
  VisibilityQueryOptions query;
  query.max_depth_m = options.keyframe_visibility_depth_m;
  const VisibilityIndex index(map);
  std::vector<double> source_depth(map.size(), std::numeric_limits<double>::infinity());
  for (size_t k = 0; k < options.num_keyframes; ++k) {
    const double x = (static_cast<double>(k) + 0.5) * options.length_m /
                     static_cast<double>(options.num_keyframes);
    const Rigid3d world_from_cam = CorridorCameraPose(x);
    Keyframe keyframe;
    keyframe.cam_from_world = world_from_cam.Inverse();
    keyframe.t_ns = static_cast<int64_t>(k) * 100'000'000;  // 10 keyframes per second
    keyframe.image_name = "frame_" + std::to_string(k) + ".png";
    keyframe.visible_points = index.Query(options.camera, world_from_cam, query);
    for (const uint32_t point : keyframe.visible_points) {
      const double depth = map.positions[point].x() - x;
      if (depth < source_depth[point]) {
        source_depth[point] = depth;
        map.source_keyframe[point] = static_cast<uint32_t>(k);
      }
    }
    map.keyframes.push_back(std::move(keyframe));
  }
  return map;
}

}  // namespace evloc
