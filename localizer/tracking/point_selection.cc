#include "localizer/tracking/point_selection.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Cholesky>

#include "core/common/error.h"

namespace evloc::tracking {
namespace {

// A fixed 32-bit mix (Murmur3 finaliser): the in-bucket order, independent of the input order.
uint32_t Mix(uint32_t value) {
  value ^= value >> 16;
  value *= 0x85ebca6bu;
  value ^= value >> 13;
  value *= 0xc2b2ae35u;
  value ^= value >> 16;
  return value;
}

// Sorts `indices` (each < `size`) ascending: by marking them (in `marked`, scratch) when they are
// many and distinct (a selection keeps thousands of a map's points; a comparison sort of them
// cost a millisecond).
void SortIndices(size_t size, std::vector<uint32_t>* indices, std::vector<uint8_t>* marked) {
  const auto compare_sort = [indices] { std::sort(indices->begin(), indices->end()); };
  if (indices->size() < 64 || indices->size() * 8 < size) return compare_sort();
  marked->assign(size, 0);
  for (const uint32_t index : *indices) {
    if ((*marked)[index]) return compare_sort();  // a repeated candidate
    (*marked)[index] = 1;
  }
  size_t next = 0;
  for (size_t index = 0; index < size; ++index) {
    if ((*marked)[index]) (*indices)[next++] = static_cast<uint32_t>(index);
  }
}

// A point of SelectEvenly that projects into the image: its bucket, its order in the bucket
// (Mix of its index) and its index.
struct SelectionCandidate {
  uint32_t bucket;
  uint32_t order;
  uint32_t index;
};

// SelectEvenly's buffers, kept per thread between calls (a selection of tens of thousands of
// candidates fills a megabyte; fresh allocations of that size cost page faults).
struct SelectionScratch {
  std::vector<SelectionCandidate> visible;
  std::vector<SelectionCandidate> by_bucket;
  std::vector<uint32_t> bucket_start;
  std::vector<uint8_t> marked;
};

}  // namespace

std::vector<uint32_t> SelectEvenly(std::span<const Eigen::Vector3f> positions,
                                   const std::vector<uint32_t>& candidates,
                                   const PinholeIntrinsics& intrinsics, int width, int height,
                                   const Rigid3d& cam_from_world,
                                   const PointSelectionOptions& options) {
  if (options.max_points < 1 || options.bucket_size_px < 1 || width < 1 || height < 1) {
    throw InvalidArgumentError(
        "SelectEvenly: max_points, bucket size and image size must be >= 1.");
  }
  const int buckets_x = (width + options.bucket_size_px - 1) / options.bucket_size_px;
  const int buckets_y = (height + options.bucket_size_px - 1) / options.bucket_size_px;
  using Candidate = SelectionCandidate;
  thread_local SelectionScratch scratch;
  std::vector<Candidate>& visible = scratch.visible;
  visible.clear();
  const Eigen::Matrix3d rotation = cam_from_world.RotationMatrix();
  for (const uint32_t index : candidates) {
    if (index >= positions.size())
      throw InvalidArgumentError("SelectEvenly: candidate out of range.");
    const Eigen::Vector3d point_in_cam =
        rotation * positions[index].cast<double>() + cam_from_world.translation;
    if (!(point_in_cam.z() >= options.min_depth_m && point_in_cam.z() <= options.max_depth_m)) {
      continue;
    }
    Eigen::Vector2d pixel;
    if (!intrinsics.Project(point_in_cam, &pixel)) continue;
    const double margin = options.image_margin_px;
    if (!(pixel.x() >= margin && pixel.y() >= margin && pixel.x() <= width - 1 - margin &&
          pixel.y() <= height - 1 - margin)) {
      continue;
    }
    const int bucket_x =
        std::min(static_cast<int>(pixel.x()) / options.bucket_size_px, buckets_x - 1);
    const int bucket_y =
        std::min(static_cast<int>(pixel.y()) / options.bucket_size_px, buckets_y - 1);
    visible.push_back({static_cast<uint32_t>(bucket_y * buckets_x + bucket_x), Mix(index), index});
  }
  std::vector<uint32_t> selected;
  if (visible.size() <= static_cast<size_t>(options.max_points)) {
    selected.reserve(visible.size());
    for (const Candidate& candidate : visible) selected.push_back(candidate.index);
    SortIndices(positions.size(), &selected, &scratch.marked);
    return selected;
  }
  // Grouped by bucket: a counting sort by bucket (a comparison sort of the whole list took most
  // of a selection's time).
  {
    std::vector<uint32_t>& bucket_start = scratch.bucket_start;
    bucket_start.assign(static_cast<size_t>(buckets_x) * buckets_y + 1, 0);
    for (const Candidate& candidate : visible) ++bucket_start[candidate.bucket + 1];
    for (size_t b = 1; b < bucket_start.size(); ++b) bucket_start[b] += bucket_start[b - 1];
    std::vector<Candidate>& by_bucket = scratch.by_bucket;
    by_bucket.resize(visible.size());
    for (const Candidate& candidate : visible)
      by_bucket[bucket_start[candidate.bucket]++] = candidate;
    visible.swap(by_bucket);
  }
  // Bucket ranges in `visible`.
  std::vector<size_t> bucket_begin;
  for (size_t i = 0; i < visible.size(); ++i) {
    if (i == 0 || visible[i].bucket != visible[i - 1].bucket) bucket_begin.push_back(i);
  }
  bucket_begin.push_back(visible.size());
  const size_t num_buckets = bucket_begin.size() - 1;
  // The largest per-bucket share `level` with sum(min(count, level)) <= max_points: it depends
  // on the counts alone.
  auto taken_at = [&](size_t level) {
    size_t total = 0;
    for (size_t b = 0; b < num_buckets; ++b) {
      total += std::min(bucket_begin[b + 1] - bucket_begin[b], level);
    }
    return total;
  };
  size_t low = 0;
  size_t high = visible.size();
  while (low < high) {
    const size_t middle = (low + high + 1) / 2;
    if (taken_at(middle) <= static_cast<size_t>(options.max_points)) {
      low = middle;
    } else {
      high = middle - 1;
    }
  }
  const size_t level = low;
  // Each bucket's first level + 1 points by (order, index), the only ones read below: a partial
  // sort of a bucket of tens of points for the few it gives (the full sort of every bucket was
  // 3 % of a DEVO run's CPU at 640x480; the same selection).
  const auto by_order = [](const Candidate& a, const Candidate& b) {
    if (a.order != b.order) return a.order < b.order;
    return a.index < b.index;
  };
  for (size_t b = 0; b < num_buckets; ++b) {
    const auto first = visible.begin() + static_cast<std::ptrdiff_t>(bucket_begin[b]);
    const auto last = visible.begin() + static_cast<std::ptrdiff_t>(bucket_begin[b + 1]);
    const size_t needed = std::min(bucket_begin[b + 1] - bucket_begin[b], level + 1);
    std::partial_sort(first, first + static_cast<std::ptrdiff_t>(needed), last, by_order);
  }
  selected.reserve(options.max_points);
  for (size_t b = 0; b < num_buckets; ++b) {
    const size_t end = std::min(bucket_begin[b + 1], bucket_begin[b] + level);
    for (size_t i = bucket_begin[b]; i < end; ++i) selected.push_back(visible[i].index);
  }
  // Fill the remainder with the next point of the buckets that have one, in bucket order.
  for (size_t b = 0; b < num_buckets && selected.size() < static_cast<size_t>(options.max_points);
       ++b) {
    if (bucket_begin[b + 1] - bucket_begin[b] > level) {
      selected.push_back(visible[bucket_begin[b] + level].index);
    }
  }
  SortIndices(positions.size(), &selected, &scratch.marked);
  return selected;
}

std::vector<uint32_t> SelectInformative(std::span<const Eigen::Vector3f> positions,
                                        std::span<const Eigen::Vector3f> gradients,
                                        const std::vector<uint32_t>& selected,
                                        const PinholeIntrinsics& intrinsics,
                                        const Rigid3d& cam_from_world,
                                        const InformativeSelectionOptions& options) {
  const int count = options.count;
  const double probe_fraction = options.gradient_probe_depth_fraction;
  if (count < 1 || !(options.seed_fraction > 0 && options.seed_fraction <= 1) ||
      !(probe_fraction > 0 && probe_fraction < 1)) {
    throw InvalidArgumentError(
        "SelectInformative: count must be >= 1, seed_fraction in (0, 1] and "
        "gradient_probe_depth_fraction in (0, 1).");
  }
  if (positions.size() != gradients.size()) {
    throw InvalidArgumentError("SelectInformative: one gradient per position is needed.");
  }
  if (selected.size() <= static_cast<size_t>(count)) return selected;
  const size_t n = selected.size();
  // Each point's predicted Jacobian row: the unit edge normal in the image times the derivative of
  // the projection (translation part), and the point in the camera crossed with it (rotation).
  thread_local std::vector<Vector6d> rows;
  rows.assign(n, Vector6d::Zero());
  const Eigen::Matrix3d rotation = cam_from_world.RotationMatrix();
  for (size_t i = 0; i < n; ++i) {
    const uint32_t index = selected[i];
    if (index >= positions.size()) {
      throw InvalidArgumentError("SelectInformative: point index out of range.");
    }
    const Eigen::Vector3d point =
        rotation * positions[index].cast<double>() + cam_from_world.translation;
    Eigen::Vector2d pixel;
    Eigen::Vector2d probe_pixel;
    Eigen::Matrix<double, 2, 3> d_pixel_d_point;
    const Eigen::Vector3d probe =
        point + probe_fraction * point.z() * (rotation * gradients[index].cast<double>());
    if (!intrinsics.Project(point, &pixel, &d_pixel_d_point) ||
        !intrinsics.Project(probe, &probe_pixel)) {
      continue;
    }
    const Eigen::Vector2d normal = probe_pixel - pixel;
    const double length = normal.norm();
    // A gradient within ~6 degrees of the viewing ray (its probe moves under a tenth of the
    // f * probe_fraction it would across the ray) has no meaningful edge normal in the image.
    if (!(length > 0.1 * probe_fraction * intrinsics.fx)) continue;
    const Eigen::Vector3d translation_part = d_pixel_d_point.transpose() * (normal / length);
    rows[i].head<3>() = translation_part;
    rows[i].tail<3>() = point.cross(translation_part);
  }
  // The seeds: seed_fraction of the count, at even intervals over `selected` (spread as it is).
  const size_t seeds = std::min<size_t>(
      count, static_cast<size_t>(std::llround(options.seed_fraction * static_cast<double>(count))));
  thread_local std::vector<uint8_t> taken;
  taken.assign(n, 0);
  std::vector<uint32_t> result;
  result.reserve(count);
  for (size_t k = 0; k < seeds; ++k) {
    const size_t i = k * n / seeds;
    taken[i] = 1;
    result.push_back(selected[i]);
  }
  // The rest by leverage j^T H^-1 j, H the information of all of `selected`: the share of H a
  // point's row carries. A point whose direction many others share (one long straight edge) has
  // a low leverage however strong it is; one that alone fixes a direction (the rare edge at
  // another angle, a near point for the translation) a high one. The small regularisation keeps
  // H invertible when the points leave a direction unconstrained.
  Matrix6d information = Matrix6d::Zero();
  for (size_t i = 0; i < n; ++i) information.selfadjointView<Eigen::Lower>().rankUpdate(rows[i]);
  information = information.selfadjointView<Eigen::Lower>();
  information.diagonal().array() += 1e-9 * information.trace() / 6 + 1e-300;
  const Matrix6d inverse = information.ldlt().solve(Matrix6d::Identity());
  thread_local std::vector<std::pair<double, uint32_t>> ranked;  // (-leverage, position)
  ranked.clear();
  for (size_t i = 0; i < n; ++i) {
    if (!taken[i]) ranked.push_back({-rows[i].dot(inverse * rows[i]), static_cast<uint32_t>(i)});
  }
  const size_t rest = std::min(static_cast<size_t>(count) - result.size(), ranked.size());
  std::partial_sort(ranked.begin(), ranked.begin() + static_cast<std::ptrdiff_t>(rest),
                    ranked.end());
  for (size_t k = 0; k < rest; ++k) result.push_back(selected[ranked[k].second]);
  std::sort(result.begin(), result.end());
  return result;
}

}  // namespace evloc::tracking
