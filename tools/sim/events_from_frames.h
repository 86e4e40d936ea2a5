// Events from a real frame sequence, the rpg_vid2e recipe with a classical interpolator: frames to
// linear intensity, dense optical flow (DIS) between consecutive frames, flow-warped intermediate
// frames so that image motion between them stays small, then ESIM (docs/simulator.md,
// "events-from-frames").
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include <opencv2/core.hpp>

#include "core/dataset/dataset.h"
#include "core/events/event.h"
#include "tools/sim/esim.h"

namespace evloc::sim {

// Options of the frames-to-events conversion.
struct EventsFromFramesOptions {
  // The event pixel.
  EsimOptions esim;
  // Largest image motion between two interpolated frames, pixels.
  double max_pixel_motion_px = 0.5;
  // Upper bound on interpolated frames between two input frames.
  int max_interpolated_per_pair = 256;
  // Input frames are raised to this power to get linear intensity (1: already linear, as DAVIS
  // APS frames; 2.2: gamma-encoded video).
  double input_gamma = 1.0;
  // Flow magnitudes above this quantile set the number of interpolated frames (ignores outliers).
  double flow_quantile = 0.99;

  // Throws InvalidArgumentError for non-positive bounds, gamma or a quantile outside (0, 1].
  void Check() const;
};

// What the conversion did.
struct EventsFromFramesStats {
  // Input frames used.
  int64_t num_input_frames = 0;
  // Interpolated frames fed to ESIM (inputs excluded).
  int64_t num_interpolated_frames = 0;
  // Events emitted.
  int64_t num_events = 0;
  // Largest per-pair flow quantile seen, pixels.
  double max_flow_px = 0;
  // Time in optical flow, seconds.
  double flow_seconds = 0;
  // Time in interpolation and ESIM, seconds.
  double esim_seconds = 0;
};

// The frame at fraction `alpha` in [0, 1] between `frame0` and `frame1` (CV_32FC1), from the
// forward flow 0->1 and backward flow 1->0 (CV_32FC2, pixels): the average of frame0 warped by
// alpha * flow01 and frame1 warped by (1 - alpha) * flow10, weighted 1 - alpha and alpha.
cv::Mat InterpolateFrame(const cv::Mat& frame0, const cv::Mat& frame1, const cv::Mat& flow01,
                         const cv::Mat& flow10, double alpha);

// Converts the frames of `images` (in time order, at least 2) into events handed to `sink` in
// time order. Throws IoError when a frame cannot be read, InvalidArgumentError for bad options,
// fewer than 2 frames or frames of different sizes.
EventsFromFramesStats EventsFromFrames(const std::vector<TimedFile>& images,
                                       const EventsFromFramesOptions& options,
                                       const std::function<void(const EventBuffer&)>& sink);

}  // namespace evloc::sim
