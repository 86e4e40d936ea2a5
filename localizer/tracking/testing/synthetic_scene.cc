#include "localizer/tracking/testing/synthetic_scene.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace evloc::tracking::testing {

std::vector<Rectangle> DefaultRectangles() {
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  const Eigen::Vector3d y = Eigen::Vector3d::UnitY();
  // A plane tilted by 40 degrees about the y axis, and one about the x axis.
  const Eigen::Vector3d tilted_u = Eigen::AngleAxisd(0.7, y) * x;
  const Eigen::Vector3d tilted_v = Eigen::AngleAxisd(-0.6, x) * y;
  return {
      {{-0.45, -0.25, 2.0}, x, y, 0.25, 0.2},
      {{0.4, 0.2, 2.6}, x, y, 0.3, 0.25},
      {{0.0, 0.45, 3.2}, x, y, 0.45, 0.15},
      {{-0.3, 0.3, 1.6}, x, y, 0.12, 0.12},
      {{0.55, -0.35, 2.2}, tilted_u, y, 0.25, 0.18},
      {{-0.1, -0.55, 3.5}, x, tilted_v, 0.4, 0.2},
      {{0.1, 0.0, 3.0}, x, y, 0.1, 0.1},
  };
}

Map MakeRectangleMap(const std::vector<Rectangle>& rectangles, double spacing_m) {
  Map map;
  for (const Rectangle& rectangle : rectangles) {
    // Four sides: (start corner, direction, length, inward gradient).
    const Eigen::Vector3d u = rectangle.axis_u * rectangle.half_u;
    const Eigen::Vector3d v = rectangle.axis_v * rectangle.half_v;
    struct Side {
      Eigen::Vector3d start, end, inward;
    };
    const Side sides[4] = {
        {rectangle.centre - u - v, rectangle.centre + u - v, rectangle.axis_v},
        {rectangle.centre + u - v, rectangle.centre + u + v, -rectangle.axis_u},
        {rectangle.centre + u + v, rectangle.centre - u + v, -rectangle.axis_v},
        {rectangle.centre - u + v, rectangle.centre - u - v, rectangle.axis_u},
    };
    for (const Side& side : sides) {
      const double length = (side.end - side.start).norm();
      const int count = std::max(1, static_cast<int>(std::floor(length / spacing_m)));
      // Skip the corners themselves: their gradient is ambiguous.
      for (int i = 1; i < count; ++i) {
        const Eigen::Vector3d position = side.start + (side.end - side.start) * (double(i) / count);
        map.AddPoint(position.cast<float>(), side.inward.normalized().cast<float>());
      }
    }
  }
  return map;
}

Rigid3d SmoothMotion(int64_t t_ns, double speed) {
  const double t = speed * static_cast<double>(t_ns) * 1e-9;
  const Eigen::Vector3d translation(0.3 * t, 0.1 * t + 0.02 * std::sin(6.0 * t),
                                    0.15 * t - 0.02 * (1 - std::cos(4.0 * t)));
  const Eigen::Vector3d rotation(0.15 * t, -0.25 * t + 0.05 * std::sin(5.0 * t), 0.1 * t);
  return Rigid3d(ExpSO3(rotation), translation);
}

double PositionErrorToSmoothMotion(const Rigid3d& world_from_cam, int64_t t_ns) {
  return (world_from_cam.translation - SmoothMotion(t_ns).translation).norm();
}

double RotationErrorToSmoothMotion(const Rigid3d& world_from_cam, int64_t t_ns) {
  return AngleBetween(world_from_cam.rotation, SmoothMotion(t_ns).rotation);
}

EventBuffer SimulateEdgeEvents(const Map& map, const Camera& camera,
                               const TrajectoryFunction& trajectory, int64_t t_begin_ns,
                               int64_t t_end_ns, int64_t render_period_ns, EdgeEventTiming timing) {
  std::vector<Event> events;
  const size_t num_points = map.size();
  std::vector<Eigen::Vector2d> last_pixel(num_points);
  std::vector<int> last_x(num_points, -1), last_y(num_points, -1);
  std::vector<bool> seen(num_points, false);
  const bool at_centre = timing == EdgeEventTiming::kCrossCentre;
  for (int64_t t_ns = t_begin_ns; t_ns <= t_end_ns; t_ns += render_period_ns) {
    const Rigid3d cam_from_world = trajectory(t_ns).Inverse();
    for (size_t i = 0; i < num_points; ++i) {
      const Eigen::Vector3d point_in_cam = cam_from_world * map.positions[i].cast<double>();
      Eigen::Vector2d pixel;
      if (!camera.Project(point_in_cam, &pixel) || !camera.IsInside(pixel)) {
        seen[i] = false;
        continue;
      }
      int x = static_cast<int>(std::lround(pixel.x()));
      int y = static_cast<int>(std::lround(pixel.y()));
      bool fires = seen[i] && (x != last_x[i] || y != last_y[i]);
      if (at_centre) {
        // Along each axis whose line of pixel centres the point crossed since the last render,
        // the pixel of the crossed centre; along the other, the nearest.
        const bool crossed_x = seen[i] && std::floor(pixel.x()) != std::floor(last_pixel[i].x());
        const bool crossed_y = seen[i] && std::floor(pixel.y()) != std::floor(last_pixel[i].y());
        if (crossed_x) {
          x = static_cast<int>(std::max(std::floor(pixel.x()), std::floor(last_pixel[i].x())));
        }
        if (crossed_y) {
          y = static_cast<int>(std::max(std::floor(pixel.y()), std::floor(last_pixel[i].y())));
        }
        fires = (crossed_x || crossed_y) && x < camera.width && y < camera.height;
      }
      if (fires) {
        Eigen::Vector2d probe;
        const Eigen::Vector3d gradient_in_cam =
            cam_from_world.rotation * map.gradients[i].cast<double>();
        if (camera.Project(point_in_cam + 0.01 * point_in_cam.z() * gradient_in_cam, &probe)) {
          const double normal_flow = -(probe - pixel).dot(pixel - last_pixel[i]);
          if (normal_flow != 0) {
            events.push_back({t_ns, static_cast<uint16_t>(x), static_cast<uint16_t>(y),
                              static_cast<int8_t>(normal_flow > 0 ? 1 : -1)});
          }
        }
      }
      seen[i] = true;
      last_pixel[i] = pixel;
      last_x[i] = x;
      last_y[i] = y;
    }
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; });
  EventBuffer buffer;
  buffer.reserve(events.size());
  for (const Event& event : events) buffer.push_back(event);
  return buffer;
}

cv::Mat RenderRectangles(const std::vector<Rectangle>& rectangles, const Camera& camera,
                         const Rigid3d& world_from_cam) {
  cv::Mat image(camera.height, camera.width, CV_8UC1, cv::Scalar(40));
  const Rigid3d cam_from_world = world_from_cam.Inverse();
  std::vector<size_t> order(rectangles.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return (cam_from_world * rectangles[a].centre).z() >
           (cam_from_world * rectangles[b].centre).z();
  });
  for (const size_t index : order) {
    const Rectangle& rectangle = rectangles[index];
    const Eigen::Vector3d u = rectangle.axis_u * rectangle.half_u;
    const Eigen::Vector3d v = rectangle.axis_v * rectangle.half_v;
    const Eigen::Vector3d corners[4] = {rectangle.centre - u - v, rectangle.centre + u - v,
                                        rectangle.centre + u + v, rectangle.centre - u + v};
    std::vector<cv::Point> polygon;
    bool visible = true;
    for (const Eigen::Vector3d& corner : corners) {
      Eigen::Vector2d pixel;
      if (!camera.Project(cam_from_world * corner, &pixel)) {
        visible = false;
        break;
      }
      // 8 fractional bits so that sub-pixel corners render accurately.
      polygon.emplace_back(static_cast<int>(std::lround(pixel.x() * 256)),
                           static_cast<int>(std::lround(pixel.y() * 256)));
    }
    if (visible) cv::fillConvexPoly(image, polygon, cv::Scalar(200), cv::LINE_AA, 8);
  }
  return image;
}

void AddKeyframesBesideThePath(Map* map, const Camera& camera, int64_t end_ns, int64_t period_ns,
                               const Vector6d& displacement, const Eigen::Vector3d& shift) {
  const uint32_t camera_index = static_cast<uint32_t>(map->cameras.size());
  map->cameras.push_back(camera);
  for (int64_t t_ns = 0; t_ns <= end_ns; t_ns += period_ns) {
    Rigid3d world_from_cam = SmoothMotion(t_ns) * ExpSE3(displacement);
    world_from_cam.translation += shift;
    Keyframe keyframe;
    keyframe.cam_from_world = world_from_cam.Inverse();
    keyframe.t_ns = t_ns;
    keyframe.camera_index = camera_index;
    map->keyframes.push_back(keyframe);
  }
}

std::vector<Rectangle> TwinRectangles(const Eigen::Vector3d& shift) {
  std::vector<Rectangle> twins = DefaultRectangles();
  for (const Rectangle& rectangle : DefaultRectangles()) {
    Rectangle copy = rectangle;
    copy.centre += shift;
    twins.push_back(copy);
  }
  return twins;
}

EventBuffer EventsBetween(const EventBuffer& events, int64_t first_ns, int64_t last_ns) {
  EventBuffer result;
  for (size_t i = 0; i < events.size(); ++i) {
    if (events.t_ns[i] > first_ns && events.t_ns[i] <= last_ns) result.push_back(events[i]);
  }
  return result;
}

}  // namespace evloc::tracking::testing
