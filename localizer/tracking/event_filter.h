// Noise filters applied to the events of a session before they reach the time surfaces
// (docs/tracking.md, "Noise filters"): hot-pixel masking, a refractory period and a
// background-activity filter, all in sensor pixels. The filtering is causal and depends only on
// the event stream, never on how it is split into packets, so the tracker's poses stay the same
// for any packet split (and evloc-track and the service stay bit-identical).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include "core/events/event.h"
#include "localizer/tracking/tracker_options.h"

namespace evloc::tracking {

// What the filters did with the events given so far. input = passed + held + the three removed
// counts.
struct EventFilterCounts {
  // Events given (Process).
  int64_t input = 0;
  // Events that passed every filter (returned by Process or AdvanceTo).
  int64_t passed = 0;
  // Events held back while the hot-pixel filter learns (not yet returned).
  int64_t held = 0;
  // Events removed because their pixel was masked as hot.
  int64_t hot_pixel = 0;
  // Events removed by the refractory period.
  int64_t refractory = 0;
  // Events removed by the background-activity filter (no neighbour fired within its window).
  int64_t background_activity = 0;
  // Pixels masked as hot now.
  int64_t masked_pixels = 0;
};

// The filters of one session (not thread-safe). Events are processed in time order in three
// stages: (1) hot pixels: every pixel's events are counted in consecutive windows of
// hot_pixel_window_s; at the end of a window a pixel is masked when its count reaches
// hot_pixel_min_rate_hz x window, hot_pixel_rate_factor x the median count of the unmasked
// pixels that fired in the window, and hot_pixel_rate_factor x the median count of its 8
// neighbours (at least 1); a masked pixel is unmasked when its count falls below half of its
// threshold (a window without any event unmasks every pixel). The first window is the
// learning period: its events are held back and filtered with the mask learned from it, so a
// pixel hot from the first event never reaches the surfaces. (2) refractory: an event less than
// refractory_period_s after the last event of its pixel that passed this stage is removed.
// (3) background activity (Delbruck): an event passes only when one of its 8 neighbours (and
// with background_activity_include_self the pixel itself) had an event, passed or not, within
// background_activity_window_s before it.
class EventFilter {
 public:
  // Filters events of a sensor of `sensor_size` pixels. Throws InvalidArgumentError when the
  // options or the size are invalid.
  EventFilter(SensorSize sensor_size, const EventFilterOptions& options);

  // True when some filter is on (otherwise Process returns its input unchanged).
  bool enabled() const { return enabled_; }
  // True while the hot-pixel filter holds back the events of its learning period.
  bool holding() const { return learning_ && !held_.empty(); }

  // Filters `events` (time-ordered, none before an event given earlier) and returns those that
  // pass, in order, together with the held-back events a complete learning period releases; the
  // reference is valid until the next call. With every filter off it is `events` itself. Throws
  // InvalidArgumentError for an event outside the sensor, before changing anything.
  const EventBuffer& Process(const EventBuffer& events);

  // Declares that no event at or before `t_ns` will follow: ends a learning period that is
  // complete by then and returns the held-back events that pass (empty otherwise).
  const EventBuffer& AdvanceTo(int64_t t_ns);

  // What the filters did so far.
  const EventFilterCounts& counts() const { return counts_; }
  // True when sensor pixel (x, y) is masked as hot now. Unchecked.
  bool IsMasked(int x, int y) const {
    return options_.hot_pixels &&
           (pixel_state_[static_cast<size_t>(y) * width_ + x] & kMaskedBit) != 0;
  }

 private:
  // A pixel's state: its count in the current window, and this bit when it is masked.
  static constexpr uint32_t kMaskedBit = uint32_t{1} << 31;

  // Closes the windows that end at or before t_ns (the first event also opens the first one).
  void CloseWindowsUntil(int64_t t_ns);
  // Judges the window [window_start_ns_, window_end_ns_) (or its first `duration_ns` when the
  // learning period ends early), updates the mask and starts the next window at `next_start_ns`.
  void CloseWindow(int64_t duration_ns, int64_t next_start_ns);
  // The median count in the current window of the (up to 8) neighbours of `pixel`.
  uint32_t NeighbourMedianCount(uint32_t pixel) const;
  // Ends the learning period: judges it and runs its held-back events through the stages 2-3.
  void EndLearning(int64_t duration_ns, int64_t next_start_ns);
  // Stages 2-3 (and the mask of stage 1) for one event; appends it to out_ when it passes.
  void Pass(size_t index, int64_t t_ns, uint16_t x, uint16_t y, int8_t polarity);
  // Makes room for `count` more events in out_ (written by index, trimmed by FinishOutput).
  void ReserveOutput(size_t count);
  // Trims out_ to the events written.
  const EventBuffer& FinishOutput();

  EventFilterOptions options_;
  bool enabled_ = false;
  int width_ = 0;
  int height_ = 0;
  int64_t window_ns_ = 0;
  int64_t refractory_ns_ = 0;
  int64_t background_window_ns_ = 0;
  // Hot pixels: per-pixel state (count in the current window | kMaskedBit), the pixels counted
  // in the window, the masked pixels.
  std::vector<uint32_t> pixel_state_;
  std::vector<uint32_t> touched_;
  std::vector<uint32_t> masked_list_;
  std::vector<uint32_t> scratch_counts_;
  std::vector<uint32_t> scratch_unmask_;
  std::vector<uint32_t> scratch_mask_;
  bool started_ = false;
  bool learning_ = false;
  int64_t window_start_ns_ = 0;
  int64_t window_end_ns_ = 0;
  EventBuffer held_;
  // Refractory: per pixel, the time of its last event that passed the refractory stage.
  std::vector<int64_t> last_passed_ns_;
  // Background activity: per pixel of the sensor padded by one pixel on each side (so that the
  // 8 neighbours need no border test), the time of its last event.
  std::vector<int64_t> last_event_ns_;
  EventBuffer out_;
  // Events written to out_ (its arrays may be longer until FinishOutput).
  size_t out_count_ = 0;
  EventFilterCounts counts_;
};

// The command-line flags of the noise filters shared by evloc-track and evloc-localizer serve:
// when `flag` is one of them, sets its field of `options` from `value` and returns true (throws
// InvalidArgumentError for a malformed value); returns false for any other flag.
bool ApplyEventFilterFlag(std::string_view flag, std::string_view value,
                          EventFilterOptions* options);
// Their usage lines (two-space indent, the descriptions from column 26).
extern const char kEventFilterFlagsUsage[];

}  // namespace evloc::tracking
