#include "tools/sim/simulate.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// The exposure window of frame k: [start, end], time stamp mid.
struct FrameWindow {
  int64_t start_ns;
  int64_t mid_ns;
  int64_t end_ns;
};

FrameWindow WindowOf(int64_t index, const FrameSensorOptions& frames) {
  const auto start = static_cast<int64_t>(std::llround(index * 1e9 / frames.fps));
  const auto exposure = static_cast<int64_t>(std::llround(frames.exposure_s * 1e9));
  return {start, start + exposure / 2, start + exposure};
}

}  // namespace

void SequenceOptions::Check() const {
  esim.Check();
  frames.Check();
  illumination.Check();
  if (!(max_pixel_motion_px > 0) || max_render_interval_ns <= 0 || min_render_interval_ns <= 0 ||
      min_render_interval_ns > max_render_interval_ns || motion_sample_stride_px <= 0 ||
      event_batch_size == 0) {
    throw InvalidArgumentError(
        "Sequence options: the pixel motion bound, render interval bounds (min <= max), sample "
        "stride and event batch size must be positive.");
  }
}

double MaxImageMotion(const Camera& camera, const std::vector<Eigen::Vector3d>& points_world,
                      const std::vector<Eigen::Vector2d>& pixels, const Rigid3d& world_from_cam) {
  const Rigid3d cam_from_world = world_from_cam.Inverse();
  double largest = 0;
  Eigen::Vector2d projected;
  for (size_t i = 0; i < points_world.size(); ++i) {
    if (!camera.Project(cam_from_world * points_world[i], &projected)) {
      return std::numeric_limits<double>::infinity();
    }
    largest = std::max(largest, (projected - pixels[i]).squaredNorm());
  }
  return std::sqrt(largest);
}

SequenceStats SimulateSequence(const RenderFunction& render, const Camera& camera,
                               const CameraMotion& motion, const SequenceOptions& options,
                               const EventSink& event_sink, const FrameSink& frame_sink) {
  options.Check();
  camera.Check();
  const int64_t duration = motion.duration_ns();
  if (duration <= 0) throw InvalidArgumentError("SimulateSequence: the motion has no duration.");

  SequenceStats stats;
  EventSimulator esim(camera.width, camera.height, options.esim);
  FrameSensor sensor(options.frames);
  const cv::Mat rays = options.illumination.IsUniform() ? cv::Mat() : ComputeRayTable(camera);
  EventBuffer events;

  int64_t frame_index = 0;
  std::optional<FrameWindow> window = WindowOf(0, options.frames);
  if (window->end_ns > duration) window.reset();
  std::unique_ptr<ExposureIntegrator> exposure;
  cv::Mat frame_depth;

  std::vector<Eigen::Vector3d> sample_points;
  std::vector<Eigen::Vector2d> sample_pixels;
  cv::Mat gray;
  cv::Mat rgb;
  cv::Mat depth;
  int64_t t = 0;
  int64_t step = options.max_render_interval_ns;
  while (true) {
    // Render and process the image at t.
    const Rigid3d pose = motion.WorldFromCam(t);
    const bool in_window = window && t >= window->start_ns && t <= window->end_ns;
    auto start = Clock::now();
    render(pose, &gray, in_window ? &rgb : nullptr, &depth);
    stats.render_seconds += SecondsSince(start);
    ++stats.num_renders;
    ApplyIllumination(options.illumination, rays, pose, depth, &gray);

    start = Clock::now();
    if (t == 0) {
      esim.Initialize(gray, t);
    } else {
      esim.AddImage(gray, t, &events);
    }
    stats.esim_seconds += SecondsSince(start);
    if (events.size() >= options.event_batch_size) {
      stats.num_events += static_cast<int64_t>(events.size());
      event_sink(events);
      events.clear();
    }

    if (in_window) {
      start = Clock::now();
      ApplyIllumination(options.illumination, rays, pose, depth, &rgb);
      if (t == window->start_ns) {
        exposure = std::make_unique<ExposureIntegrator>(window->start_ns, window->end_ns);
      }
      exposure->Add(rgb, t);
      if (t == window->mid_ns) frame_depth = depth.clone();
      if (t == window->end_ns) {
        frame_sink(window->mid_ns, sensor.Expose(exposure->Mean()), frame_depth);
        ++stats.num_frames;
        exposure.reset();
        window = WindowOf(++frame_index, options.frames);
        if (window->end_ns > duration) window.reset();
      }
      stats.frame_seconds += SecondsSince(start);
    }
    if (t >= duration) break;

    // World points seen now, to measure the image motion of candidate next poses.
    sample_points.clear();
    sample_pixels.clear();
    const Rigid3d& world_from_cam = pose;
    for (int row = options.motion_sample_stride_px / 2; row < camera.height;
         row += options.motion_sample_stride_px) {
      for (int col = options.motion_sample_stride_px / 2; col < camera.width;
           col += options.motion_sample_stride_px) {
        const float z = depth.at<float>(row, col);
        Eigen::Vector3d ray;
        if (z > 0 && camera.Unproject(Eigen::Vector2d(col, row), &ray)) {
          sample_points.push_back(world_from_cam * (ray * static_cast<double>(z)));
          sample_pixels.emplace_back(col, row);
        }
      }
    }

    // The next render time: the next forced time (exposure start, middle, end) or the end of the
    // sequence, or earlier, halving the step until the image motion is small enough.
    int64_t next_forced = duration;
    if (window.has_value()) {
      const FrameWindow current = *window;
      if (current.start_ns > t) {
        next_forced = std::min(next_forced, current.start_ns);
      } else if (current.mid_ns > t) {
        next_forced = std::min(next_forced, current.mid_ns);
      } else if (current.end_ns > t) {
        next_forced = std::min(next_forced, current.end_ns);
      }
    }
    step = std::min(step * 2, options.max_render_interval_ns);
    int64_t next = std::min(t + step, next_forced);
    while (true) {
      const double image_motion =
          MaxImageMotion(camera, sample_points, sample_pixels, motion.WorldFromCam(next));
      if (image_motion <= options.max_pixel_motion_px ||
          next - t <= options.min_render_interval_ns) {
        if (std::isfinite(image_motion)) {
          stats.max_measured_motion_px = std::max(stats.max_measured_motion_px, image_motion);
        }
        break;
      }
      next = t + std::max((next - t) / 2, options.min_render_interval_ns);
    }
    step = next - t;
    t = next;
  }
  stats.num_events += static_cast<int64_t>(events.size());
  if (!events.empty()) event_sink(events);
  return stats;
}

}  // namespace evloc::sim
