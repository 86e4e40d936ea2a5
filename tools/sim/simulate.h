// The simulation loop of `evloc-sim render`: adaptive render times along a camera motion, ESIM on
// every render, frames integrated over their exposure, depth at frame times
// (docs/simulator.md, "Render schedule").
#pragma once

#include <cstdint>
#include <functional>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/events/event.h"
#include "core/geometry/rigid3.h"
#include "tools/sim/esim.h"
#include "tools/sim/frame_sensor.h"
#include "tools/sim/motion.h"

namespace evloc::sim {

// Renders the view from a pose: linear gray radiance (CV_32FC1, required), RGB (CV_32FC3, only
// when `rgb` is not null) and depth z in metres (CV_32FC1, 0 = nothing hit; only when not null).
using RenderFunction =
    std::function<void(const Rigid3d& world_from_cam, cv::Mat* gray, cv::Mat* rgb, cv::Mat* depth)>;
// Receives events in time order, in batches.
using EventSink = std::function<void(const EventBuffer& events)>;
// Receives a frame (8-bit BGR) and the depth map (metres) at its time stamp (mid-exposure).
using FrameSink = std::function<void(int64_t t_ns, const cv::Mat& image, const cv::Mat& depth_m)>;

// Options of the simulation loop.
struct SequenceOptions {
  // The event pixel.
  EsimOptions esim;
  // The frame camera (its fps sets the frame times).
  FrameSensorOptions frames;
  // The scene illumination seen by both cameras.
  IlluminationOptions illumination;
  // Largest image motion between two consecutive ESIM images, pixels.
  double max_pixel_motion_px = 0.5;
  // Largest image motion between two renders, pixels; images between renders are interpolated
  // along the exact flow from the rendered depth (equal to max_pixel_motion_px: no interpolation).
  double max_render_motion_px = 3.0;
  // Longest interval between two renders, nanoseconds.
  int64_t max_render_interval_ns = 5'000'000;
  // Shortest interval between two renders, nanoseconds (bounds the work for extreme motion).
  int64_t min_render_interval_ns = 10'000;
  // Spacing of the depth samples used to measure image motion, pixels.
  int motion_sample_stride_px = 8;
  // Events are handed to the sink in batches of about this many.
  size_t event_batch_size = 1 << 20;

  // Throws InvalidArgumentError when a member fails its Check() or a bound is not positive.
  void Check() const;
};

// What the simulation loop did.
struct SequenceStats {
  // Number of renders (each feeds ESIM).
  int64_t num_renders = 0;
  // Number of images interpolated between renders (each feeds ESIM).
  int64_t num_interpolated = 0;
  // Number of events emitted.
  int64_t num_events = 0;
  // Number of frames emitted.
  int64_t num_frames = 0;
  // Largest image motion between consecutive ESIM images, measured on the depth samples, pixels.
  double max_measured_motion_px = 0;
  // Time spent rendering, seconds.
  double render_seconds = 0;
  // Time spent computing flow and interpolating images, seconds.
  double interpolation_seconds = 0;
  // Time spent in ESIM, seconds.
  double esim_seconds = 0;
  // Time spent exposing frames, seconds.
  double frame_seconds = 0;
  // The event pixel's counts: signal, noise, leak and hot-pixel events, suppressed and dropped.
  EsimCounts esim_counts;
};

// Image motion between two poses: the largest pixel displacement of the world points `points`
// (seen at `pixels` from the first pose) when seen from `world_from_cam`. Points that cannot be
// projected count as infinite motion.
double MaxImageMotion(const Camera& camera, const std::vector<Eigen::Vector3d>& points_world,
                      const std::vector<Eigen::Vector2d>& pixels, const Rigid3d& world_from_cam);

// The flow from view a to view b of the pixels of a (CV_32FC2, pixels): each pixel's point at its
// depth (z, metres; `rays` from ComputeRayTable) projected into b; 0 where there is no depth or
// the point does not project.
cv::Mat FlowFromDepth(const Camera& camera, const cv::Mat& rays, const cv::Mat& depth,
                      const Rigid3d& world_from_a, const Rigid3d& world_from_b);

// Runs the loop over [0, motion.duration_ns()]: renders at adaptive times (each step halved until
// the measured image motion is at most max_render_motion_px, and every exposure start, middle and
// end rendered exactly), interpolates images between renders so that consecutive ESIM images
// move at most max_pixel_motion_px, feeds ESIM, and integrates frames over every image. Events go
// to `event_sink` in time order; frames to `frame_sink` in time order. Throws InvalidArgumentError
// for bad options.
SequenceStats SimulateSequence(const RenderFunction& render, const Camera& camera,
                               const CameraMotion& motion, const SequenceOptions& options,
                               const EventSink& event_sink, const FrameSink& frame_sink);

}  // namespace evloc::sim
