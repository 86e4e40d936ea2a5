#include "localizer/tracking/map_source.h"

#include <algorithm>
#include <numeric>

#include "core/common/error.h"

namespace evloc::tracking {

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

void StaticMapSource::CandidateViewpoints(const ViewpointQuery& query,
                                          std::vector<Rigid3d>* world_from_cams) const {
  world_from_cams->clear();
  std::vector<size_t> order(map_.keyframes.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(), [this](size_t a, size_t b) {
    return map_.keyframes[a].t_ns < map_.keyframes[b].t_ns;
  });
  const auto add = [&](const Rigid3d& world_from_cam) {
    if (query.search_center &&
        (world_from_cam.translation - *query.search_center).norm() > query.search_radius_m) {
      return;
    }
    world_from_cams->push_back(world_from_cam);
  };
  for (size_t k = 0; k < order.size(); ++k) {
    const Rigid3d world_from_cam = map_.keyframes[order[k]].cam_from_world.Inverse();
    add(world_from_cam);
    if (k + 1 == order.size()) break;
    const Rigid3d next = map_.keyframes[order[k + 1]].cam_from_world.Inverse();
    const int samples = std::max(0, query.samples_between_keyframes);
    for (int s = 1; s <= samples; ++s) {
      add(Interpolate(world_from_cam, next, static_cast<double>(s) / (samples + 1)));
    }
  }
}

}  // namespace evloc::tracking
