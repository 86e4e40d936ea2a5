#include "tools/sim/simulate.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>

#include "core/common/error.h"
#include "tools/sim/events_from_frames.h"

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
  if (!(max_pixel_motion_px > 0) || !(max_render_motion_px >= max_pixel_motion_px) ||
      max_render_interval_ns <= 0 || min_render_interval_ns <= 0 ||
      min_render_interval_ns > max_render_interval_ns || motion_sample_stride_px <= 0 ||
      event_batch_size == 0) {
    throw InvalidArgumentError(
        "Sequence options: the pixel motion bounds (render >= ESIM), render interval bounds (min "
        "<= max), sample "
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

cv::Mat FlowFromDepth(const Camera& camera, const cv::Mat& rays, const cv::Mat& depth,
                      const Rigid3d& world_from_a, const Rigid3d& world_from_b) {
  const Rigid3d b_from_a = world_from_b.Inverse() * world_from_a;
  const Eigen::Matrix3d rotation = b_from_a.RotationMatrix();
  cv::Mat flow(depth.size(), CV_32FC2, cv::Scalar(0, 0));
  cv::parallel_for_(
      cv::Range(0, depth.rows),
      [&](const cv::Range& rows) {
        Eigen::Vector2d pixel;
        for (int row = rows.start; row < rows.end; ++row) {
          const float* depth_row = depth.ptr<float>(row);
          const auto* ray_row = rays.ptr<cv::Vec3f>(row);
          auto* flow_row = flow.ptr<cv::Vec2f>(row);
          for (int col = 0; col < depth.cols; ++col) {
            const float z = depth_row[col];
            const cv::Vec3f& ray = ray_row[col];
            if (!(z > 0) || !std::isfinite(ray[0])) continue;
            const Eigen::Vector3d point_a =
                Eigen::Vector3d(ray[0], ray[1], ray[2]) * static_cast<double>(z);
            if (camera.Project(rotation * point_a + b_from_a.translation, &pixel)) {
              flow_row[col] = cv::Vec2f(static_cast<float>(pixel.x() - col),
                                        static_cast<float>(pixel.y() - row));
            }
          }
        }
      },
      2);
  return flow;
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
  const cv::Mat rays = ComputeRayTable(camera);
  EventBuffer events;

  int64_t frame_index = 0;
  std::optional<FrameWindow> window = WindowOf(0, options.frames);
  if (window->end_ns > duration) window.reset();
  std::unique_ptr<ExposureIntegrator> exposure;
  cv::Mat frame_depth;
  const auto in_window = [&](int64_t t) {
    return window.has_value() && t >= window->start_ns && t <= window->end_ns;
  };
  // Feeds one image to ESIM, and its colour (when inside an exposure) to the frame camera.
  const auto process = [&](int64_t t, const cv::Mat& gray, const cv::Mat& rgb,
                           const cv::Mat* depth) {
    auto start = Clock::now();
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
    if (!in_window(t)) return;
    start = Clock::now();
    if (t == window->start_ns) {
      exposure = std::make_unique<ExposureIntegrator>(window->start_ns, window->end_ns);
    }
    exposure->Add(rgb, t);
    if (t == window->mid_ns) frame_depth = depth->clone();
    if (t == window->end_ns) {
      frame_sink(window->mid_ns, sensor.Expose(exposure->Mean()), frame_depth);
      ++stats.num_frames;
      exposure.reset();
      window = WindowOf(++frame_index, options.frames);
      if (window->end_ns > duration) window.reset();
    }
    stats.frame_seconds += SecondsSince(start);
  };
  // Renders at t with illumination applied; colour only inside an exposure window.
  const auto render_at = [&](int64_t t, const Rigid3d& pose, cv::Mat* gray, cv::Mat* rgb,
                             cv::Mat* depth) {
    const bool with_colour = in_window(t);
    const auto start = Clock::now();
    render(pose, gray, with_colour ? rgb : nullptr, depth);
    stats.render_seconds += SecondsSince(start);
    ++stats.num_renders;
    ApplyIllumination(options.illumination, rays, pose, *depth, gray);
    if (with_colour) ApplyIllumination(options.illumination, rays, pose, *depth, rgb);
  };

  std::vector<Eigen::Vector3d> sample_points;
  std::vector<Eigen::Vector2d> sample_pixels;
  cv::Mat gray;
  cv::Mat rgb;
  cv::Mat depth;
  cv::Mat next_gray;
  cv::Mat next_rgb;
  cv::Mat next_depth;
  int64_t t = 0;
  Rigid3d pose = motion.WorldFromCam(0);
  render_at(0, pose, &gray, &rgb, &depth);
  process(0, gray, rgb, &depth);
  int64_t step = options.max_render_interval_ns;
  while (t < duration) {
    // World points seen now, to measure the image motion of candidate next poses.
    sample_points.clear();
    sample_pixels.clear();
    for (int row = options.motion_sample_stride_px / 2; row < camera.height;
         row += options.motion_sample_stride_px) {
      for (int col = options.motion_sample_stride_px / 2; col < camera.width;
           col += options.motion_sample_stride_px) {
        const float z = depth.at<float>(row, col);
        const cv::Vec3f& ray = rays.at<cv::Vec3f>(row, col);
        if (z > 0 && std::isfinite(ray[0])) {
          sample_points.push_back(
              pose * (Eigen::Vector3d(ray[0], ray[1], ray[2]) * static_cast<double>(z)));
          sample_pixels.emplace_back(col, row);
        }
      }
    }

    // The next render time: the next forced time (exposure start, middle, end) or the end of the
    // sequence, or earlier, halving the step until the image motion is at most the render bound.
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
    double image_motion = 0;
    while (true) {
      image_motion =
          MaxImageMotion(camera, sample_points, sample_pixels, motion.WorldFromCam(next));
      if (image_motion <= options.max_render_motion_px ||
          next - t <= options.min_render_interval_ns) {
        break;
      }
      next = t + std::max((next - t) / 2, options.min_render_interval_ns);
    }
    const Rigid3d next_pose = motion.WorldFromCam(next);
    render_at(next, next_pose, &next_gray, &next_rgb, &next_depth);

    // Images between the two renders, warped along the exact flow from the rendered depth, so
    // that consecutive ESIM images are at most max_pixel_motion_px apart.
    const int substeps =
        std::isfinite(image_motion)
            ? std::max(1, static_cast<int>(std::ceil(image_motion / options.max_pixel_motion_px)))
            : 1;
    if (std::isfinite(image_motion)) {
      stats.max_measured_motion_px =
          std::max(stats.max_measured_motion_px, image_motion / substeps);
    }
    if (substeps > 1) {
      const auto start = Clock::now();
      const cv::Mat flow_forward = FlowFromDepth(camera, rays, depth, pose, next_pose);
      const cv::Mat flow_backward = FlowFromDepth(camera, rays, next_depth, next_pose, pose);
      const bool colour = in_window(t) && in_window(next);
      stats.interpolation_seconds += SecondsSince(start);
      for (int k = 1; k < substeps; ++k) {
        const double alpha = static_cast<double>(k) / substeps;
        const int64_t t_k = t + static_cast<int64_t>(std::llround(alpha * (next - t)));
        if (t_k <= t || t_k >= next) continue;
        const auto interpolation_start = Clock::now();
        const cv::Mat gray_k =
            InterpolateFrame(gray, next_gray, flow_forward, flow_backward, alpha);
        const cv::Mat rgb_k =
            colour ? InterpolateFrame(rgb, next_rgb, flow_forward, flow_backward, alpha)
                   : cv::Mat();
        stats.interpolation_seconds += SecondsSince(interpolation_start);
        ++stats.num_interpolated;
        process(t_k, gray_k, rgb_k, nullptr);
      }
    }
    process(next, next_gray, next_rgb, &next_depth);
    step = next - t;
    t = next;
    pose = next_pose;
    std::swap(gray, next_gray);
    std::swap(rgb, next_rgb);
    std::swap(depth, next_depth);
  }
  stats.num_events += static_cast<int64_t>(events.size());
  if (!events.empty()) event_sink(events);
  stats.esim_counts = esim.counts();
  return stats;
}

}  // namespace evloc::sim
