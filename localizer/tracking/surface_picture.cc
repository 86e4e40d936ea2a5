#include "localizer/tracking/surface_picture.h"

#include <cmath>

#include <opencv2/imgproc.hpp>

namespace evloc::tracking {

cv::Mat TimeSurfacePicture(const Tracker& tracker, SurfaceChannel channel, int64_t t_ns) {
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

void DrawReprojectedPoints(const Camera& camera, std::span<const Eigen::Vector3f> positions,
                           const std::vector<uint32_t>& indices, const Rigid3d& world_from_cam,
                           const cv::Mat& surface, cv::Mat* picture) {
  const Rigid3d cam_from_world = world_from_cam.Inverse();
  for (const uint32_t index : indices) {
    if (index >= positions.size()) continue;
    const Eigen::Vector3d p_cam = cam_from_world * positions[index].cast<double>();
    Eigen::Vector2d pixel;
    if (!camera.Project(p_cam, &pixel) || !camera.IsInside(pixel)) continue;
    const cv::Point point(static_cast<int>(std::lround(pixel.x())),
                          static_cast<int>(std::lround(pixel.y())));
    if (point.x < 0 || point.y < 0 || point.x >= surface.cols || point.y >= surface.rows) continue;
    const bool on_edge = surface.at<uint8_t>(point) > 0;
    cv::circle(*picture, point, 1, on_edge ? cv::Scalar(0, 220, 0) : cv::Scalar(0, 0, 255),
               cv::FILLED);
  }
}

cv::Mat SurfaceWithReprojectedMap(const Tracker& tracker, const MapSource& source,
                                  const Rigid3d& world_from_cam, int64_t t_ns) {
  const cv::Mat surface = TimeSurfacePicture(tracker, SurfaceChannel::kAll, t_ns);
  cv::Mat picture;
  cv::cvtColor(surface, picture, cv::COLOR_GRAY2BGR);
  std::vector<uint32_t> candidates;
  source.VisibleCandidates(tracker.ideal_camera(), world_from_cam, VisibilityQueryOptions{},
                           &candidates);
  DrawReprojectedPoints(tracker.ideal_camera(), source.points().positions, candidates,
                        world_from_cam, surface, &picture);
  return picture;
}

}  // namespace evloc::tracking
