#include "localizer/tracking/pose_time.h"

#include <algorithm>
#include <cmath>
#include <iterator>

namespace evloc::tracking {
namespace {

// The least bilinear weight of a point's cell on active pixels for the point to count.
constexpr double kMinActiveWeight = 0.25;

}  // namespace

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
  const int width = surface.width();
  const int height = surface.height();
  scratch->clear();
  for (const uint32_t index : indices) {
    const Eigen::Vector3d point =
        rotation * positions[index].cast<double>() + cam_from_world.translation;
    Eigen::Vector2d pixel;
    Eigen::Matrix<double, 2, 3> d_pixel_d_point;
    if (!intrinsics.Project(point, &pixel, &d_pixel_d_point)) continue;
    // The age the point's bilinear sample of the field stands for: the bilinear blend of the
    // ages of the active pixels of its cell (the solver's minimum lies between pixels).
    if (!(pixel.x() >= 0 && pixel.y() >= 0 && pixel.x() < width - 1 && pixel.y() < height - 1)) {
      continue;
    }
    const int x0 = static_cast<int>(pixel.x());
    const int y0 = static_cast<int>(pixel.y());
    const double a = pixel.x() - x0;
    const double b = pixel.y() - y0;
    const double corner_weights[4] = {(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b};
    const size_t corner_offsets[4] = {0, 1, static_cast<size_t>(width),
                                      static_cast<size_t>(width) + 1};
    const size_t base = static_cast<size_t>(y0) * width + x0;
    double active_weight = 0;
    double weighted_age = 0;
    for (int corner = 0; corner < 4; ++corner) {
      const int64_t last_t_ns = stamps[base + corner_offsets[corner]];
      if (last_t_ns == kNeverFired) continue;
      // Events later than the evaluation time count as fired at it (as in the field).
      const int64_t age_ns = std::max<int64_t>(0, t_ns - last_t_ns);
      if (age_ns > max_age_ns) continue;
      active_weight += corner_weights[corner];
      weighted_age += corner_weights[corner] * static_cast<double>(age_ns);
    }
    // A point mostly over empty pixels is on no edge: it says nothing about time.
    if (!(active_weight > kMinActiveWeight)) continue;
    const int64_t age_ns = std::llround(weighted_age / active_weight);
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
