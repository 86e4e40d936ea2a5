// Canny-VO (Zhou, Li and Kneip 2018; docs/tracking.md, "Mapless odometry"): RGB-D visual
// odometry on edges. A keyframe's Canny edges are lifted with its depth into 3D points with 3D
// gradients (maps/edge_lifting.h); every later frame is registered to the keyframe by a robust
// Gauss-Newton on SE(3) whose residuals are the distances, along the edge normal, from each
// projected point to the nearest edge of the frame in the point's orientation bin
// (oriented_edges.h). A new keyframe is taken when too few keyframe points remain in view, or the
// baseline or rotation to the keyframe grows too large.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/camera/undistortion_table.h"
#include "core/geometry/rigid3.h"
#include "localizer/odometry/oriented_edges.h"
#include "localizer/tracking/motion_model.h"
#include "localizer/tracking/tracker_options.h"

namespace evloc::odometry {

// Options of Canny-VO.
struct CannyVoOptions {
  // Edge detection and the oriented fields.
  OrientedEdgeOptions edges;
  // Keyframe points kept (evenly over the image, 16 px buckets).
  int max_points = 3000;
  // Depths outside [min_depth_m, max_depth_m] are not lifted, metres.
  double min_depth_m = 0.1;
  // Farthest depth lifted, metres.
  double max_depth_m = 10.0;
  // An edge pixel whose 3x3 depth neighbourhood spans more than this fraction of its depth lies
  // on a depth discontinuity: it takes the nearest (foreground) depth of the neighbourhood.
  double depth_discontinuity_fraction = 0.05;
  // Robust loss of the residuals (pixels along the edge normal).
  tracking::RobustLoss loss = tracking::RobustLoss::kHuber;
  // Its scale, pixels.
  double robust_scale_px = 1.5;
  // Gauss-Newton iterations per frame at most.
  int max_iterations = 20;
  // Stop when the increment's norm (metres and radians) falls below this.
  double min_increment = 1e-6;
  // A frame is tracked when at least this many points have a nearest edge...
  int min_points = 50;
  // ... and at least this fraction of the points in view lie within inlier_px of theirs.
  double min_inlier_fraction = 0.3;
  // Inlier distance, pixels.
  double inlier_px = 2.0;
  // New keyframe when fewer than this fraction of the keyframe's points project into the image.
  double keyframe_min_visible_fraction = 0.7;
  // New keyframe when the baseline to the keyframe exceeds this fraction of its median depth.
  double keyframe_max_baseline_fraction = 0.1;
  // New keyframe when the rotation to the keyframe exceeds this, degrees.
  double keyframe_max_rotation_deg = 10.0;
  // Constant-velocity window of the motion prior, seconds.
  double velocity_window_s = 0.1;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// One keyframe point, in the keyframe's camera frame.
struct KeyframePoint {
  // Position, metres.
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  // Unit 3D gradient direction.
  Eigen::Vector3d gradient = Eigen::Vector3d::UnitX();
};

// The 3D edge points of an RGB-D keyframe: `edges` lifted with `depth_m` (CV_32FC1 metres of the
// same camera, 0 = none), up to max_points evenly spread. Edge pixels without a valid depth are
// dropped; on a depth discontinuity the foreground depth is used (see CannyVoOptions).
std::vector<KeyframePoint> LiftKeyframeEdges(const Camera& camera,
                                             const std::vector<EdgePixel>& edges,
                                             const cv::Mat& depth_m, const CannyVoOptions& options);

// The outcome of one frame.
struct VoEstimate {
  // Frame time, nanoseconds.
  int64_t t_ns = 0;
  // The estimate (the prediction when the frame was not tracked).
  Rigid3d world_from_cam;
  // Covariance of xi in world_from_cam * ExpSE3(xi), (v, omega): sigma^2 H^-1 of the final
  // iteration (1e6 * I when not tracked).
  Matrix6d covariance = Matrix6d::Identity();
  // True when the frame met min_points and min_inlier_fraction.
  bool tracked = false;
  // True when the frame became the new keyframe (the first frame too).
  bool new_keyframe = false;
  // Points with a nearest edge at the estimate.
  int points_used = 0;
  // Fraction of the keyframe points in view that lie within inlier_px of their edge.
  double inlier_fraction = 0;
  // Root mean square of the inlier residuals, pixels.
  double rms_residual_px = 0;
  // Gauss-Newton iterations run.
  int iterations = 0;
  // Edge detection and fields of the frame, milliseconds.
  double fields_ms = 0;
  // Registration, milliseconds.
  double solve_ms = 0;
  // Keyframe lifting (0 when no keyframe was taken), milliseconds.
  double keyframe_ms = 0;
  // The whole frame, milliseconds.
  double total_ms = 0;
};

// Canny-VO over a sequence of RGB-D frames. Not thread-safe.
class CannyVo {
 public:
  // `camera` is the camera of the grey and depth images (depth registered to it). Throws
  // InvalidArgumentError for bad options or camera.
  CannyVo(const Camera& camera, const CannyVoOptions& options);

  // Sets the pose of the next frame, which becomes the first keyframe.
  void Reset(const Rigid3d& world_from_cam, int64_t t_ns);

  // Tracks one frame (CV_8UC1 grey and CV_32FC1 depth in metres, the camera's size) taken at
  // t_ns, after the previous one. Throws InvalidArgumentError before Reset, for images of another
  // type or size, or a time not after the previous frame's.
  VoEstimate AddFrame(int64_t t_ns, const cv::Mat& gray, const cv::Mat& depth_m);

  // The current keyframe's points (its camera frame) and pose.
  const std::vector<KeyframePoint>& keyframe_points() const { return keyframe_points_; }
  // world_from_cam of the current keyframe.
  const Rigid3d& world_from_keyframe() const { return world_from_keyframe_; }
  // The options in use.
  const CannyVoOptions& options() const { return options_; }

 private:
  // Makes the frame the keyframe at `world_from_cam`.
  void TakeKeyframe(const std::vector<EdgePixel>& edges, const cv::Mat& depth_m,
                    const Rigid3d& world_from_cam);

  Camera camera_;
  CannyVoOptions options_;
  UndistortionTable table_;
  tracking::ConstantVelocityModel motion_;
  bool started_ = false;
  bool has_keyframe_ = false;
  std::optional<int64_t> last_t_ns_;
  Rigid3d world_from_keyframe_;
  double keyframe_median_depth_m_ = 1.0;
  std::vector<KeyframePoint> keyframe_points_;
};

// The registration of 3D points (in a reference frame) to the oriented edges of an image: robust
// Gauss-Newton on cam_from_reference with residuals along the nearest edge's normal. Exposed for
// tests and the event variant; `intrinsics` are the ideal pinhole camera of the fields.
struct EdgeRegistration {
  // The estimate.
  Rigid3d cam_from_reference;
  // Gauss-Newton information matrix at the estimate (robustly weighted).
  Matrix6d information = Matrix6d::Zero();
  // Weighted residual variance (pixels^2).
  double residual_variance = 0;
  // Points in view at the estimate.
  int points_in_view = 0;
  // Points with a nearest edge at the estimate.
  int points_used = 0;
  // Of those in view, the fraction within inlier_px.
  double inlier_fraction = 0;
  // RMS of the inlier residuals, pixels.
  double rms_residual_px = 0;
  // Iterations run.
  int iterations = 0;
};

// Registers `points` to `fields` starting from `initial_cam_from_reference`.
EdgeRegistration RegisterToOrientedEdges(const std::vector<KeyframePoint>& points,
                                         const OrientedEdgeFields& fields, const Camera& ideal,
                                         const Rigid3d& initial_cam_from_reference,
                                         const CannyVoOptions& options);

}  // namespace evloc::odometry
