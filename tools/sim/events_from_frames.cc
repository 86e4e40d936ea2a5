#include "tools/sim/events_from_frames.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Linear intensity in [0, 1] from an image file.
cv::Mat LoadLinear(const TimedFile& file, double gamma) {
  cv::Mat gray = ReadGrayImage(file.path);
  if (gamma != 1.0) cv::pow(gray, gamma, gray);
  return gray;
}

// 8-bit version of a [0, 1] image, for the flow estimator.
cv::Mat To8Bit(const cv::Mat& image) {
  cv::Mat out;
  image.convertTo(out, CV_8UC1, 255.0);
  return out;
}

// The `quantile` of the flow magnitudes.
double FlowQuantile(const cv::Mat& flow, double quantile) {
  std::vector<float> magnitudes;
  magnitudes.reserve(flow.total());
  for (int row = 0; row < flow.rows; ++row) {
    const auto* vectors = flow.ptr<cv::Vec2f>(row);
    for (int col = 0; col < flow.cols; ++col) {
      magnitudes.push_back(std::hypot(vectors[col][0], vectors[col][1]));
    }
  }
  if (magnitudes.empty()) return 0;
  const size_t index =
      std::min(magnitudes.size() - 1, static_cast<size_t>(quantile * (magnitudes.size() - 1)));
  std::nth_element(magnitudes.begin(), magnitudes.begin() + index, magnitudes.end());
  return magnitudes[index];
}

// The pixel coordinate grid (x, y) of a size, cached per thread.
const cv::Mat& PixelGrid(cv::Size size) {
  thread_local cv::Mat grid;
  if (grid.size() != size) {
    grid.create(size, CV_32FC2);
    for (int row = 0; row < size.height; ++row) {
      auto* out = grid.ptr<cv::Vec2f>(row);
      for (int col = 0; col < size.width; ++col) {
        out[col] = cv::Vec2f(static_cast<float>(col), static_cast<float>(row));
      }
    }
  }
  return grid;
}

// `frame` sampled at x - scale * flow(x).
cv::Mat WarpBack(const cv::Mat& frame, const cv::Mat& flow, double scale) {
  cv::Mat map;
  cv::scaleAdd(flow, -scale, PixelGrid(flow.size()), map);
  cv::Mat warped;
  cv::remap(frame, warped, map, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  return warped;
}

}  // namespace

void EventsFromFramesOptions::Check() const {
  esim.Check();
  if (!(max_pixel_motion_px > 0) || max_interpolated_per_pair < 0 || !(input_gamma > 0) ||
      !(flow_quantile > 0 && flow_quantile <= 1)) {
    throw InvalidArgumentError(
        "events-from-frames options: the pixel motion bound and gamma must be positive, the "
        "interpolation cap >= 0 and the flow quantile in (0, 1].");
  }
}

cv::Mat InterpolateFrame(const cv::Mat& frame0, const cv::Mat& frame1, const cv::Mat& flow01,
                         const cv::Mat& flow10, double alpha) {
  cv::Mat from0 = WarpBack(frame0, flow01, alpha);
  cv::Mat from1 = WarpBack(frame1, flow10, 1.0 - alpha);
  cv::Mat blended;
  cv::addWeighted(from0, 1.0 - alpha, from1, alpha, 0.0, blended);
  return blended;
}

EventsFromFramesStats EventsFromFrames(const std::vector<TimedFile>& images,
                                       const EventsFromFramesOptions& options,
                                       const std::function<void(const EventBuffer&)>& sink) {
  options.Check();
  if (images.size() < 2) {
    throw InvalidArgumentError("events-from-frames needs at least 2 frames, got " +
                               std::to_string(images.size()) + ".");
  }
  EventsFromFramesStats stats;
  cv::Mat previous = LoadLinear(images[0], options.input_gamma);
  EventSimulator esim(previous.cols, previous.rows, options.esim);
  esim.Initialize(previous, images[0].t_ns);
  cv::Ptr<cv::DISOpticalFlow> flow_estimator =
      cv::DISOpticalFlow::create(cv::DISOpticalFlow::PRESET_MEDIUM);
  stats.num_input_frames = 1;
  EventBuffer events;
  for (size_t i = 1; i < images.size(); ++i) {
    cv::Mat current = LoadLinear(images[i], options.input_gamma);
    if (current.size() != previous.size()) {
      throw InvalidArgumentError("events-from-frames: '" + images[i].path.string() +
                                 "' differs in size from the first frame.");
    }
    auto start = Clock::now();
    const cv::Mat previous8 = To8Bit(previous);
    const cv::Mat current8 = To8Bit(current);
    cv::Mat flow01;
    cv::Mat flow10;
    flow_estimator->calc(previous8, current8, flow01);
    flow_estimator->calc(current8, previous8, flow10);
    stats.flow_seconds += SecondsSince(start);

    start = Clock::now();
    const double motion = std::max(FlowQuantile(flow01, options.flow_quantile),
                                   FlowQuantile(flow10, options.flow_quantile));
    stats.max_flow_px = std::max(stats.max_flow_px, motion);
    const int steps = std::clamp(static_cast<int>(std::ceil(motion / options.max_pixel_motion_px)),
                                 1, options.max_interpolated_per_pair + 1);
    const int64_t t0 = images[i - 1].t_ns;
    const int64_t t1 = images[i].t_ns;
    for (int k = 1; k < steps; ++k) {
      const double alpha = static_cast<double>(k) / steps;
      const int64_t t_ns = t0 + static_cast<int64_t>(std::llround(alpha * (t1 - t0)));
      if (t_ns <= esim.last_time_ns() || t_ns >= t1) continue;
      esim.AddImage(InterpolateFrame(previous, current, flow01, flow10, alpha), t_ns, &events);
      ++stats.num_interpolated_frames;
    }
    esim.AddImage(current, t1, &events);
    ++stats.num_input_frames;
    stats.esim_seconds += SecondsSince(start);
    if (events.size() >= (1u << 20)) {
      stats.num_events += static_cast<int64_t>(events.size());
      sink(events);
      events.clear();
    }
    previous = current;
  }
  stats.num_events += static_cast<int64_t>(events.size());
  if (!events.empty()) sink(events);
  return stats;
}

}  // namespace evloc::sim
