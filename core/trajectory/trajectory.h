// A camera trajectory: poses world_from_cam at strictly increasing times, with interpolation.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "core/geometry/rigid3.h"

namespace evloc {

// One pose of a trajectory: where the camera was at time t_ns.
struct TimedPose {
  // Time, nanoseconds (the clock of the source: sensor, simulator or ground truth).
  int64_t t_ns = 0;
  // Camera pose: maps camera coordinates to world (map) coordinates.
  Rigid3d world_from_cam;
};

// A sequence of poses at strictly increasing times. Poses between samples are interpolated with
// Interpolate() from core/geometry (slerp of rotation, linear translation).
class Trajectory {
 public:
  // An empty trajectory.
  Trajectory() = default;
  // Takes `poses`; throws InvalidArgumentError unless their times strictly increase and every
  // pose is finite.
  explicit Trajectory(std::vector<TimedPose> poses);

  // The samples, in time order.
  const std::vector<TimedPose>& poses() const { return poses_; }
  // Appends a sample; throws InvalidArgumentError unless pose.t_ns > end_ns() and it is finite.
  void Append(const TimedPose& pose);

  // Number of samples.
  size_t size() const { return poses_.size(); }
  // True when there are no samples.
  bool empty() const { return poses_.empty(); }
  // Time of the first sample; throws InvalidArgumentError when empty.
  int64_t start_ns() const;
  // Time of the last sample; throws InvalidArgumentError when empty.
  int64_t end_ns() const;
  // Duration end_ns() - start_ns(), 0 when empty.
  int64_t duration_ns() const;

  // The pose at t_ns, interpolated between the two samples around it (exactly a sample's pose at
  // its time); std::nullopt outside [start_ns(), end_ns()] or when empty.
  std::optional<Rigid3d> Lookup(int64_t t_ns) const;

  // The velocity at t_ns as a constant-velocity motion model measures it: the body-frame twist
  // per second (linear m/s, angular rad/s) of world_from_cam over the `window_ns` before t_ns,
  // world_from_cam(t) = world_from_cam(t - window) * ExpSE3(window * twist); over the window
  // after t_ns when the trajectory starts less than a window before it. std::nullopt when the
  // trajectory does not span a window around t_ns; throws InvalidArgumentError unless
  // window_ns > 0.
  std::optional<Vector6d> Velocity(int64_t t_ns, int64_t window_ns) const;

  // Index of the last sample with time <= t_ns; std::nullopt when t_ns < start_ns() or empty.
  std::optional<size_t> IndexAtOrBefore(int64_t t_ns) const;

 private:
  std::vector<TimedPose> poses_;
};

}  // namespace evloc
