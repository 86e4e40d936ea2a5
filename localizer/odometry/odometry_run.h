// The mapless odometry over a recorded dataset with depth (docs/tracking.md, "Mapless odometry"):
// Canny-VO on its associated colour and depth frames, Canny-DEVO on its events and depth frames.
// Used by evloc-track --mode vo | devo.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "core/dataset/dataset.h"
#include "core/geometry/rigid3.h"
#include "core/trajectory/trajectory.h"
#include "localizer/odometry/canny_devo.h"
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
  // With a depth camera of its own (depth_camchain.yaml, depth_camera.txt) the dataset's depth is
  // that camera's frames, registered to the frame camera (RegisterDepth; the frames are the
  // dataset camera's, as a DAVIS's), paired with the frames by time; false: depth.txt.
  bool use_depth_camera = true;

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

// The pose an odometry run starts from at its first frame's time t_ns: `given` when set, else
// the dataset's ground truth at t_ns. Throws InvalidArgumentError when neither exists.
Rigid3d OdometryStartPose(const Dataset& dataset, const std::optional<Rigid3d>& given,
                          int64_t t_ns);

// Runs Canny-VO over the frames of `dataset` that have a depth map within the tolerance, from
// the first one at or after `initial_t_ns`, which starts at OdometryStartPose. Calls `on_step`
// after every frame. Throws InvalidArgumentError when the dataset has no images or no depth or no
// pair is found, IoError / ParseError for unreadable files.
VoRunResult RunCannyVo(const Dataset& dataset, const std::optional<Rigid3d>& initial_world_from_cam,
                       int64_t initial_t_ns, const VoRunOptions& options,
                       const std::function<void(const VoEstimate&)>& on_step = {});

// Options of a Canny-DEVO run over a dataset.
struct DevoRunOptions {
  // The odometry's options.
  CannyDevoOptions devo;
  // The first reference frame is the first depth frame at least this long after the start time,
  // so that the events before it fill the time surface, nanoseconds (and once the hot-pixel
  // filter, when on, no longer holds the events of its learning period back).
  int64_t warm_up_ns = 30'000'000;
  // Events read per batch (any value gives the same poses).
  size_t read_batch_events = 1 << 16;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// What a DEVO run produced.
struct DevoRunResult {
  // One pose per step, world_from_cam.
  Trajectory trajectory;
  // Every step's estimate, in order.
  std::vector<tracking::PoseEstimate> steps;
  // The reference frames taken, in order.
  std::vector<ReferenceFrameInfo> reference_frames;
  // Events read.
  int64_t events = 0;
  // Steps whose status was LOST.
  int64_t lost_steps = 0;
  // Wall-clock time of the run (reading included), seconds.
  double wall_s = 0;
};

// The depth a DEVO run over `dataset` uses: its depth camera (depth_camchain.yaml,
// depth_camera.txt) when it has one, else depth.txt taken as the event camera's own depth
// (identity extrinsic). Throws InvalidArgumentError naming the dataset when it has neither.
DepthCameraStream DevoDepthStream(const Dataset& dataset);

// Runs Canny-DEVO over the events and the depth (DevoDepthStream) of `dataset`, from the first
// depth frame at least warm_up_ns after `initial_t_ns`, which starts at OdometryStartPose; the
// events before it only fill the time surfaces. Calls `on_step` after every step. Throws
// InvalidArgumentError when the dataset has no events or no depth, IoError / ParseError for
// unreadable files.
DevoRunResult RunCannyDevo(const Dataset& dataset,
                           const std::optional<Rigid3d>& initial_world_from_cam,
                           int64_t initial_t_ns, const DevoRunOptions& options,
                           const std::function<void(const tracking::PoseEstimate&)>& on_step = {});

}  // namespace evloc::odometry
