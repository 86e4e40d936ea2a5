#include "core/trajectory/trajectory.h"

#include <algorithm>
#include <string>
#include <utility>

#include "core/common/error.h"

namespace evloc {
namespace {

void CheckFinite(const TimedPose& pose) {
  if (!pose.world_from_cam.IsFinite()) {
    throw InvalidArgumentError("trajectory pose at t_ns=" + std::to_string(pose.t_ns) +
                               " has a NaN or infinite coefficient");
  }
}

}  // namespace

Trajectory::Trajectory(std::vector<TimedPose> poses) : poses_(std::move(poses)) {
  for (size_t i = 0; i < poses_.size(); ++i) {
    CheckFinite(poses_[i]);
    if (i > 0 && poses_[i].t_ns <= poses_[i - 1].t_ns) {
      throw InvalidArgumentError("trajectory times must strictly increase: pose " +
                                 std::to_string(i) + " at t_ns=" + std::to_string(poses_[i].t_ns) +
                                 " follows t_ns=" + std::to_string(poses_[i - 1].t_ns));
    }
  }
}

void Trajectory::Append(const TimedPose& pose) {
  CheckFinite(pose);
  if (!poses_.empty() && pose.t_ns <= poses_.back().t_ns) {
    throw InvalidArgumentError(
        "trajectory times must strictly increase: appending t_ns=" + std::to_string(pose.t_ns) +
        " after t_ns=" + std::to_string(poses_.back().t_ns));
  }
  poses_.push_back(pose);
}

int64_t Trajectory::start_ns() const {
  if (poses_.empty()) throw InvalidArgumentError("start_ns() of an empty trajectory");
  return poses_.front().t_ns;
}

int64_t Trajectory::end_ns() const {
  if (poses_.empty()) throw InvalidArgumentError("end_ns() of an empty trajectory");
  return poses_.back().t_ns;
}

int64_t Trajectory::duration_ns() const {
  return poses_.empty() ? 0 : poses_.back().t_ns - poses_.front().t_ns;
}

std::optional<size_t> Trajectory::IndexAtOrBefore(int64_t t_ns) const {
  const auto after =
      std::upper_bound(poses_.begin(), poses_.end(), t_ns,
                       [](int64_t time, const TimedPose& pose) { return time < pose.t_ns; });
  if (after == poses_.begin()) return std::nullopt;
  return static_cast<size_t>(after - poses_.begin()) - 1;
}

std::optional<Rigid3d> Trajectory::Lookup(int64_t t_ns) const {
  if (poses_.empty() || t_ns < poses_.front().t_ns || t_ns > poses_.back().t_ns) {
    return std::nullopt;
  }
  const size_t before = *IndexAtOrBefore(t_ns);
  const TimedPose& a = poses_[before];
  if (a.t_ns == t_ns) return a.world_from_cam;
  const TimedPose& b = poses_[before + 1];
  // Differences of int64 times are exact; the ratio is the only rounding.
  const double alpha = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  return Interpolate(a.world_from_cam, b.world_from_cam, alpha);
}

std::optional<Vector6d> Trajectory::Velocity(int64_t t_ns, int64_t window_ns) const {
  if (window_ns <= 0) {
    throw InvalidArgumentError("Trajectory::Velocity: the window must be positive, got " +
                               std::to_string(window_ns) + " ns");
  }
  if (poses_.empty()) return std::nullopt;
  // The window before t_ns, or after it near the start (a session that starts with the data).
  const int64_t begin_ns = t_ns - window_ns >= poses_.front().t_ns ? t_ns - window_ns : t_ns;
  const std::optional<Rigid3d> begin = Lookup(begin_ns);
  const std::optional<Rigid3d> end = Lookup(begin_ns + window_ns);
  if (!begin || !end) return std::nullopt;
  return LogSE3(begin->Inverse() * *end) / (static_cast<double>(window_ns) * 1e-9);
}

}  // namespace evloc
