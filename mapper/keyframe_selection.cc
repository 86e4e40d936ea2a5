#include "mapper/keyframe_selection.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <unordered_set>

#include "core/common/error.h"

namespace evloc::mapper {
namespace {

double Degrees(double radians) { return radians * 180.0 / std::numbers::pi; }

// Median of the depths of the view's sparse points in its camera; 0 without points in front.
double MedianDepth(const RegisteredView& view,
                   const std::unordered_map<uint64_t, Eigen::Vector3d>& sparse_points) {
  std::vector<double> depths;
  depths.reserve(view.observed_points.size());
  for (const uint64_t id : view.observed_points) {
    const auto point = sparse_points.find(id);
    if (point == sparse_points.end()) {
      throw InvalidArgumentError("view " + view.image_name + " refers to unknown sparse point " +
                                 std::to_string(id));
    }
    const double depth = (view.cam_from_world * point->second).z();
    if (depth > 0.0) depths.push_back(depth);
  }
  if (depths.empty()) return 0.0;
  const auto middle = depths.begin() + depths.size() / 2;
  std::nth_element(depths.begin(), middle, depths.end());
  return *middle;
}

Eigen::Vector3d Center(const RegisteredView& view) {
  return view.cam_from_world.Inverse().translation;
}

size_t CountShared(const std::unordered_set<uint64_t>& a, const RegisteredView& b) {
  size_t shared = 0;
  for (const uint64_t id : b.observed_points) shared += a.contains(id) ? 1 : 0;
  return shared;
}

// `count` indices spread evenly over [0, size), first and last included, increasing.
std::vector<size_t> EvenlySpaced(size_t size, size_t count) {
  std::vector<size_t> indices;
  for (size_t k = 0; k < count; ++k) {
    indices.push_back(count == 1 ? 0
                                 : static_cast<size_t>(std::llround(
                                       static_cast<double>(k) * static_cast<double>(size - 1) /
                                       static_cast<double>(count - 1))));
  }
  indices.erase(std::unique(indices.begin(), indices.end()), indices.end());
  return indices;
}

// Greedy keyframes in view order with the baseline and rotation thresholds times `scale`.
std::vector<size_t> GreedyKeyframes(const std::vector<RegisteredView>& views,
                                    const std::vector<double>& median_depths,
                                    const KeyframeSelectionOptions& options, double scale) {
  std::vector<size_t> keyframes = {0};
  for (size_t i = 1; i < views.size(); ++i) {
    const RegisteredView& last = views[keyframes.back()];
    const std::unordered_set<uint64_t> last_points(last.observed_points.begin(),
                                                   last.observed_points.end());
    const double shared_fraction = last_points.empty()
                                       ? 0.0
                                       : static_cast<double>(CountShared(last_points, views[i])) /
                                             static_cast<double>(last_points.size());
    const double depth = median_depths[keyframes.back()];
    const double baseline = (Center(views[i]) - Center(last)).norm();
    const double rotation_deg =
        Degrees(AngleBetween(views[i].cam_from_world.rotation, last.cam_from_world.rotation));
    if (shared_fraction < options.max_shared_fraction ||
        (depth > 0.0 && baseline > scale * options.max_baseline_ratio * depth) ||
        rotation_deg > scale * options.max_rotation_deg) {
      keyframes.push_back(i);
    }
  }
  return keyframes;
}

}  // namespace

void KeyframeSelectionOptions::Check() const {
  if (max_keyframes && *max_keyframes < 1) {
    throw InvalidArgumentError("max_keyframes must be at least 1");
  }
  if (!(max_shared_fraction > 0.0 && max_shared_fraction <= 1.0)) {
    throw InvalidArgumentError("max_shared_fraction must be in (0, 1]");
  }
  if (min_keyframes < 1) throw InvalidArgumentError("min_keyframes must be at least 1");
  if (!(max_baseline_ratio > 0.0)) throw InvalidArgumentError("max_baseline_ratio must be > 0");
  if (!(max_rotation_deg > 0.0)) throw InvalidArgumentError("max_rotation_deg must be > 0");
  if (num_neighbours < 1) throw InvalidArgumentError("num_neighbours must be at least 1");
  if (min_shared_points < 0) throw InvalidArgumentError("min_shared_points must be >= 0");
  if (!(min_neighbour_baseline_ratio >= 0.0)) {
    throw InvalidArgumentError("min_neighbour_baseline_ratio must be >= 0");
  }
  if (!(preferred_neighbour_baseline_ratio > 0.0)) {
    throw InvalidArgumentError("preferred_neighbour_baseline_ratio must be > 0");
  }
  if (!(max_neighbour_angle_deg > 0.0 && max_neighbour_angle_deg <= 180.0)) {
    throw InvalidArgumentError("max_neighbour_angle_deg must be in (0, 180]");
  }
}

KeyframeSelection SelectKeyframes(
    const std::vector<RegisteredView>& views,
    const std::unordered_map<uint64_t, Eigen::Vector3d>& sparse_points,
    const KeyframeSelectionOptions& options) {
  options.Check();
  if (views.empty()) throw InvalidArgumentError("no registered views to select keyframes from");
  std::vector<double> median_depths(views.size());
  for (size_t i = 0; i < views.size(); ++i) median_depths[i] = MedianDepth(views[i], sparse_points);

  // Greedy selection in view order; on short sequences with finer thresholds until enough.
  size_t wanted = std::min(views.size(), static_cast<size_t>(options.min_keyframes));
  if (options.max_keyframes) wanted = std::min(wanted, static_cast<size_t>(*options.max_keyframes));
  std::vector<size_t> keyframes;
  double scale = 1.0;
  for (int attempt = 0; attempt < 8; ++attempt, scale *= 0.5) {
    keyframes = GreedyKeyframes(views, median_depths, options, scale);
    if (keyframes.size() >= wanted) break;
  }
  if (keyframes.size() < wanted) keyframes = EvenlySpaced(views.size(), wanted);
  if (options.max_keyframes && keyframes.size() > static_cast<size_t>(*options.max_keyframes)) {
    const size_t count = static_cast<size_t>(*options.max_keyframes);
    std::vector<size_t> thinned;
    for (const size_t position : EvenlySpaced(keyframes.size(), count)) {
      thinned.push_back(keyframes[position]);
    }
    keyframes = std::move(thinned);
  }

  KeyframeSelection selection;
  selection.keyframes = keyframes;
  const double max_angle_rad = options.max_neighbour_angle_deg * std::numbers::pi / 180.0;
  for (const size_t keyframe : keyframes) {
    const RegisteredView& view = views[keyframe];
    const std::unordered_set<uint64_t> points(view.observed_points.begin(),
                                              view.observed_points.end());
    const double depth = median_depths[keyframe];
    const Eigen::Vector3d axis = view.cam_from_world.rotation.inverse() * Eigen::Vector3d::UnitZ();
    std::vector<std::pair<double, size_t>> scored;  // (score, view index)
    for (size_t other = 0; other < views.size(); ++other) {
      if (other == keyframe) continue;
      const size_t shared = CountShared(points, views[other]);
      if (shared < static_cast<size_t>(std::max(options.min_shared_points, 1))) continue;
      const double baseline = (Center(views[other]) - Center(view)).norm();
      if (baseline < options.min_neighbour_baseline_ratio * depth) continue;
      const Eigen::Vector3d other_axis =
          views[other].cam_from_world.rotation.inverse() * Eigen::Vector3d::UnitZ();
      if (std::acos(std::clamp(axis.dot(other_axis), -1.0, 1.0)) > max_angle_rad) continue;
      const double baseline_weight =
          depth > 0.0
              ? std::min(1.0, baseline / (options.preferred_neighbour_baseline_ratio * depth))
              : 1.0;
      scored.emplace_back(static_cast<double>(shared) * baseline_weight, other);
    }
    std::sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) {
      return a.first != b.first ? a.first > b.first : a.second < b.second;
    });
    std::vector<size_t> neighbours;
    for (size_t k = 0; k < scored.size() && k < static_cast<size_t>(options.num_neighbours); ++k) {
      neighbours.push_back(scored[k].second);
    }
    selection.neighbours.push_back(std::move(neighbours));
    selection.median_depths.push_back(depth);
  }
  return selection;
}

}  // namespace evloc::mapper
