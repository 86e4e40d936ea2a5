// The time a registered pose represents (docs/tracking.md, "Pose time"). A step at time t
// registers the map against time surfaces whose freshest pixels fired before t: an edge moving at
// v px/s last fired the pixel the points settle on when it crossed that pixel, on average half a
// pixel (1 / (2 v) seconds) before t. The pose that fits the surfaces is therefore the camera's
// pose at t - age rather than at t (the estimates lagged the ground truth by 1.5-8 ms on the
// simulated sequences, docs/accuracy.md). This measures that age from the events under the
// registered points; the tracker moves the pose forward by it along its motion.
#pragma once

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/geometry/rigid3.h"
#include "localizer/tracking/registration.h"
#include "localizer/tracking/time_surface.h"

namespace evloc::tracking {

// The outcome of MeasureSurfaceAge.
struct SurfaceAge {
  // The weighted median age, nanoseconds (0 when no point contributed).
  int64_t age_ns = 0;
  // Points that contributed: their pixel was active and they move in the image.
  int points = 0;
};

// The age at `t_ns` of the events that `indices` of `positions` (world points) were registered
// to at `cam_from_world`: for each point, the bilinear blend (at its projection) of the ages of
// the last events in `channel` of the active pixels (under `decay`) of its cell, as the field's
// bilinear sample blends their values; a point whose cell has less than a quarter of its weight
// on active pixels does not count. The result is the median
// of those ages weighted by the squared image speed of each point under `velocity` (the
// body-frame twist of world_from_cam per second, ConstantVelocityModel): a point that does not
// move in the image says nothing about time, and a fast one pins it most precisely. The median
// rather than the mean: points left on an old edge or on noise report ages up to the whole
// decay window. `scratch` holds (age, weight) pairs between calls.
SurfaceAge MeasureSurfaceAge(const TimeSurface& surface, SurfaceChannel channel,
                             const SurfaceDecay& decay, int64_t t_ns,
                             const PinholeIntrinsics& intrinsics, const Rigid3d& cam_from_world,
                             const Vector6d& velocity, std::span<const Eigen::Vector3f> positions,
                             std::span<const uint32_t> indices,
                             std::vector<std::pair<int64_t, double>>* scratch);

// The weighted median of `samples` (value, weight > 0): the smallest value whose cumulative
// weight, over the samples sorted by value, reaches half the total. Reorders `samples`;
// expected linear time. 0 for no samples.
int64_t WeightedMedian(std::vector<std::pair<int64_t, double>>* samples);

}  // namespace evloc::tracking
