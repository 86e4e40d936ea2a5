#include "localizer/relocalization/event_image_hypotheses.h"

#include "core/common/error.h"

namespace evloc::relocalization {

LocateOptions EventImageHypotheses::Options() {
  LocateOptions options;
  options.verify = false;
  options.pose.min_inliers = 8;
  options.pose.min_inlier_ratio = 0.15;
  return options;
}

EventImageHypotheses::EventImageHypotheses(const Map& map, const VisibilityIndex& visibility,
                                           const Camera& sensor_camera,
                                           const LocateOptions& options)
    : map_(map), visibility_(visibility), camera_(sensor_camera), options_(options) {
  if (!map.relocalization) throw InvalidArgumentError(kNoRelocalizationDataMessage);
  camera_.Check();
  options_.Check();
}

std::vector<Rigid3d> EventImageHypotheses::Hypotheses(const cv::Mat& image,
                                                      int64_t /*t_ns*/) const {
  const LocateResult result = LocateImage(map_, visibility_, camera_, image, options_);
  if (result.inliers == 0 || result.status != LocateStatus::kFound) return {};
  return {result.pnp_world_from_cam};
}

}  // namespace evloc::relocalization
