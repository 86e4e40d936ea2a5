// Pictures a person debugs tracking with (evloc-track --debug-dir), after the paper's figures:
// the time surface with the map reprojected at the estimate, the ON/OFF surfaces, and each
// point's predicted image gradient and optical flow.
#pragma once

#include <filesystem>

#include <opencv2/core.hpp>

#include "core/geometry/rigid3.h"
#include "localizer/tracking/tracker.h"
#include "maps/map.h"
#include "maps/visibility.h"

namespace evloc::tracking {

// Renders one debug picture of a step (CV_8UC3, four panels side by side):
// 1. the unsigned time surface T (white = fresh) with the visible map points projected at the
//    estimate (green: on an active pixel, red: not);
// 2. ON (red) and OFF (blue) surfaces;
// 3. per point, the predicted image-gradient direction (yellow) and the flow since the previous
//    step (cyan, scaled x5), over the dimmed unsigned surface.
// 4. the events since the previous step (dim red ON, dim blue OFF) and each point's predicted
//    polarity (bright red ON, bright blue OFF, grey unsigned), from the motion prior's velocity.
// `previous_world_from_cam` is the previous step's estimate (for the flow of panel 3).
cv::Mat RenderTrackingDebugImage(const Tracker& tracker, const Map& map,
                                 const VisibilityIndex* visibility, const PoseEstimate& step,
                                 const Rigid3d& previous_world_from_cam);

}  // namespace evloc::tracking
