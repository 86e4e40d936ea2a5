// ESIM: an event camera simulated from a sequence of linear intensity images (docs/simulator.md,
// docs/simulator.md). Each pixel keeps a reference log intensity; when the log intensity
// crosses reference +- contrast threshold between two images, an event is emitted at the
// linearly interpolated crossing time and the reference moves by one threshold.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

#include <opencv2/core.hpp>

#include "core/events/event.h"

namespace evloc::sim {

// Parameters of the simulated event pixel.
struct EsimOptions {
  // Contrast threshold for ON events, in log intensity units.
  double contrast_threshold_on = 0.2;
  // Contrast threshold for OFF events, in log intensity units.
  double contrast_threshold_off = 0.2;
  // Standard deviation of the per-pixel threshold mismatch (log units); 0 disables it.
  double threshold_mismatch_sigma = 0.03;
  // Smallest per-pixel threshold after mismatch, log units (keeps the pixel finite).
  double min_contrast_threshold = 0.01;
  // Refractory period in nanoseconds: a pixel that fired stays silent this long, while its
  // reference level still follows the signal; 0 disables it.
  int64_t refractory_period_ns = 500'000;
  // Background-activity noise rate per pixel, Hz (Poisson, random polarity); 0 disables it.
  double noise_rate_hz_per_pixel = 0.1;
  // Offset added to the linear intensity before the logarithm: L = log(I + log_epsilon).
  double log_epsilon = 1e-3;
  // Seed of the mismatch and noise random generators (same seed, same events).
  uint64_t seed = 1;
  // Worker threads for the per-pixel loop (1 or more).
  int num_threads = 2;

  // The options with mismatch, refractory period and noise switched off (the `--clean` flag).
  EsimOptions Clean() const;

  // Throws InvalidArgumentError when a threshold is not positive and finite, sigma or the noise
  // rate is negative, the refractory period is negative, log_epsilon is not positive, or
  // num_threads < 1.
  void Check() const;
};

// Simulates events from images given in time order. Usage: Initialize() with the first image,
// then AddImage() for each following image; each call appends the events of the interval
// between the previous image and this one, sorted by time.
class EventSimulator {
 public:
  // A simulator for images of `width` x `height` pixels. Throws InvalidArgumentError when the
  // options fail Check() or the size is not in (0, 65535].
  EventSimulator(int width, int height, const EsimOptions& options);

  // Sets every reference level to the log of `intensity` (CV_32FC1, linear, >= 0) at t_ns.
  // Throws InvalidArgumentError when the image has the wrong size or type.
  void Initialize(const cv::Mat& intensity, int64_t t_ns);

  // Appends to `events` the events between the previous image and `intensity` at t_ns, sorted by
  // time (ties by row, then column); every time is in (previous t_ns, t_ns]. Throws
  // InvalidArgumentError when not initialised, t_ns does not increase, or the image is wrong.
  void AddImage(const cv::Mat& intensity, int64_t t_ns, EventBuffer* events);

  // True once Initialize() has been called.
  bool initialized() const { return initialized_; }
  // Time of the last image, nanoseconds.
  int64_t last_time_ns() const { return last_t_ns_; }
  // The per-pixel reference log levels (CV_32FC1), for tests and diagnostics.
  const cv::Mat& reference_log_intensity() const { return reference_; }
  // The per-pixel ON thresholds after mismatch (CV_32FC1).
  const cv::Mat& on_thresholds() const { return threshold_on_; }
  // The per-pixel OFF thresholds after mismatch (CV_32FC1).
  const cv::Mat& off_thresholds() const { return threshold_off_; }

 private:
  // Converts a linear image to log intensity in `log_image`.
  void LogImage(const cv::Mat& intensity, cv::Mat* log_image) const;
  // Emits the crossing events of rows [row_begin, row_end) into `out` (unsorted).
  void SimulateRows(int row_begin, int row_end, const cv::Mat& new_log, int64_t t_new_ns,
                    std::vector<Event>* out);
  // Appends background-activity noise events of the interval (last_t_ns_, t_new_ns] to `out`.
  void AddNoise(int64_t t_new_ns, std::vector<Event>* out);

  int width_;
  int height_;
  EsimOptions options_;
  bool initialized_ = false;
  int64_t last_t_ns_ = 0;
  cv::Mat previous_log_;                // log intensity of the previous image
  cv::Mat reference_;                   // reference log level per pixel
  cv::Mat threshold_on_;                // per-pixel ON threshold
  cv::Mat threshold_off_;               // per-pixel OFF threshold
  std::vector<int64_t> last_event_ns_;  // time of the last emitted event per pixel
  std::mt19937_64 noise_rng_;
  std::vector<std::vector<Event>> thread_events_;
};

}  // namespace evloc::sim
