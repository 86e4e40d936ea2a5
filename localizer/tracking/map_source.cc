#include "localizer/tracking/map_source.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <utility>

#include "core/common/error.h"

namespace evloc::tracking {

void CheckSearchRegion(const Eigen::Vector3d& center, double radius_m, const std::string& what) {
  if (!center.allFinite() || !std::isfinite(radius_m) || radius_m <= 0) {
    throw InvalidArgumentError(what + ": the centre must be finite and the radius positive");
  }
}

StaticMapSource::StaticMapSource(const Map& map, const VisibilityIndex* visibility)
    : map_(map), visibility_(visibility) {
  if (map.positions.size() != map.gradients.size()) {
    throw InvalidArgumentError("StaticMapSource: the map has not one gradient per point.");
  }
}

void StaticMapSource::VisibleCandidates(const Camera& camera, const Rigid3d& world_from_cam,
                                        const VisibilityQueryOptions& options,
                                        std::vector<uint32_t>* candidates) const {
  if (visibility_ != nullptr) {
    *candidates = visibility_->Query(camera, world_from_cam, options);
    return;
  }
  candidates->resize(map_.size());
  std::iota(candidates->begin(), candidates->end(), 0u);
}

void MapSource::CandidateViewpoints(const ViewpointQuery& /*query*/,
                                    std::vector<Rigid3d>* world_from_cams) const {
  world_from_cams->clear();
}

void ViewpointsAlongKeyframes(std::vector<std::pair<int64_t, Rigid3d>> keyframes,
                              const ViewpointQuery& query, std::vector<Rigid3d>* world_from_cams) {
  world_from_cams->clear();
  std::stable_sort(keyframes.begin(), keyframes.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  const auto add = [&](const Rigid3d& world_from_cam) {
    if (query.search_center &&
        (world_from_cam.translation - *query.search_center).norm() > query.search_radius_m) {
      return;
    }
    world_from_cams->push_back(world_from_cam);
  };
  for (size_t k = 0; k < keyframes.size(); ++k) {
    const Rigid3d& world_from_cam = keyframes[k].second;
    add(world_from_cam);
    if (k + 1 == keyframes.size()) break;
    const Rigid3d& next = keyframes[k + 1].second;
    const int samples = std::max(0, query.samples_between_keyframes);
    for (int s = 1; s <= samples; ++s) {
      add(Interpolate(world_from_cam, next, static_cast<double>(s) / (samples + 1)));
    }
  }
}

void StaticMapSource::CandidateViewpoints(const ViewpointQuery& query,
                                          std::vector<Rigid3d>* world_from_cams) const {
  std::vector<std::pair<int64_t, Rigid3d>> keyframes;
  keyframes.reserve(map_.keyframes.size());
  for (const Keyframe& keyframe : map_.keyframes) {
    keyframes.emplace_back(keyframe.t_ns, keyframe.cam_from_world.Inverse());
  }
  ViewpointsAlongKeyframes(std::move(keyframes), query, world_from_cams);
}

}  // namespace evloc::tracking
