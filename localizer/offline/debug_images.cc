#include "localizer/offline/debug_images.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "localizer/tracking/polarity.h"
#include "localizer/tracking/surface_picture.h"

namespace evloc::tracking {
namespace {

cv::Point ToPoint(const Eigen::Vector2d& pixel) {
  return cv::Point(static_cast<int>(std::lround(pixel.x())),
                   static_cast<int>(std::lround(pixel.y())));
}

}  // namespace

cv::Mat RenderTrackingDebugImage(const Tracker& tracker, const Map& map,
                                 const VisibilityIndex* visibility, const PoseEstimate& step,
                                 const Rigid3d& previous_world_from_cam) {
  const Camera& camera = tracker.ideal_camera();
  const cv::Mat all = TimeSurfacePicture(tracker, SurfaceChannel::kAll, step.t_ns);
  const cv::Mat on = TimeSurfacePicture(tracker, SurfaceChannel::kOn, step.t_ns);
  const cv::Mat off = TimeSurfacePicture(tracker, SurfaceChannel::kOff, step.t_ns);

  cv::Mat panel_map;
  cv::cvtColor(all, panel_map, cv::COLOR_GRAY2BGR);
  cv::Mat panel_polarity;
  cv::merge(std::vector<cv::Mat>{off, cv::Mat::zeros(on.size(), CV_8UC1), on}, panel_polarity);
  cv::Mat panel_flow;
  cv::cvtColor(all / 3, panel_flow, cv::COLOR_GRAY2BGR);
  // Panel 4: the events since the previous step (dim red ON, dim blue OFF) and each point's
  // predicted polarity (bright red ON, bright blue OFF, grey unsigned).
  const TimeSurface& surface = tracker.time_surface();
  const int64_t previous_t_ns =
      step.t_ns - static_cast<int64_t>(std::llround(1e9 / tracker.options().step_rate_hz));
  cv::Mat panel_prediction(all.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  for (int y = 0; y < surface.height(); ++y) {
    auto* row = panel_prediction.ptr<cv::Vec3b>(y);
    for (int x = 0; x < surface.width(); ++x) {
      const int64_t t_on = surface.LastTimestamp(SurfaceChannel::kOn, x, y);
      const int64_t t_off = surface.LastTimestamp(SurfaceChannel::kOff, x, y);
      if (std::max(t_on, t_off) <= previous_t_ns) continue;
      row[x] = t_on >= t_off ? cv::Vec3b(0, 0, 110) : cv::Vec3b(110, 0, 0);
    }
  }
  const PolarityPredictionOptions polarity_options{tracker.options().polarity_neutral_band_deg,
                                                   tracker.options().gradient_probe_depth_fraction,
                                                   tracker.options().min_flow_px};
  // The flow over one step period from the motion prior's velocity (less noisy than the
  // difference of two estimates).
  const Rigid3d flow_origin_world_from_cam =
      step.world_from_cam *
      ExpSE3(-tracker.velocity() * (static_cast<double>(step.t_ns - previous_t_ns) * 1e-9));
  const PolarityPredictor predictor(PinholeIntrinsics::FromCamera(camera),
                                    step.world_from_cam.Inverse(),
                                    flow_origin_world_from_cam.Inverse(), polarity_options);

  std::vector<uint32_t> points;
  if (visibility != nullptr) {
    points = visibility->Query(camera, step.world_from_cam);
  } else {
    points.resize(map.size());
    std::iota(points.begin(), points.end(), 0u);
  }
  DrawReprojectedPoints(camera, map.positions, points, step.world_from_cam, all, &panel_map);
  const Rigid3d cam_from_world = step.world_from_cam.Inverse();
  const Rigid3d previous_cam_from_world = previous_world_from_cam.Inverse();
  const size_t stride = std::max<size_t>(1, points.size() / 400);
  for (size_t k = 0; k < points.size(); ++k) {
    const uint32_t index = points[k];
    const Eigen::Vector3d p_world = map.positions[index].cast<double>();
    const Eigen::Vector3d p_cam = cam_from_world * p_world;
    Eigen::Vector2d pixel;
    if (!camera.Project(p_cam, &pixel) || !camera.IsInside(pixel)) continue;
    const PredictedPolarity polarity =
        predictor.Predict(p_world, map.gradients[index].cast<double>());
    panel_prediction.at<cv::Vec3b>(ToPoint(pixel)) =
        polarity == PredictedPolarity::kOn    ? cv::Vec3b(0, 0, 255)
        : polarity == PredictedPolarity::kOff ? cv::Vec3b(255, 0, 0)
                                              : cv::Vec3b(160, 160, 160);
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
                static_cast<double>(step.t_ns) * 1e-9, TrackingStatusName(step.status),
                step.quality.points_used, step.quality.on_edge_fraction,
                step.quality.mean_residual);
  cv::putText(panel_map, caption, cv::Point(5, 15), cv::FONT_HERSHEY_SIMPLEX, 0.4,
              cv::Scalar(0, 255, 255), 1, cv::LINE_AA);
  cv::putText(panel_polarity, "ON (red) / OFF (blue)", cv::Point(5, 15), cv::FONT_HERSHEY_SIMPLEX,
              0.4, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  cv::putText(panel_flow, "gradient (yellow), flow x5 (cyan)", cv::Point(5, 15),
              cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  cv::putText(panel_prediction, "predicted ON/OFF/none; last step's events dim", cv::Point(5, 15),
              cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  cv::Mat picture;
  cv::hconcat(std::vector<cv::Mat>{panel_map, panel_polarity, panel_flow, panel_prediction},
              picture);
  return picture;
}

}  // namespace evloc::tracking
