#include "localizer/tracking/pose_time.h"

#include <algorithm>
#include <iterator>

#include "localizer/tracking/occlusion.h"

namespace evloc::tracking {

SurfaceAge MeasureSurfaceAge(const TimeSurface& surface, SurfaceChannel channel,
                             const SurfaceDecay& decay, int64_t t_ns,
                             const PinholeIntrinsics& intrinsics, const Rigid3d& cam_from_world,
                             const Vector6d& velocity, std::span<const Eigen::Vector3f> positions,
                             std::span<const uint32_t> indices,
                             std::vector<std::pair<int64_t, double>>* scratch) {
  const Eigen::Matrix3d rotation = cam_from_world.RotationMatrix();
  // world_from_cam(t + dt) = world_from_cam(t) * ExpSE3(velocity * dt): a fixed world point moves
  // in the camera frame at -(v + omega x p).
  const Eigen::Vector3d linear = velocity.head<3>();
  const Eigen::Vector3d angular = velocity.tail<3>();
  const int64_t max_age_ns = decay.MaxActiveAgeExactNs();
  const int64_t* stamps = surface.LastTimestamps(channel);
  scratch->clear();
  for (const uint32_t index : indices) {
    const Eigen::Vector3d point =
        rotation * positions[index].cast<double>() + cam_from_world.translation;
    Eigen::Vector2d pixel;
    Eigen::Matrix<double, 2, 3> d_pixel_d_point;
    if (!intrinsics.Project(point, &pixel, &d_pixel_d_point)) continue;
    int x;
    int y;
    if (!NearestEdgeField::RoundToPixel(pixel, &x, &y) || x < 0 || y < 0 || x >= surface.width() ||
        y >= surface.height()) {
      continue;
    }
    const int64_t last_t_ns = stamps[static_cast<size_t>(y) * surface.width() + x];
    if (last_t_ns == kNeverFired) continue;
    // Events later than the evaluation time count as fired at it (as in the field).
    const int64_t age_ns = std::max<int64_t>(0, t_ns - last_t_ns);
    if (age_ns > max_age_ns) continue;
    const Eigen::Vector2d flow = d_pixel_d_point * -(linear + angular.cross(point));
    const double weight = flow.squaredNorm();
    if (!(weight > 0)) continue;
    scratch->emplace_back(age_ns, weight);
  }
  SurfaceAge result;
  result.points = static_cast<int>(scratch->size());
  result.age_ns = WeightedMedian(scratch);
  return result;
}

int64_t WeightedMedian(std::vector<std::pair<int64_t, double>>* samples) {
  if (samples->empty()) return 0;
  double total = 0;
  for (const auto& sample : *samples) total += sample.second;
  const double half = 0.5 * total;
  // Quickselect on [begin, end): the answer lies in it, with `below` the weight before it.
  auto begin = samples->begin();
  auto end = samples->end();
  double below = 0;
  while (end - begin > 1) {
    const auto middle = begin + (end - begin) / 2;
    std::nth_element(begin, middle, end);
    double left = 0;
    for (auto it = begin; it != middle; ++it) left += it->second;
    if (below + left >= half) {
      end = middle;  // The cumulative weight reaches half before the middle element.
    } else if (below + left + middle->second >= half) {
      return middle->first;
    } else {
      below += left + middle->second;
      begin = middle + 1;
    }
  }
  // Rounding can leave the sums a hair short of half the total: the largest value then.
  return begin < end ? begin->first : std::prev(begin)->first;
}

}  // namespace evloc::tracking
