// ESIM: an event camera simulated from a sequence of linear intensity images (docs/simulator.md,
// docs/simulator.md). Each pixel keeps a reference log intensity; when the log intensity
// crosses reference +- contrast threshold between two images, an event is emitted at the
// linearly interpolated crossing time and the reference moves by one threshold.
#pragma once

#include <cstdint>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/events/event.h"

namespace evloc::sim {

// Parameters of the simulated event pixel. The defaults are the `ideal` sensor: the ESIM pixel
// of vid2e (thresholds with mismatch, refractory period, uniform background noise). The realistic
// pixel (docs/simulator.md, "The realistic pixel") adds a photoreceptor low-pass, light-dependent
// shot noise, leak events, hot pixels and a read-out limit; each is off at its default.
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
  // Background-activity (shot) noise rate per pixel, Hz, at the darkest level (I = 0; Poisson,
  // random polarity); 0 disables it. Uniform over the image when noise_half_intensity is 0.
  double noise_rate_hz_per_pixel = 0.1;
  // Linear intensity at which the shot-noise rate has fallen to half its dark rate: the rate at
  // intensity I is noise_rate_hz_per_pixel / (1 + I / noise_half_intensity); 0: the rate does
  // not depend on the light (the ideal pixel).
  double noise_half_intensity = 0;
  // Photoreceptor cutoff frequency, Hz, at linear intensity 1 (white paper under the bright
  // lighting preset); the cutoff is proportional to I + log_epsilon (the photocurrent plus the
  // dark current), so events lag and blur in the dark. 0: no low-pass (infinite bandwidth).
  double photoreceptor_cutoff_hz = 0;
  // Leak event rate per pixel, Hz (the reference drifts down by one ON threshold per period);
  // 0 disables leak events.
  double leak_rate_hz = 0;
  // Spread of the per-pixel leak rate, decades (log-normal, fixed for the sequence).
  double leak_rate_spread_decades = 0.1;
  // Fraction of hot pixels in [0, 1): pixels chosen at random (fixed for the sequence) that fire
  // at hot_pixel_rate_hz whatever the light.
  double hot_pixel_fraction = 0;
  // Event rate of a hot pixel, Hz (Poisson, one polarity per pixel, before the refractory period).
  double hot_pixel_rate_hz = 1000;
  // Read-out limit, events per second: the arbiter serves one event every 1/rate seconds, later
  // events wait (their time stamps are delayed); 0: unlimited.
  double readout_rate_eps = 0;
  // Longest wait in the read-out queue, nanoseconds; an event that would wait longer is dropped.
  int64_t readout_max_delay_ns = 1'000'000;
  // Offset added to the linear intensity before the logarithm: L = log(I + log_epsilon).
  double log_epsilon = 1e-3;
  // Seed of the mismatch and noise random generators (same seed, same events).
  uint64_t seed = 1;
  // Worker threads for the per-pixel loop (1 or more).
  int num_threads = 2;

  // The options with mismatch, refractory period, noise, leak, hot pixels, low-pass and read-out
  // limit switched off (the `--clean` flag).
  EsimOptions Clean() const;

  // True when any part of the realistic pixel is on (low-pass, light-dependent noise, leak, hot
  // pixels, read-out limit); false for the ideal pixel, whose events are those of the original
  // ESIM bit for bit.
  bool UsesPixelModel() const;

  // Throws InvalidArgumentError when a threshold is not positive and finite, a rate, spread,
  // intensity or sigma is negative or not finite, the hot-pixel fraction is not in [0, 1), the
  // refractory period or read-out delay is negative, log_epsilon is not positive, or
  // num_threads < 1.
  void Check() const;
};

// The `--sensor` presets: "ideal" (the defaults above), "davis240", "davis346", "gen3", "gen4"
// (parameters and their sources in docs/simulator.md). Throws InvalidArgumentError naming the
// valid names for any other name.
EsimOptions SensorPreset(const std::string& name);

// The names SensorPreset accepts, in order.
const std::vector<std::string>& SensorPresetNames();

// What kind of mechanism produced an event.
enum class EventOrigin : uint8_t { kSignal = 0, kNoise = 1, kLeak = 2, kHotPixel = 3 };

// Counts of the events a simulator emitted and of those it suppressed or dropped.
struct EsimCounts {
  // Events emitted, all kinds.
  int64_t events = 0;
  // Emitted events caused by a change of the (filtered) log intensity.
  int64_t signal = 0;
  // Emitted shot-noise (background-activity) events.
  int64_t noise = 0;
  // Emitted leak events.
  int64_t leak = 0;
  // Emitted hot-pixel events.
  int64_t hot_pixel = 0;
  // Events suppressed by the refractory period (realistic pixel only; all kinds).
  int64_t refractory_suppressed = 0;
  // Events dropped by the read-out limit (waited longer than readout_max_delay_ns).
  int64_t readout_dropped = 0;
  // Emitted events whose time stamp the read-out queue delayed.
  int64_t readout_delayed = 0;
  // Longest read-out delay of an emitted event, nanoseconds.
  int64_t readout_max_delay_ns = 0;

  // Adds another set of counts (maximum for the delay).
  void Add(const EsimCounts& other);
};

// Simulates events from images given in time order. Usage: Initialize() with the first image,
// then AddImage() for each following image; each call appends the events of the interval
// between the previous image and this one, sorted by time. With a read-out limit, events wait in
// the read-out queue and may carry a time after the image's (still in non-decreasing order over
// the whole sequence).
class EventSimulator {
 public:
  // A simulator for images of `width` x `height` pixels. Throws InvalidArgumentError when the
  // options fail Check() or the size is not in (0, 65535].
  EventSimulator(int width, int height, const EsimOptions& options);

  // Sets every reference level to the log of `intensity` (CV_32FC1, linear, >= 0) at t_ns.
  // Throws InvalidArgumentError when the image has the wrong size or type.
  void Initialize(const cv::Mat& intensity, int64_t t_ns);

  // Appends to `events` the events between the previous image and `intensity` at t_ns, sorted by
  // time (ties by row, then column); every time is in (previous t_ns, t_ns], or later by the
  // read-out delay when a read-out limit is set. `origins`, when not null, receives the origin of
  // each appended event. Throws InvalidArgumentError when not initialised, t_ns does not
  // increase, or the image is wrong.
  void AddImage(const cv::Mat& intensity, int64_t t_ns, EventBuffer* events,
                std::vector<EventOrigin>* origins = nullptr);

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
  // The photoreceptor output (low-passed log intensity) per pixel (CV_32FC1); the log intensity
  // itself when there is no low-pass. Empty for the ideal pixel.
  const cv::Mat& filtered_log_intensity() const { return filtered_; }
  // Indices (row * width + column) of the hot pixels, ascending.
  const std::vector<int32_t>& hot_pixels() const { return hot_pixels_; }
  // Per-pixel leak rates, Hz (empty without leak).
  const std::vector<float>& leak_rates_hz() const { return leak_rate_hz_; }
  // What was emitted, suppressed and dropped so far.
  const EsimCounts& counts() const { return counts_; }

 private:
  // Converts a linear image to log intensity in `log_image`.
  void LogImage(const cv::Mat& intensity, cv::Mat* log_image) const;
  // Emits the crossing events of rows [row_begin, row_end) into `out` (unsorted).
  void SimulateRows(int row_begin, int row_end, const cv::Mat& new_log, int64_t t_new_ns,
                    std::vector<Event>* out);
  // Emits the background-activity noise events of the interval (last_t_ns_, t_new_ns]: uniform
  // over the image, or thinned by each pixel's light when `new_log` (the new log image) is given
  // and noise_half_intensity > 0.
  void AddNoise(int64_t t_new_ns, const cv::Mat* new_log,
                const std::function<void(const Event&)>& emit);
  // One event of the realistic pixel before the refractory period and the read-out.
  struct Candidate {
    Event event;
    EventOrigin origin;
  };
  // The realistic pixel's AddImage (UsesPixelModel()).
  void AddImageWithPixelModel(const cv::Mat& new_log, int64_t t_new_ns, EventBuffer* events,
                              std::vector<EventOrigin>* origins);
  // Low-pass, leak and threshold crossings of rows [row_begin, row_end) into `out` (unsorted).
  void SimulatePixelModelRows(int row_begin, int row_end, const cv::Mat& new_log, int64_t t_new_ns,
                              std::vector<Candidate>* out);
  // Light-dependent shot noise and hot-pixel events of the interval into `out`.
  void AddPixelModelNoise(const cv::Mat& new_log, int64_t t_new_ns, std::vector<Candidate>* out);

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
  // The realistic pixel's state (empty for the ideal pixel).
  cv::Mat filtered_;                  // photoreceptor output (log units)
  cv::Mat leak_debt_;                 // leak drift not yet paid by a leak event (log units)
  std::vector<float> leak_rate_hz_;   // per-pixel leak rate
  std::vector<int32_t> hot_pixels_;   // hot pixel indices, ascending
  std::vector<int8_t> hot_polarity_;  // the polarity of each hot pixel
  std::mt19937_64 hot_rng_;           // hot-pixel event times
  double readout_next_free_ns_ = 0;   // when the read-out arbiter is next free
  std::vector<std::vector<Candidate>> thread_candidates_;
  EsimCounts counts_;
};

}  // namespace evloc::sim
