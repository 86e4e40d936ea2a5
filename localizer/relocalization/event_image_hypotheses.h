// The event search's hypotheses from an image of the events (docs/relocalization.md, "Hypotheses
// from an image of the events"): the image locator's retrieval, matching and PnP, run on the
// tracker's leaky-integrator image of the events, without the locator's edge verification (the
// tracker refines and verifies every hypothesis on the events themselves).
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "localizer/relocalization/image_locator.h"
#include "localizer/tracking/image_hypothesis_source.h"
#include "maps/map.h"
#include "maps/visibility.h"

namespace evloc::relocalization {

class EventImageHypotheses final : public tracking::ImageHypothesisSource {
 public:
  // Hypotheses in `map` (with relocalization data; `visibility` built on it; both must outlive
  // this) for images of `sensor_camera`. Throws InvalidArgumentError when the map has no
  // relocalization data (kNoRelocalizationDataMessage), the camera fails Check() or the options
  // fail Check().
  EventImageHypotheses(const Map& map, const VisibilityIndex& visibility,
                       const Camera& sensor_camera, const LocateOptions& options = Options());

  // The PnP pose of LocateImage on `image` when its PnP stage succeeds (at most one pose).
  std::vector<Rigid3d> Hypotheses(const cv::Mat& image, int64_t t_ns) const override;

  // LocateImage's options for images of events: no edge verification, and a PnP acceptance of 8
  // inliers and 15 % (images of events share fewer features with the map's photographs: 8-19
  // inliers of about 50 correspondences where the pose was within 3 cm, docs/relocalization.md).
  static LocateOptions Options();

 private:
  const Map& map_;
  const VisibilityIndex& visibility_;
  Camera camera_;
  LocateOptions options_;
};

}  // namespace evloc::relocalization
