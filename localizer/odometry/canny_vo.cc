#include "localizer/odometry/canny_vo.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include <Eigen/Cholesky>

#include "core/common/error.h"
#include "localizer/tracking/point_selection.h"
#include "localizer/tracking/registration.h"
#include "maps/edge_lifting.h"

namespace evloc::odometry {
namespace {

using Clock = std::chrono::steady_clock;

double MillisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// The residual system of the points at one pose.
struct EdgeSystem {
  Matrix6d information = Matrix6d::Zero();
  Vector6d gradient = Vector6d::Zero();
  double weighted_squares = 0;
  int in_view = 0;
  int used = 0;
  int inliers = 0;
  double inlier_squares = 0;
};

EdgeSystem BuildEdgeSystem(const std::vector<KeyframePoint>& points,
                           const OrientedEdgeFields& fields,
                           const tracking::PinholeIntrinsics& intrinsics,
                           const Rigid3d& cam_from_reference, const CannyVoOptions& options) {
  EdgeSystem system;
  const Eigen::Matrix3d rotation = cam_from_reference.RotationMatrix();
  const int width = fields.width();
  const int height = fields.height();
  const std::vector<EdgePixel>& edges = fields.edges();
  for (const KeyframePoint& point : points) {
    const Eigen::Vector3d point_in_cam = rotation * point.position + cam_from_reference.translation;
    Eigen::Vector2d pixel;
    Eigen::Matrix<double, 2, 3> d_pixel_d_point;
    if (!intrinsics.Project(point_in_cam, &pixel, &d_pixel_d_point)) continue;
    if (!(pixel.x() >= 0 && pixel.y() >= 0 && pixel.x() <= width - 1 && pixel.y() <= height - 1)) {
      continue;
    }
    ++system.in_view;
    // The predicted image gradient: the projection of a short step along the 3D gradient.
    const Eigen::Vector3d probe =
        point_in_cam + (0.01 * point_in_cam.z()) * (rotation * point.gradient);
    Eigen::Vector2d probe_pixel;
    if (!intrinsics.Project(probe, &probe_pixel)) continue;
    const Eigen::Vector2d direction = probe_pixel - pixel;
    if (!(direction.squaredNorm() > 1e-12)) continue;
    const int bin = OrientationBin(direction, fields.bins());
    const int nearest = fields.NearestEdge(bin, static_cast<int>(std::lround(pixel.x())),
                                           static_cast<int>(std::lround(pixel.y())));
    if (nearest < 0) continue;
    const EdgePixel& edge = edges[nearest];
    const Eigen::Vector2d& normal = edge.gradient_direction;
    const double residual = normal.dot(pixel - edge.ideal_pixel);
    Eigen::Matrix<double, 3, 6> d_point_d_delta;
    d_point_d_delta.leftCols<3>().setIdentity();
    d_point_d_delta.rightCols<3>() = -Hat(point_in_cam);
    const tracking::RowVector6d jacobian = normal.transpose() * d_pixel_d_point * d_point_d_delta;
    const double weight = tracking::RobustWeight(options.loss, options.robust_scale_px, residual);
    system.information.noalias() += weight * jacobian.transpose() * jacobian;
    system.gradient.noalias() += weight * residual * jacobian.transpose();
    system.weighted_squares += weight * residual * residual;
    ++system.used;
    if (std::abs(residual) <= options.inlier_px) {
      ++system.inliers;
      system.inlier_squares += residual * residual;
    }
  }
  return system;
}

}  // namespace

void CannyVoOptions::Check() const {
  edges.Check();
  if (max_points < 10) throw InvalidArgumentError("CannyVoOptions: max_points must be >= 10");
  if (!(min_depth_m > 0) || !(max_depth_m > min_depth_m) || !std::isfinite(max_depth_m)) {
    throw InvalidArgumentError("CannyVoOptions: need 0 < min_depth_m < max_depth_m");
  }
  if (!(depth_discontinuity_fraction > 0)) {
    throw InvalidArgumentError("CannyVoOptions: depth_discontinuity_fraction must be positive");
  }
  if (!(robust_scale_px > 0) || !(inlier_px > 0)) {
    throw InvalidArgumentError("CannyVoOptions: robust_scale_px and inlier_px must be positive");
  }
  if (max_iterations < 1 || min_points < 6) {
    throw InvalidArgumentError("CannyVoOptions: max_iterations >= 1 and min_points >= 6 needed");
  }
  if (!(min_increment > 0)) throw InvalidArgumentError("CannyVoOptions: min_increment > 0");
  if (!(min_inlier_fraction >= 0 && min_inlier_fraction <= 1) ||
      !(keyframe_min_visible_fraction >= 0 && keyframe_min_visible_fraction <= 1)) {
    throw InvalidArgumentError("CannyVoOptions: fractions must lie in [0, 1]");
  }
  if (!(keyframe_max_baseline_fraction > 0) || !(keyframe_max_rotation_deg > 0)) {
    throw InvalidArgumentError("CannyVoOptions: keyframe thresholds must be positive");
  }
  if (!(velocity_window_s >= 0)) {
    throw InvalidArgumentError("CannyVoOptions: velocity_window_s must be >= 0");
  }
}

std::vector<KeyframePoint> LiftKeyframeEdges(const Camera& camera,
                                             const std::vector<EdgePixel>& edges,
                                             const cv::Mat& depth_m,
                                             const CannyVoOptions& options) {
  if (depth_m.type() != CV_32FC1 || depth_m.cols != camera.width || depth_m.rows != camera.height) {
    throw InvalidArgumentError("LiftKeyframeEdges: the depth must be CV_32FC1 metres of " +
                               std::to_string(camera.width) + "x" + std::to_string(camera.height));
  }
  auto valid = [&](float z) { return z >= options.min_depth_m && z <= options.max_depth_m; };
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Vector3d> gradients;
  positions.reserve(edges.size());
  gradients.reserve(edges.size());
  for (const EdgePixel& edge : edges) {
    const int x = edge.sensor_pixel.x();
    const int y = edge.sensor_pixel.y();
    const float center = depth_m.at<float>(y, x);
    if (!valid(center)) continue;
    float nearest = center;
    float farthest = center;
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int u = x + dx;
        const int v = y + dy;
        if (u < 0 || v < 0 || u >= depth_m.cols || v >= depth_m.rows) continue;
        const float z = depth_m.at<float>(v, u);
        if (!valid(z)) continue;
        nearest = std::min(nearest, z);
        farthest = std::max(farthest, z);
      }
    }
    const double depth =
        farthest - nearest > options.depth_discontinuity_fraction * nearest ? nearest : center;
    // The sub-pixel edge's ray at the pixel's depth, and its view-facing 3D gradient
    // (maps/edge_lifting.h); only the gradient's image projection is used.
    Eigen::Vector3d ray;
    if (!camera.Unproject(edge.sensor_subpixel, &ray) || !(ray.z() > 0)) continue;
    const Eigen::Vector3d point = ray * (depth / ray.z());
    Eigen::Vector3d gradient;
    if (!ComputeGradient3d(camera, edge.sensor_subpixel, edge.gradient_direction, point,
                           &gradient)) {
      continue;
    }
    positions.push_back(point.cast<float>());
    gradients.push_back(gradient);
  }
  std::vector<uint32_t> candidates(positions.size());
  for (size_t i = 0; i < candidates.size(); ++i) candidates[i] = static_cast<uint32_t>(i);
  tracking::PointSelectionOptions selection;
  selection.max_points = options.max_points;
  selection.min_depth_m = options.min_depth_m;
  selection.max_depth_m = options.max_depth_m;
  selection.image_margin_px = 0;
  const std::vector<uint32_t> chosen =
      tracking::SelectEvenly(positions, candidates, tracking::PinholeIntrinsics::FromCamera(camera),
                             camera.width, camera.height, Rigid3d(), selection);
  std::vector<KeyframePoint> points;
  points.reserve(chosen.size());
  for (const uint32_t index : chosen) {
    points.push_back({positions[index].cast<double>(), gradients[index]});
  }
  return points;
}

EdgeRegistration RegisterToOrientedEdges(const std::vector<KeyframePoint>& points,
                                         const OrientedEdgeFields& fields, const Camera& ideal,
                                         const Rigid3d& initial_cam_from_reference,
                                         const CannyVoOptions& options) {
  const tracking::PinholeIntrinsics intrinsics = tracking::PinholeIntrinsics::FromCamera(ideal);
  EdgeRegistration result;
  result.cam_from_reference = initial_cam_from_reference;
  EdgeSystem system;
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    system = BuildEdgeSystem(points, fields, intrinsics, result.cam_from_reference, options);
    ++result.iterations;
    if (system.used < 6) break;
    const Vector6d delta = -system.information.ldlt().solve(system.gradient);
    if (!delta.allFinite()) break;
    result.cam_from_reference = ExpSE3(delta) * result.cam_from_reference;
    if (delta.norm() < options.min_increment) break;
  }
  system = BuildEdgeSystem(points, fields, intrinsics, result.cam_from_reference, options);
  result.information = system.information;
  result.points_in_view = system.in_view;
  result.points_used = system.used;
  result.residual_variance =
      system.used > 6 ? system.weighted_squares / (system.used - 6) : system.weighted_squares;
  result.inlier_fraction =
      system.in_view > 0 ? static_cast<double>(system.inliers) / system.in_view : 0.0;
  result.rms_residual_px =
      system.inliers > 0 ? std::sqrt(system.inlier_squares / system.inliers) : 0.0;
  return result;
}

CannyVo::CannyVo(const Camera& camera, const CannyVoOptions& options)
    : camera_(camera),
      options_(options),
      table_(camera),
      motion_(static_cast<int64_t>(std::llround(options.velocity_window_s * 1e9))) {
  options_.Check();
}

void CannyVo::Reset(const Rigid3d& world_from_cam, int64_t t_ns) {
  motion_.Reset(world_from_cam, t_ns);
  started_ = true;
  has_keyframe_ = false;
  last_t_ns_.reset();
  keyframe_points_.clear();
}

void CannyVo::TakeKeyframe(const std::vector<EdgePixel>& edges, const cv::Mat& depth_m,
                           const Rigid3d& world_from_cam) {
  keyframe_points_ = LiftKeyframeEdges(camera_, edges, depth_m, options_);
  world_from_keyframe_ = world_from_cam;
  has_keyframe_ = true;
  std::vector<double> depths;
  depths.reserve(keyframe_points_.size());
  for (const KeyframePoint& point : keyframe_points_) depths.push_back(point.position.z());
  if (!depths.empty()) {
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    keyframe_median_depth_m_ = depths[depths.size() / 2];
  }
}

VoEstimate CannyVo::AddFrame(int64_t t_ns, const cv::Mat& gray, const cv::Mat& depth_m) {
  const Clock::time_point start = Clock::now();
  if (!started_) throw InvalidArgumentError("CannyVo::AddFrame: call Reset first");
  if (last_t_ns_ && t_ns <= *last_t_ns_) {
    throw InvalidArgumentError("CannyVo::AddFrame: frame time " + std::to_string(t_ns) +
                               " ns is not after the previous frame's");
  }
  if (gray.type() != CV_8UC1 || gray.cols != camera_.width || gray.rows != camera_.height ||
      depth_m.type() != CV_32FC1 || depth_m.cols != camera_.width ||
      depth_m.rows != camera_.height) {
    throw InvalidArgumentError("CannyVo::AddFrame: expected CV_8UC1 grey and CV_32FC1 depth of " +
                               std::to_string(camera_.width) + "x" +
                               std::to_string(camera_.height));
  }
  VoEstimate estimate;
  estimate.t_ns = t_ns;
  std::vector<EdgePixel> edges = DetectOrientedEdges(gray, table_, options_.edges);
  if (!has_keyframe_) {
    const Clock::time_point keyframe_start = Clock::now();
    TakeKeyframe(edges, depth_m, motion_.last_world_from_cam());
    estimate.keyframe_ms = MillisecondsSince(keyframe_start);
    estimate.world_from_cam = motion_.last_world_from_cam();
    estimate.covariance.setZero();
    estimate.tracked = true;
    estimate.new_keyframe = true;
    estimate.points_used = static_cast<int>(keyframe_points_.size());
    estimate.inlier_fraction = 1;
    last_t_ns_ = t_ns;
    estimate.total_ms = MillisecondsSince(start);
    return estimate;
  }
  const Clock::time_point fields_start = Clock::now();
  const OrientedEdgeFields fields(edges, camera_.width, camera_.height, options_.edges);
  estimate.fields_ms = MillisecondsSince(fields_start);

  const Clock::time_point solve_start = Clock::now();
  const Rigid3d predicted_world_from_cam = motion_.Predict(t_ns);
  const Rigid3d keyframe_from_world = world_from_keyframe_.Inverse();
  const EdgeRegistration registration =
      RegisterToOrientedEdges(keyframe_points_, fields, table_.ideal_camera(),
                              predicted_world_from_cam.Inverse() * world_from_keyframe_, options_);
  estimate.solve_ms = MillisecondsSince(solve_start);
  estimate.iterations = registration.iterations;
  estimate.points_used = registration.points_used;
  estimate.inlier_fraction = registration.inlier_fraction;
  estimate.rms_residual_px = registration.rms_residual_px;
  estimate.tracked = registration.points_used >= options_.min_points &&
                     registration.inlier_fraction >= options_.min_inlier_fraction &&
                     registration.cam_from_reference.IsFinite();
  if (estimate.tracked) {
    estimate.world_from_cam = world_from_keyframe_ * registration.cam_from_reference.Inverse();
    const Eigen::LDLT<Matrix6d> ldlt(registration.information);
    estimate.covariance = registration.residual_variance * ldlt.solve(Matrix6d::Identity());
    if (!estimate.covariance.allFinite()) {
      estimate.covariance = tracking::kUnconstrainedVariance * Matrix6d::Identity();
    }
    motion_.Update(estimate.world_from_cam, t_ns);
  } else {
    estimate.world_from_cam = predicted_world_from_cam;
    estimate.covariance = tracking::kUnconstrainedVariance * Matrix6d::Identity();
    motion_.Update(estimate.world_from_cam, t_ns);
    motion_.StopMotion();
  }
  // A new keyframe when the view has moved on (or the old one no longer tracks).
  const Rigid3d keyframe_from_cam = keyframe_from_world * estimate.world_from_cam;
  const double visible_fraction =
      keyframe_points_.empty()
          ? 0.0
          : static_cast<double>(registration.points_in_view) / keyframe_points_.size();
  const double rotation_deg =
      AngleBetween(keyframe_from_cam.rotation, Eigen::Quaterniond::Identity()) * 180.0 / M_PI;
  if (!estimate.tracked || visible_fraction < options_.keyframe_min_visible_fraction ||
      keyframe_from_cam.translation.norm() >
          options_.keyframe_max_baseline_fraction * keyframe_median_depth_m_ ||
      rotation_deg > options_.keyframe_max_rotation_deg) {
    const Clock::time_point keyframe_start = Clock::now();
    TakeKeyframe(edges, depth_m, estimate.world_from_cam);
    estimate.keyframe_ms = MillisecondsSince(keyframe_start);
    estimate.new_keyframe = true;
  }
  last_t_ns_ = t_ns;
  estimate.total_ms = MillisecondsSince(start);
  return estimate;
}

}  // namespace evloc::odometry
