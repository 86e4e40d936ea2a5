#include "localizer/odometry/testing/handover_scene.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/dataset/dataset.h"
#include "core/events/evb.h"
#include "core/trajectory/trajectory.h"

namespace evloc::odometry::testing {
namespace {

using tracking::testing::Rectangle;

// 0 before 0, 1 after 1, C1 in between.
double SmoothStep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3 - 2 * x);
}

// A rectangle facing a camera at the origin, `range_m` away along the bearing `bearing_deg` to
// the right, moved by (u, v) in its plane; `tilt` turns its u axis about the vertical.
Rectangle Facing(double bearing_deg, double range_m, double u, double v, double half_u,
                 double half_v, double tilt = 0.0) {
  const double bearing = bearing_deg * M_PI / 180.0;
  const Eigen::Vector3d direction(std::sin(bearing), 0.0, std::cos(bearing));
  const Eigen::Vector3d axis_u(std::cos(bearing), 0.0, -std::sin(bearing));
  const Eigen::Vector3d axis_v = Eigen::Vector3d::UnitY();
  Rectangle rectangle;
  rectangle.centre = range_m * direction + u * axis_u + v * axis_v;
  rectangle.axis_u = Eigen::AngleAxisd(tilt, axis_v) * axis_u;
  rectangle.axis_v = axis_v;
  rectangle.half_u = half_u;
  rectangle.half_v = half_v;
  return rectangle;
}

std::vector<Rectangle> Layout(double bearing_deg) {
  return {Facing(bearing_deg, 2.0, -0.4, -0.2, 0.25, 0.18),
          Facing(bearing_deg, 2.4, 0.35, 0.15, 0.3, 0.22),
          Facing(bearing_deg, 2.8, 0.0, 0.4, 0.4, 0.15),
          Facing(bearing_deg, 1.7, -0.2, 0.25, 0.12, 0.1),
          Facing(bearing_deg, 2.2, 0.5, -0.35, 0.25, 0.18, 0.7)};
}

}  // namespace

std::vector<Rectangle> MappedRectangles() { return Layout(0.0); }

std::vector<Rectangle> AwayRectangles() { return Layout(kTurnDeg); }

Map HandoverMap() { return tracking::testing::MakeRectangleMap(MappedRectangles(), 0.01); }

Camera HandoverEventCamera() { return Camera::Pinhole(320, 240, 250, 250, 159.5, 119.5); }

Camera HandoverDepthCamera() { return Camera::Pinhole(240, 180, 190, 190, 119.5, 89.5); }

Rigid3d HandoverEventFromDepth() {
  return Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d::UnitY())),
      Eigen::Vector3d(0.04, 0.0, 0.0));
}

Rigid3d HandoverMotion(int64_t t_ns) {
  const double t = static_cast<double>(t_ns) * 1e-9;
  const double out = SmoothStep(static_cast<double>(t_ns - kLeaveNs) / (kAwayNs - kLeaveNs));
  const double back = SmoothStep(static_cast<double>(t_ns - kReturnNs) / (kBackNs - kReturnNs));
  const double yaw = kTurnDeg * M_PI / 180.0 * (out - back);
  // Hand-held sway: a few centimetres and a degree or two about the other axes.
  const Eigen::Vector3d translation(0.05 * std::sin(2 * M_PI * 0.7 * t),
                                    0.03 * std::sin(2 * M_PI * 1.1 * t),
                                    0.06 * std::sin(2 * M_PI * 0.5 * t));
  const Eigen::Quaterniond rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY())) *
      Eigen::Quaterniond(
          Eigen::AngleAxisd(0.03 * std::sin(2 * M_PI * 0.9 * t), Eigen::Vector3d::UnitX())) *
      Eigen::Quaterniond(
          Eigen::AngleAxisd(0.02 * std::sin(2 * M_PI * 0.6 * t), Eigen::Vector3d::UnitZ()));
  return Rigid3d(rotation, translation);
}

EventBuffer HandoverEvents() {
  std::vector<Rectangle> all = MappedRectangles();
  for (const Rectangle& rectangle : AwayRectangles()) all.push_back(rectangle);
  return tracking::testing::SimulateEdgeEvents(tracking::testing::MakeRectangleMap(all, 0.01),
                                               HandoverEventCamera(), HandoverMotion, 0, kEndNs);
}

cv::Mat HandoverDepthFrame(int64_t t_ns) {
  std::vector<Rectangle> all = MappedRectangles();
  for (const Rectangle& rectangle : AwayRectangles()) all.push_back(rectangle);
  const Camera camera = HandoverDepthCamera();
  const Rigid3d world_from_depth = HandoverMotion(t_ns) * HandoverEventFromDepth();
  const Eigen::Matrix3d rotation = world_from_depth.RotationMatrix();
  const double margin_m = 0.2;
  cv::Mat depth(camera.height, camera.width, CV_32FC1, cv::Scalar(0));
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const Eigen::Vector3d ray_cam((x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy, 1.0);
      const Eigen::Vector3d ray = rotation * ray_cam;
      double nearest = std::numeric_limits<double>::infinity();
      for (const Rectangle& rectangle : all) {
        const Eigen::Vector3d normal = rectangle.axis_u.cross(rectangle.axis_v);
        const double denominator = normal.dot(ray);
        if (std::abs(denominator) < 1e-9) continue;
        // z along the depth camera's axis: the ray has z = 1 in its frame.
        const double z = normal.dot(rectangle.centre - world_from_depth.translation) / denominator;
        if (!(z > 0.1) || z >= nearest) continue;
        const Eigen::Vector3d offset = world_from_depth.translation + z * ray - rectangle.centre;
        if (std::abs(offset.dot(rectangle.axis_u)) <= rectangle.half_u + margin_m &&
            std::abs(offset.dot(rectangle.axis_v)) <= rectangle.half_v + margin_m) {
          nearest = z;
        }
      }
      if (std::isfinite(nearest)) depth.at<float>(y, x) = std::round(nearest * 1000.0) * 1e-3f;
    }
  }
  return depth;
}

std::vector<int64_t> HandoverDepthTimes() {
  std::vector<int64_t> times;
  for (int64_t t = 10'000'000; t <= kEndNs; t += 33'333'333) times.push_back(t);
  return times;
}

std::filesystem::path WriteHandoverDataset(const std::filesystem::path& root) {
  const std::filesystem::path out = root / "dataset";
  DatasetWriter writer(out, {});
  const Camera camera = HandoverEventCamera();
  writer.WriteCamera(camera);
  writer.WriteDepthCamera(camera, HandoverDepthCamera(), HandoverEventFromDepth());
  for (const int64_t t : HandoverDepthTimes()) writer.AddDepthCameraFrame(t, HandoverDepthFrame(t));
  std::vector<TimedPose> poses;
  for (int64_t t = 0; t <= kEndNs; t += 5'000'000) poses.push_back({t, HandoverMotion(t)});
  writer.WriteGroundTruth(Trajectory(poses));
  EvbWriter events(writer.staging_dir() / dataset_files::kEventsEvb,
                   SensorSize{camera.width, camera.height});
  events.Write(HandoverEvents());
  events.Close();
  writer.Commit();
  std::filesystem::create_directories(root / "map");
  SaveMap(root / "map" / "map.evmap", HandoverMap());
  return out;
}

}  // namespace evloc::odometry::testing
