// Synthetic maps with known geometry, for tests, benchmarks and demos: edge points on the walls,
// floor and ceiling of a straight corridor, and keyframes walking down its axis.
#pragma once

#include <cstddef>
#include <cstdint>

#include "core/camera/camera.h"
#include "maps/map.h"

namespace evloc {

// Shape and size of a synthetic corridor map.
struct CorridorMapOptions {
  // Number of points.
  size_t num_points = 10000;
  // Number of keyframes, evenly spaced along the corridor; 0 gives a map without keyframes.
  size_t num_keyframes = 10;
  // Corridor length along the world x axis, metres (points have x in [0, length]).
  double length_m = 20.0;
  // Corridor width along y, metres (walls at y = +-width/2).
  double width_m = 2.0;
  // Corridor height along z, metres (floor at z = -height/2, ceiling at +height/2).
  double height_m = 2.5;
  // Keyframes list the points within this depth of them (and inside their image), metres.
  double keyframe_visibility_depth_m = 5.0;
  // Camera of every keyframe.
  Camera camera = Camera::Pinhole(640, 480, 320.0, 320.0, 319.5, 239.5);
  // Seed of the pseudo-random generator: equal options give equal maps.
  uint32_t seed = 1;

  // Throws InvalidArgumentError unless the sizes are finite and > 0, num_points fits 32-bit
  // indices, and the camera is valid.
  void Check() const;
};

// Builds a corridor map: points uniformly on the four faces, each with a unit gradient tangent to
// its face, an inverse-depth sigma and gradient magnitude, and (with keyframes) the nearest
// keyframe that sees it as source; keyframes at x = (k + 0.5) * length / num_keyframes on the
// axis, looking down +x, listing the points they see. Throws InvalidArgumentError for invalid
// options.
Map MakeCorridorMap(const CorridorMapOptions& options);

// The pose world_from_cam of a camera on the corridor axis at `x_m` looking down +x (camera z
// along world +x, camera y along world -z, so that "down" in the image is the floor).
Rigid3d CorridorCameraPose(double x_m);

}  // namespace evloc
