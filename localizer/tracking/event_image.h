// A grey image reconstructed from events, for the search's image hypotheses
// (docs/relocalization.md, "Events: hypotheses from an image of the events"): per pixel, a leaky
// integrator of the event polarities, v <- v * exp(-dt / tau) + p. Each event is a step of the
// log intensity by about one contrast threshold, so v is the log intensity high-pass filtered
// with time constant tau: with the camera moving, the low-pass part is the scene blurred along
// the motion and v keeps its texture, enough for the map's local features to match. Written here
// rather than taken from a library: OpenCV's contrib has no event integrator, and the integrator
// is a few lines on the tracker's own event buffers. It is kept as each pixel's value at an
// anchor time (below), so that an event costs one addition, not a decay of its pixel first.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/events/event.h"

namespace evloc::tracking {

class EventImage {
 public:
  // An image of width x height pixels (the sensor's) and time constant tau_s (> 0). Throws
  // InvalidArgumentError otherwise.
  EventImage(int width, int height, double tau_s);

  // Forgets every event.
  void Clear();

  // Integrates events [begin, end) of `events` (time-ordered, also across calls); events outside
  // the image are skipped.
  void Insert(const EventBuffer& events, size_t begin, size_t end);

  // Nanoseconds of events integrated since the first event after construction or Clear() (0
  // before one).
  int64_t covered_ns() const { return any_ ? last_t_ns_ - first_t_ns_ : 0; }

  // The integrator's value at pixel (x, y) decayed to t_ns (>= its last event), in contrast
  // thresholds (0 for a pixel that never fired or outside the image).
  double Value(int x, int y, int64_t t_ns) const;

  // The image at t_ns (>= the last event): every pixel decayed to t_ns, then stretched linearly
  // from the 1st to the 99th percentile of the pixels that saw an event onto 0..255 (an 8-bit
  // grey image, CV_8UC1). All grey (128) before any event.
  cv::Mat Render(int64_t t_ns) const;

 private:
  // The value of `pixel` (row-major index) decayed to t_ns.
  float Decayed(size_t pixel, int64_t t_ns) const;
  // Brings every value to the anchor t_ns (scaled by exp(-(t_ns - anchor) / tau)).
  void Reanchor(int64_t t_ns);

  int width_;
  int height_;
  double tau_ns_;
  // Per pixel, the sum of its polarities weighted by exp((t - anchor_t_ns_) / tau): the
  // integrator's value at the anchor time, so that an event adds to one number and the image
  // decays all pixels by one factor. The anchor moves forward (every value scaled down) before
  // the weights outgrow a float's precision.
  std::vector<float> value_;
  bool any_ = false;
  int64_t first_t_ns_ = 0;
  int64_t last_t_ns_ = 0;
  int64_t anchor_t_ns_ = 0;
};

}  // namespace evloc::tracking
