// Where the global search gets hypotheses from an image of the events (docs/relocalization.md,
// "Hypotheses from an image of the events"): an interface, so that the tracker does not depend
// on the module that locates images (localizer/relocalization implements it with the map's
// local features, retrieval and PnP).
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/geometry/rigid3.h"

namespace evloc::tracking {

class ImageHypothesisSource {
 public:
  virtual ~ImageHypothesisSource() = default;

  // Poses (world_from_cam) from which `image` (CV_8UC1, the tracker's sensor camera: its pixels
  // and distortion), an image of the events up to t_ns, may have been taken, most likely first;
  // empty when none. The tracker
  // refines and verifies each against the events itself, so a hypothesis need not be verified
  // here. May be called from a thread other than the tracker's (one call at a time per tracker);
  // must not throw for an image of the right size and type.
  virtual std::vector<Rigid3d> Hypotheses(const cv::Mat& image, int64_t t_ns) const = 0;
};

}  // namespace evloc::tracking
