// The mapless odometry over a recorded dataset with depth (docs/tracking.md, "Mapless odometry"):
// Canny-VO on its associated colour and depth frames. Used by evloc-track --mode vo.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "core/dataset/dataset.h"
#include "core/geometry/rigid3.h"
#include "core/trajectory/trajectory.h"
#include "localizer/odometry/canny_vo.h"

namespace evloc::odometry {

// Which mapless odometry runs.
enum class OdometryMode {
  // Canny-VO: RGB-D frames.
  kVo,
  // Canny-DEVO: events with depth frames.
  kDevo,
};

// "vo" or "devo".
const char* OdometryModeName(OdometryMode mode);

// Options of a Canny-VO run over a dataset.
struct VoRunOptions {
  // The odometry's options.
  CannyVoOptions vo;
  // Colour and depth frames further apart than this are not paired, nanoseconds (TUM RGB-D; in
  // the evloc layout depth is at the frame times).
  int64_t association_tolerance_ns = kTumAssociationToleranceNs;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// What a run produced.
struct VoRunResult {
  // One pose per frame, world_from_cam (also for untracked frames: the prediction).
  Trajectory trajectory;
  // Every frame's estimate, in order.
  std::vector<VoEstimate> steps;
  // Frames not tracked.
  int64_t untracked_frames = 0;
  // Keyframes taken (the first frame included).
  int64_t keyframes = 0;
  // Wall-clock time of the run (reading included), seconds.
  double wall_s = 0;
};

// Runs Canny-VO over the frames of `dataset` that have a depth map within the tolerance, from
// the first one at or after `initial_t_ns`, which starts at `initial_world_from_cam`. Calls
// `on_step` after every frame. Throws InvalidArgumentError when the dataset has no images or no
// depth or no pair is found, IoError / ParseError for unreadable files.
VoRunResult RunCannyVo(const Dataset& dataset, const Rigid3d& initial_world_from_cam,
                       int64_t initial_t_ns, const VoRunOptions& options,
                       const std::function<void(const VoEstimate&)>& on_step = {});

}  // namespace evloc::odometry
