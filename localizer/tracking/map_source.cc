#include "localizer/tracking/map_source.h"

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

}  // namespace evloc::tracking
