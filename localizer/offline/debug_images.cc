#include "localizer/offline/debug_images.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace evloc::tracking {
namespace {

cv::Mat SurfaceImage(const Tracker& tracker, SurfaceChannel channel, int64_t t_ns) {
  const TimeSurface& surface = tracker.time_surface();
  SurfaceDecay decay;
  decay.decay_time_ns = tracker.options().decay_time_s * 1e9;
  decay.empty_threshold = tracker.options().empty_threshold;
  cv::Mat image(surface.height(), surface.width(), CV_8UC1);
  for (int y = 0; y < surface.height(); ++y) {
    auto* row = image.ptr<uint8_t>(y);
    for (int x = 0; x < surface.width(); ++x) {
      const double value = decay.Value(surface.LastTimestamp(channel, x, y), t_ns);
      row[x] = static_cast<uint8_t>(std::lround(255.0 * value));
    }
  }
  return image;
}

cv::Point ToPoint(const Eigen::Vector2d& pixel) {
  return cv::Point(static_cast<int>(std::lround(pixel.x())),
                   static_cast<int>(std::lround(pixel.y())));
}

}  // namespace

cv::Mat RenderTrackingDebugImage(const Tracker& tracker, const Map& map,
                                 const VisibilityIndex* visibility, const PoseEstimate& step,
                                 const Rigid3d& previous_world_from_cam) {
  const Camera& camera = tracker.ideal_camera();
  const cv::Mat all = SurfaceImage(tracker, SurfaceChannel::kAll, step.t_ns);
  const cv::Mat on = SurfaceImage(tracker, SurfaceChannel::kOn, step.t_ns);
  const cv::Mat off = SurfaceImage(tracker, SurfaceChannel::kOff, step.t_ns);

  cv::Mat panel_map;
  cv::cvtColor(all, panel_map, cv::COLOR_GRAY2BGR);
  cv::Mat panel_polarity;
  cv::merge(std::vector<cv::Mat>{off, cv::Mat::zeros(on.size(), CV_8UC1), on}, panel_polarity);
  cv::Mat panel_flow;
  cv::cvtColor(all / 3, panel_flow, cv::COLOR_GRAY2BGR);

  std::vector<uint32_t> points;
  if (visibility != nullptr) {
    points = visibility->Query(camera, step.world_from_cam);
  } else {
    points.resize(map.size());
    std::iota(points.begin(), points.end(), 0u);
  }
  const Rigid3d cam_from_world = step.world_from_cam.Inverse();
  const Rigid3d previous_cam_from_world = previous_world_from_cam.Inverse();
  const size_t stride = std::max<size_t>(1, points.size() / 400);
  for (size_t k = 0; k < points.size(); ++k) {
    const uint32_t index = points[k];
    const Eigen::Vector3d p_world = map.positions[index].cast<double>();
    const Eigen::Vector3d p_cam = cam_from_world * p_world;
    Eigen::Vector2d pixel;
    if (!camera.Project(p_cam, &pixel) || !camera.IsInside(pixel)) continue;
    const bool on_edge = all.at<uint8_t>(ToPoint(pixel)) > 0;
    cv::circle(panel_map, ToPoint(pixel), 1,
               on_edge ? cv::Scalar(0, 220, 0) : cv::Scalar(0, 0, 255), cv::FILLED);
    if (k % stride != 0) continue;
    // Predicted gradient: project P + s g, with s a small fraction of the depth.
    const double probe = 0.02 * p_cam.z();
    Eigen::Vector2d gradient_pixel;
    if (camera.Project(cam_from_world * (p_world + probe * map.gradients[index].cast<double>()),
                       &gradient_pixel)) {
      const Eigen::Vector2d direction = (gradient_pixel - pixel).normalized();
      cv::arrowedLine(panel_flow, ToPoint(pixel), ToPoint(pixel + 8.0 * direction),
                      cv::Scalar(0, 255, 255), 1, cv::LINE_AA, 0, 0.3);
    }
    Eigen::Vector2d previous_pixel;
    if (camera.Project(previous_cam_from_world * p_world, &previous_pixel)) {
      const Eigen::Vector2d flow = pixel - previous_pixel;
      cv::arrowedLine(panel_flow, ToPoint(pixel), ToPoint(pixel + 5.0 * flow),
                      cv::Scalar(255, 255, 0), 1, cv::LINE_AA, 0, 0.3);
    }
  }

  char caption[160];
  std::snprintf(caption, sizeof(caption), "t=%.4fs %s pts=%d on-edge=%.2f res=%.2f",
                static_cast<double>(step.t_ns) * 1e-9,
                step.status == TrackingStatus::kTracking ? "TRACKING" : "LOST",
                step.quality.points_used, step.quality.on_edge_fraction,
                step.quality.mean_residual);
  cv::putText(panel_map, caption, cv::Point(5, 15), cv::FONT_HERSHEY_SIMPLEX, 0.4,
              cv::Scalar(0, 255, 255), 1, cv::LINE_AA);
  cv::putText(panel_polarity, "ON (red) / OFF (blue)", cv::Point(5, 15), cv::FONT_HERSHEY_SIMPLEX,
              0.4, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  cv::putText(panel_flow, "gradient (yellow), flow x5 (cyan)", cv::Point(5, 15),
              cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  cv::Mat picture;
  cv::hconcat(std::vector<cv::Mat>{panel_map, panel_polarity, panel_flow}, picture);
  return picture;
}

}  // namespace evloc::tracking
