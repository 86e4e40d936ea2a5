// Time surfaces (docs/tracking.md, "Time surfaces"): per pixel of the ideal pinhole image, the time
// stamp of the last event, for all events and separately for ON and OFF events. Events are
// undistorted one by one through a pixel look-up table built once per session; no image is remapped
// per step.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera/undistortion_table.h"
#include "core/events/event.h"
#include "localizer/tracking/potential_field.h"

namespace evloc::tracking {

// One of the three surfaces.
enum class SurfaceChannel : int {
  // Every event, whatever its polarity (the unsigned surface).
  kAll = 0,
  // ON events only.
  kOn = 1,
  // OFF events only.
  kOff = 2,
};

// The time stamp of a pixel that has never fired.
inline constexpr int64_t kNeverFired = std::numeric_limits<int64_t>::min();

// The decay of a time surface: T(x, t) = exp(-(t - t_last) / tau), and T <= threshold counts as
// empty (T = 0).
struct SurfaceDecay {
  // tau, nanoseconds.
  double decay_time_ns = 3e7;
  // The emptiness threshold delta.
  double empty_threshold = 0.1;

  // T for a pixel last fired at `last_t_ns`, evaluated at `t_ns` (events later than t_ns count
  // as fired at t_ns); 0 when empty or never fired.
  double Value(int64_t last_t_ns, int64_t t_ns) const;
  // The age beyond which a pixel is certainly empty, nanoseconds.
  int64_t MaxActiveAgeNs() const;
  // The largest age at which a pixel is still active (Value > 0), nanoseconds: a pixel is active
  // exactly when t_ns - last_t_ns <= this.
  int64_t MaxActiveAgeExactNs() const;
};

// T = exp(-age / tau) for the ages a pixel is active at, without a library call (the lazy field
// evaluates it for every pixel it samples first in a step): a table of exp(-k / 16) times a
// degree-5 Taylor polynomial of the remainder r in [0, 1/16). Relative error below 1e-10, far
// below the float the field stores; activity itself is decided on the exact age bound.
class DecayExponential {
 public:
  // For `decay`; ages up to decay.MaxActiveAgeExactNs() are active.
  explicit DecayExponential(const SurfaceDecay& decay);

  // The largest active age, nanoseconds (SurfaceDecay::MaxActiveAgeExactNs).
  int64_t max_active_age_ns() const { return max_active_age_ns_; }

  // exp(-age_ns / tau) for 0 <= age_ns <= max_active_age_ns(). Unchecked.
  double operator()(int64_t age_ns) const {
    const double x = static_cast<double>(age_ns) * inverse_tau_ns_;
    const int k = static_cast<int>(x * kStepsPerUnit);
    const double r = x - k * (1.0 / kStepsPerUnit);
    const double polynomial =
        1 - r * (1 - r * (1.0 / 2 - r * (1.0 / 6 - r * (1.0 / 24 - r * (1.0 / 120)))));
    return table_[k] * polynomial;
  }

 private:
  static constexpr int kStepsPerUnit = 16;
  double inverse_tau_ns_ = 0;
  int64_t max_active_age_ns_ = 0;
  // exp(-k / kStepsPerUnit), k = 0 .. the largest active age in steps, plus one.
  std::vector<double> table_;
};

// Per-pixel last time stamps of the ideal pinhole image of a camera.
class TimeSurface {
 public:
  // Builds the sensor-pixel to ideal-pixel look-up (nearest integer pixel) from `table`. Sensor
  // pixels whose undistorted position falls outside the image are dropped on insertion.
  explicit TimeSurface(const UndistortionTable& table);
  // The same look-up for `camera` binned `binning` x `binning` (UndistortionTable(camera,
  // binning)) without building the table. InvalidArgumentError for an invalid camera or binning.
  TimeSurface(const Camera& camera, int binning);

  // Image width, pixels.
  int width() const { return width_; }
  // Image height, pixels.
  int height() const { return height_; }

  // Stores events [begin, end) of `events`: one table look-up and two stores per event (and two
  // more per hole the event's sensor pixel fills, see ForEachIdealPixel). Throws
  // InvalidArgumentError for an event outside the sensor (nothing after it is stored).
  void Insert(const EventBuffer& events, size_t begin, size_t end);

  // Forgets every event.
  void Clear();

  // The last time stamp of ideal pixel (x, y) in `channel`, or kNeverFired. Unchecked.
  int64_t LastTimestamp(SurfaceChannel channel, int x, int y) const {
    return last_t_ns_[static_cast<int>(channel)][static_cast<size_t>(y) * width_ + x];
  }

  // The last time stamps of `channel`, one per ideal pixel, row-major (kNeverFired when never
  // fired). Valid until the surface is destroyed.
  const int64_t* LastTimestamps(SurfaceChannel channel) const {
    return last_t_ns_[static_cast<int>(channel)].data();
  }

  // The row-major ideal pixel index of sensor pixel (x, y), or -1 when it has none. Unchecked.
  int32_t IdealPixelIndex(int x, int y) const {
    return sensor_to_pixel_[static_cast<size_t>(y) * sensor_width_ + x];
  }

  // Calls visit(index) for every ideal pixel sensor pixel (x, y) fills: its own (IdealPixelIndex,
  // when it has one), then the holes it also fills (see holes_). Unchecked.
  template <typename Visit>
  void ForEachIdealPixel(int x, int y, Visit&& visit) const {
    const size_t sensor = static_cast<size_t>(y) * sensor_width_ + x;
    if (sensor_to_pixel_[sensor] >= 0) visit(sensor_to_pixel_[sensor]);
    if (hole_begin_.empty()) return;
    for (uint32_t k = hole_begin_[sensor]; k < hole_begin_[sensor + 1]; ++k) visit(holes_[k]);
  }

  // Number of ideal pixels no sensor pixel maps to by rounding that are filled from the sensor
  // pixel their ray falls on (0 for a pinhole sensor).
  size_t num_filled_holes() const { return holes_.size(); }

  // Number of inserted events that were dropped because their undistorted pixel lies outside
  // the image.
  int64_t num_dropped() const { return num_dropped_; }
  // Number of inserted events that were stored.
  int64_t num_stored() const { return num_stored_; }

  // T(x, t_ns) of every ideal pixel of `channel` (CV_32FC1, SurfaceDecay::Value: 0 when empty).
  cv::Mat Values(SurfaceChannel channel, int64_t t_ns, const SurfaceDecay& decay) const;
  // The same into `values` (its memory reused when it already has the surface's size and type).
  void Values(SurfaceChannel channel, int64_t t_ns, const SurfaceDecay& decay,
              cv::Mat* values) const;
  // The binary mask (CV_8UC1, 255 = active) of pixels of `channel` with T(x, t_ns) > threshold:
  // Values > 0.
  cv::Mat ActiveMask(SurfaceChannel channel, int64_t t_ns, const SurfaceDecay& decay) const;

 private:
  int width_ = 0;
  int height_ = 0;
  int sensor_width_ = 0;
  int sensor_height_ = 0;
  // Per sensor pixel (row-major), the index of its ideal pixel, or -1.
  std::vector<int32_t> sensor_to_pixel_;
  // Holes: where the undistortion stretches the image (the periphery of a barrel lens), sensor
  // pixels rounded to their ideal pixels leave ideal pixels between them that nothing maps to
  // (22 % of a DAVIS240's ideal image inside its footprint, 35-43 % beyond half its focal
  // length from the centre), which would never fire and read as "no edge" to the registration.
  // Each such pixel whose ray falls on the sensor is filled by the sensor pixel nearest to where
  // it falls: sensor pixel s also stores its events at holes_[hole_begin_[s] .. hole_begin_[s+1]).
  // Both empty when there is no hole.
  std::vector<uint32_t> hole_begin_;
  std::vector<int32_t> holes_;
  // Per channel, per ideal pixel (row-major), the last time stamp.
  std::vector<int64_t> last_t_ns_[3];
  int64_t num_dropped_ = 0;
  int64_t num_stored_ = 0;

  // Sizes the look-up for `sensor` and `ideal` (every sensor pixel dropped), for SetIdealPixel.
  void StartLookup(const Camera& sensor, const Camera& ideal);
  // Maps sensor pixel (x, y) to the ideal pixel nearest to `ideal_pixel` (dropped outside).
  void SetIdealPixel(int x, int y, const Eigen::Vector2f& ideal_pixel);
  // After every SetIdealPixel: fills the holes (see holes_) from the sensor pixels their rays
  // fall on through `sensor` (its ideal camera `ideal`).
  void FillHoles(const Camera& sensor, const Camera& ideal);
};

// The potential field 1 - T of one channel of a time surface at one time, optionally smoothed,
// evaluated lazily: only pixels that are sampled are computed, and memoised until the next
// SetTime. Reads the surface live: events inserted after SetTime show through, so call SetTime
// after inserting.
class TimeSurfaceField final : public PotentialField {
 public:
  // `surface` must outlive the field.
  TimeSurfaceField(const TimeSurface& surface, SurfaceChannel channel, const SurfaceDecay& decay,
                   bool smooth);

  // Sets the evaluation time and forgets memoised values.
  void SetTime(int64_t t_ns);
  // Changes the decay for the values computed after the next SetTime.
  void SetDecay(const SurfaceDecay& decay);
  // The decay in use.
  const SurfaceDecay& decay() const { return decay_; }
  // The evaluation time.
  int64_t time_ns() const { return t_ns_; }

  int width() const override { return surface_.width(); }
  int height() const override { return surface_.height(); }

  // The unsmoothed value 1 - T at pixel (x, y), 1 where empty, memoised. Unchecked.
  float RawValue(int x, int y) {
    const size_t index = static_cast<size_t>(y) * surface_.width() + x;
    return RawValue(&raw_[index], index, stamp_);
  }
  // The field value at pixel (x, y) (smoothed when enabled), memoised. Unchecked.
  float ValueAt(int x, int y) { return smooth_ ? SmoothedValue(x, y) : RawValue(x, y); }

  // Inline even where it is large: the solver's hot loop calls it through the concrete type.
  [[gnu::always_inline]] bool Sample(double u, double v, double* value,
                                     Eigen::Vector2d* gradient) override {
    if (smooth_) {
      return SampleBilinear(
          surface_.width(), surface_.height(), u, v,
          [this](int x, int y) { return SmoothedValue(x, y); }, value, gradient);
    }
    int x0;
    int y0;
    double a;
    double b;
    if (!LocateCell(surface_.width(), surface_.height(), u, v, &x0, &y0, &a, &b)) return false;
    // The four raw values of the cell from one base index, with the stamp read once.
    const size_t width = surface_.width();
    const size_t index = y0 * width + x0;
    Memo* memo = raw_.data() + index;
    const uint32_t stamp = stamp_;
    const double f00 = RawValue(memo, index, stamp);
    const double f10 = RawValue(memo + 1, index + 1, stamp);
    const double f01 = RawValue(memo + width, index + width, stamp);
    const double f11 = RawValue(memo + width + 1, index + width + 1, stamp);
    InterpolateCell(a, b, f00, f10, f01, f11, value, gradient);
    return true;
  }

  // Hints the memoised values of the bilinear cell at (u, v) into the cache ahead of Sample (the
  // solver calls it a few points ahead). (u, v) must lie inside the image. No effect on values.
  void Prefetch(double u, double v) const {
    const size_t width = surface_.width();
    const size_t index = static_cast<size_t>(v) * width + static_cast<size_t>(u);
    const Memo* memo = (smooth_ ? smoothed_.data() : raw_.data()) + index;
    __builtin_prefetch(memo);
    __builtin_prefetch(memo + 1);
    __builtin_prefetch(memo + width);
    __builtin_prefetch(memo + width + 1);
  }

  // The whole field as an image (CV_32FC1), computed densely; equal to ValueAt everywhere up to
  // float rounding. Used by FieldEvaluation::kDense and by tests.
  cv::Mat RenderDense() const;

  // Number of pixels computed (smoothed values) since the last SetTime.
  int64_t num_evaluated() const { return num_evaluated_; }

 private:
  // A memoised value and the stamp of the time it was computed for (one 8-byte load per pixel).
  struct Memo {
    uint32_t stamp = 0;
    float value = 1.0f;
  };

  // The memoised raw value of pixel `index` (memo = &raw_[index]) at `stamp` (= stamp_).
  float RawValue(Memo* memo, size_t index, uint32_t stamp) {
    if (memo->stamp != stamp) [[unlikely]] {
      memo->value = ComputeRaw(index);
      memo->stamp = stamp;
    }
    return memo->value;
  }
  // 1 - decay_.Value(last_t, t_ns_) of pixel `index`, with the exponential from the table. Inline:
  // the solver's loop then makes no call (a call would spill its registers).
  float ComputeRaw(size_t index) const {
    const int64_t last_t = surface_.LastTimestamps(channel_)[index];
    if (last_t == kNeverFired) return 1.0f;
    const int64_t age_ns = std::max<int64_t>(0, t_ns_ - last_t);
    if (age_ns > exponential_.max_active_age_ns()) return 1.0f;
    return static_cast<float>(1.0 - exponential_(age_ns));
  }
  float SmoothedValue(int x, int y);

  const TimeSurface& surface_;
  SurfaceChannel channel_;
  SurfaceDecay decay_;
  DecayExponential exponential_;
  bool smooth_;
  int64_t t_ns_ = 0;
  // Memo stamp of the current time; a value is valid when its stamp equals this.
  uint32_t stamp_ = 1;
  std::vector<Memo> raw_;
  std::vector<Memo> smoothed_;
  int64_t num_evaluated_ = 0;
};

}  // namespace evloc::tracking
