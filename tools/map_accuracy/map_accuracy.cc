#include "tools/map_accuracy/map_accuracy.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <string>

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/dataset/dataset.h"
#include "core/trajectory/trajectory.h"

namespace evloc::mapper {
namespace {

double Median(std::vector<double> values) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto middle = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const double cosine = a.normalized().dot(b.normalized());
  return std::acos(std::clamp(cosine, -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

double DistanceToSegment(const Eigen::Vector3d& point, const Eigen::Vector3d& a,
                         const Eigen::Vector3d& b) {
  const Eigen::Vector3d ab = b - a;
  const double length_squared = ab.squaredNorm();
  if (length_squared <= 0.0) return (point - a).norm();
  const double t = std::clamp((point - a).dot(ab) / length_squared, 0.0, 1.0);
  return (point - (a + t * ab)).norm();
}

// The image direction of gradient `gradient` at `point` in `view`; false when not visible.
bool ImageDirection(const DepthView& view, const Eigen::Vector3d& point,
                    const Eigen::Vector3d& gradient, Eigen::Vector2d* direction) {
  const Eigen::Vector3d in_cam = view.cam_from_world * point;
  const Eigen::Vector3d tip_in_cam = view.cam_from_world * (point + 1e-3 * gradient);
  Eigen::Vector2d pixel;
  Eigen::Vector2d tip;
  if (in_cam.z() <= 0.0 || tip_in_cam.z() <= 0.0) return false;
  if (!view.camera.Project(in_cam, &pixel) || !view.camera.Project(tip_in_cam, &tip)) return false;
  *direction = tip - pixel;
  return direction->norm() > 1e-12;
}

}  // namespace

void MapAccuracyOptions::Check() const {
  if (!(within_m > 0.0)) throw InvalidArgumentError("within_m must be > 0");
  if (depth_window_half_size_px < 0) {
    throw InvalidArgumentError("depth_window_half_size_px must be >= 0");
  }
  if (!(max_segment_length_m >= 0.0)) {
    throw InvalidArgumentError("max_segment_length_m must be >= 0");
  }
}

MapAccuracy MeasureMapAccuracy(const Map& map, const Map& reference,
                               const std::vector<DepthView>& views,
                               const MapAccuracyOptions& options,
                               std::vector<PointAccuracy>* per_point,
                               const std::vector<bool>& reference_gradient_defined) {
  options.Check();
  if (!reference_gradient_defined.empty() &&
      reference_gradient_defined.size() != reference.size()) {
    throw InvalidArgumentError("reference_gradient_defined has " +
                               std::to_string(reference_gradient_defined.size()) + " flags for " +
                               std::to_string(reference.size()) + " reference points");
  }
  if (map.size() == 0) throw InvalidArgumentError("the measured map is empty");
  if (reference.size() < 2) throw InvalidArgumentError("the reference map has fewer than 2 points");
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  cloud->reserve(reference.size());
  for (const Eigen::Vector3f& position : reference.positions) {
    cloud->push_back(pcl::PointXYZ(position.x(), position.y(), position.z()));
  }
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(cloud);
  std::vector<Eigen::Vector3d> centers;
  std::map<int64_t, size_t> view_by_time;
  for (size_t v = 0; v < views.size(); ++v) {
    centers.push_back(views[v].cam_from_world.Inverse().translation);
    if (views[v].t_ns) view_by_time.emplace(*views[v].t_ns, v);
  }
  // The view taken within 1 ms of t_ns.
  const auto view_of_time = [&](int64_t t_ns) -> std::optional<size_t> {
    const auto after = view_by_time.lower_bound(t_ns - 1000000);
    if (after == view_by_time.end() || after->first > t_ns + 1000000) return std::nullopt;
    return after->second;
  };

  MapAccuracy accuracy;
  accuracy.num_points = map.size();
  std::vector<double> depth_errors;
  std::vector<double> signed_depth_errors;
  std::vector<double> edge_distances;
  std::vector<double> gradient_angles;
  std::vector<double> defined_gradient_angles;
  std::vector<double> image_gradient_angles;
  std::vector<int> indices(2);
  std::vector<float> squared_distances(2);
  const int window = options.depth_window_half_size_px;
  constexpr double kNotMeasured = std::numeric_limits<double>::quiet_NaN();
  if (per_point != nullptr) {
    per_point->assign(map.size(), {kNotMeasured, kNotMeasured, kNotMeasured, kNotMeasured, 0});
  }
  for (size_t i = 0; i < map.size(); ++i) {
    const Eigen::Vector3d point = map.positions[i].cast<double>();
    const Eigen::Vector3d gradient = map.gradients[i].cast<double>();
    // Ground-truth edges.
    const pcl::PointXYZ query(map.positions[i].x(), map.positions[i].y(), map.positions[i].z());
    if (tree.nearestKSearch(query, 2, indices, squared_distances) < 1) continue;
    const Eigen::Vector3d first = reference.positions[indices[0]].cast<double>();
    double distance = (point - first).norm();
    if (indices.size() > 1) {
      const Eigen::Vector3d second = reference.positions[indices[1]].cast<double>();
      if ((second - first).norm() <= options.max_segment_length_m) {
        distance = DistanceToSegment(point, first, second);
      }
    }
    edge_distances.push_back(distance);
    const Eigen::Vector3d reference_gradient = reference.gradients[indices[0]].cast<double>();
    gradient_angles.push_back(AngleDeg(gradient, reference_gradient));
    if (reference_gradient_defined.empty() || reference_gradient_defined[indices[0]]) {
      defined_gradient_angles.push_back(gradient_angles.back());
    }
    if (per_point != nullptr) {
      (*per_point)[i].edge_distance_m = distance;
      (*per_point)[i].gradient_angle_deg = gradient_angles.back();
      (*per_point)[i].reference_index = static_cast<uint32_t>(indices[0]);
    }

    // The view of the point's source keyframe (it observed the point there: no occlusion), else
    // the nearest depth view (by camera centre) in which the point projects with valid depth.
    std::vector<std::pair<double, size_t>> by_distance;
    const uint32_t source = i < map.source_keyframe.size() ? map.source_keyframe[i] : kNoKeyframe;
    const std::optional<size_t> source_view =
        source < map.keyframes.size() ? view_of_time(map.keyframes[source].t_ns) : std::nullopt;
    for (size_t v = 0; v < views.size(); ++v) {
      // The source view first (distance -1), then by distance.
      by_distance.emplace_back(source_view == v ? -1.0 : (centers[v] - point).squaredNorm(), v);
    }
    std::sort(by_distance.begin(), by_distance.end());
    for (const auto& [order, v] : by_distance) {
      const DepthView& view = views[v];
      const Eigen::Vector3d in_cam = view.cam_from_world * point;
      Eigen::Vector2d pixel;
      if (in_cam.z() <= 0.0 || !view.camera.Project(in_cam, &pixel) ||
          !view.camera.IsInside(pixel)) {
        continue;
      }
      const int u = static_cast<int>(std::lround(pixel.x()));
      const int w = static_cast<int>(std::lround(pixel.y()));
      double best = std::numeric_limits<double>::infinity();
      double best_signed = 0.0;
      for (int dy = -window; dy <= window; ++dy) {
        for (int dx = -window; dx <= window; ++dx) {
          const int x = u + dx;
          const int y = w + dy;
          if (x < 0 || y < 0 || x >= view.depth_m.cols || y >= view.depth_m.rows) continue;
          const float depth = view.depth_m.at<float>(y, x);
          if (depth > 0.0f && std::abs(in_cam.z() - depth) < best) {
            best = std::abs(in_cam.z() - depth);
            best_signed = in_cam.z() - depth;
          }
        }
      }
      if (!std::isfinite(best)) continue;
      depth_errors.push_back(best);
      signed_depth_errors.push_back(best_signed);
      if (order < 0.0) ++accuracy.num_depth_in_source_view;
      if (per_point != nullptr) (*per_point)[i].depth_error_m = best;
      Eigen::Vector2d direction;
      Eigen::Vector2d reference_direction;
      if (ImageDirection(view, point, gradient, &direction) &&
          ImageDirection(view, point, reference_gradient, &reference_direction)) {
        image_gradient_angles.push_back(
            AngleDeg(Eigen::Vector3d(direction.x(), direction.y(), 0),
                     Eigen::Vector3d(reference_direction.x(), reference_direction.y(), 0)));
        if (per_point != nullptr) {
          (*per_point)[i].image_gradient_angle_deg = image_gradient_angles.back();
        }
      }
      break;
    }
  }
  const auto fraction_within = [&](const std::vector<double>& values) {
    if (values.empty()) return 0.0;
    const auto count = std::count_if(values.begin(), values.end(),
                                     [&](double value) { return value <= options.within_m; });
    return static_cast<double>(count) / static_cast<double>(values.size());
  };
  accuracy.num_depth_compared = depth_errors.size();
  accuracy.median_depth_error_m = Median(depth_errors);
  accuracy.median_signed_depth_error_m = Median(signed_depth_errors);
  accuracy.depth_within_fraction = fraction_within(depth_errors);
  accuracy.median_edge_distance_m = Median(edge_distances);
  accuracy.edge_within_fraction = fraction_within(edge_distances);
  accuracy.median_gradient_angle_deg = Median(gradient_angles);
  const auto fraction = [](const std::vector<double>& angles,
                           const std::function<bool(double)>& predicate) {
    if (angles.empty()) return 0.0;
    return static_cast<double>(std::count_if(angles.begin(), angles.end(), predicate)) /
           static_cast<double>(angles.size());
  };
  const auto within_10deg = [](double angle) { return angle <= 10.0; };
  const auto opposite = [](double angle) { return angle > 90.0; };
  accuracy.gradient_within_10deg_fraction = fraction(gradient_angles, within_10deg);
  accuracy.gradient_opposite_fraction = fraction(gradient_angles, opposite);
  accuracy.num_gradient_defined = defined_gradient_angles.size();
  accuracy.median_gradient_angle_defined_deg = Median(defined_gradient_angles);
  accuracy.gradient_within_10deg_defined_fraction = fraction(defined_gradient_angles, within_10deg);
  accuracy.gradient_opposite_defined_fraction = fraction(defined_gradient_angles, opposite);
  accuracy.median_image_gradient_angle_deg = Median(image_gradient_angles);
  return accuracy;
}

std::vector<double> KeyframeEdgeDistances(const Map& map, const std::filesystem::path& image_dir) {
  std::vector<double> distances;
  for (const Keyframe& keyframe : map.keyframes) {
    const std::filesystem::path path = image_dir / keyframe.image_name;
    const cv::Mat gray = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
    if (gray.empty()) throw IoError("cannot read the keyframe image " + path.string());
    cv::Mat edges;
    cv::Canny(gray, edges, 40, 100, 3, true);
    cv::Mat distance;
    cv::distanceTransform(255 - edges, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
    const Camera& camera = map.cameras[keyframe.camera_index];
    for (const uint32_t point : keyframe.visible_points) {
      Eigen::Vector2d pixel;
      if (!camera.Project(keyframe.cam_from_world * map.positions[point].cast<double>(), &pixel) ||
          !camera.IsInside(pixel)) {
        continue;
      }
      // Bilinear interpolation of the distance field at the sub-pixel projection.
      const int x0 = std::clamp(static_cast<int>(pixel.x()), 0, distance.cols - 2);
      const int y0 = std::clamp(static_cast<int>(pixel.y()), 0, distance.rows - 2);
      const double ax = pixel.x() - x0;
      const double ay = pixel.y() - y0;
      const double value =
          (1 - ay) * ((1 - ax) * distance.at<float>(y0, x0) + ax * distance.at<float>(y0, x0 + 1)) +
          ay *
              ((1 - ax) * distance.at<float>(y0 + 1, x0) + ax * distance.at<float>(y0 + 1, x0 + 1));
      distances.push_back(value);
    }
  }
  std::sort(distances.begin(), distances.end());
  return distances;
}

std::vector<DepthView> ReadDatasetDepthViews(const std::filesystem::path& dataset, int stride) {
  if (stride < 1) throw InvalidArgumentError("the depth-map stride must be at least 1");
  const Dataset data = ReadDataset(dataset);
  if (!data.ground_truth) {
    throw IoError("dataset '" + dataset.string() + "' has no " + dataset_files::kGroundTruthTxt +
                  ": the depth maps have no poses.");
  }
  std::vector<DepthView> views;
  for (size_t index = 0; index < data.depth.size(); index += static_cast<size_t>(stride)) {
    const TimedFile& depth = data.depth[index];
    const std::optional<Rigid3d> world_from_cam = data.ground_truth->Lookup(depth.t_ns);
    if (!world_from_cam) continue;  // outside the ground truth's time span
    DepthView view;
    view.camera = data.camera;
    view.cam_from_world = world_from_cam->Inverse();
    view.t_ns = depth.t_ns;
    view.depth_m = ReadDepthPng(depth.path);
    views.push_back(std::move(view));
  }
  return views;
}

}  // namespace evloc::mapper
