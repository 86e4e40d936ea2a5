// Rigid and similarity transforms on Eigen, named by direction (docs/conventions.md):
// `b_from_a` maps coordinates in frame a to frame b, `p_b = b_from_a * p_a`, and
// `c_from_a = c_from_b * b_from_a`.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace evloc {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Matrix3x4d = Eigen::Matrix<double, 3, 4>;

// A rigid transform (rotation, then translation): p_b = rotation * p_a + translation.
struct Rigid3d {
  // Unit quaternion; kept normalised by every operation of this file.
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  // Translation in the target frame, metres.
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& rotation_in, const Eigen::Vector3d& translation_in)
      : rotation(rotation_in.normalized()), translation(translation_in) {}

  // The identity transform.
  static Rigid3d Identity() { return Rigid3d(); }
  // From a 3x4 [R|t] or the top rows of a 4x4 homogeneous matrix; R is re-orthonormalised.
  static Rigid3d FromMatrix(const Matrix3x4d& matrix);
  static Rigid3d FromMatrix(const Eigen::Matrix4d& matrix) {
    return FromMatrix(Matrix3x4d(matrix.topRows<3>()));
  }

  // The 3x3 rotation matrix.
  Eigen::Matrix3d RotationMatrix() const { return rotation.toRotationMatrix(); }
  // The 3x4 matrix [R|t].
  Matrix3x4d ToMatrix3x4() const;
  // The 4x4 homogeneous matrix.
  Eigen::Matrix4d ToMatrix4() const;
  // a_from_b for this b_from_a.
  Rigid3d Inverse() const;
  // Maps a point: p_b = b_from_a * p_a.
  Eigen::Vector3d operator*(const Eigen::Vector3d& point) const {
    return rotation * point + translation;
  }
  // True when every coefficient is finite.
  bool IsFinite() const;
};

// Composition: c_from_a = c_from_b * b_from_a.
Rigid3d operator*(const Rigid3d& c_from_b, const Rigid3d& b_from_a);

// A similarity transform: p_b = scale * (rotation * p_a) + translation.
struct Sim3d {
  // Positive scale factor.
  double scale = 1.0;
  // Unit quaternion.
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  // Translation in the target frame.
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  // Maps a point.
  Eigen::Vector3d operator*(const Eigen::Vector3d& point) const {
    return scale * (rotation * point) + translation;
  }
  // The inverse similarity.
  Sim3d Inverse() const;
  // Maps a camera pose world_from_cam (in the source frame) into the target frame: the rotation
  // is rotated, the centre is transformed; the scale does not apply to the orientation.
  Rigid3d TransformPose(const Rigid3d& source_from_cam) const;
};

// Skew-symmetric matrix of v: Hat(v) * w == v.cross(w).
Eigen::Matrix3d Hat(const Eigen::Vector3d& v);

// Exponential map of SO(3): rotation by |omega| radians about omega/|omega|.
Eigen::Quaterniond ExpSO3(const Eigen::Vector3d& omega);
// Logarithm of SO(3): the rotation vector, with angle in [0, pi].
Eigen::Vector3d LogSO3(const Eigen::Quaterniond& rotation);

// Exponential map of SE(3). The twist is ordered (v, omega): xi.head<3>() is the translational
// part, xi.tail<3>() the rotation vector (the Sophus convention).
Rigid3d ExpSE3(const Vector6d& xi);
// Logarithm of SE(3), ordered (v, omega).
Vector6d LogSE3(const Rigid3d& transform);

// Pose interpolation for trajectories: slerp of the rotation and linear interpolation of the
// translation (as the TUM and ECD evaluation tools do). alpha = 0 gives a, alpha = 1 gives b;
// alpha outside [0, 1] extrapolates.
Rigid3d Interpolate(const Rigid3d& a, const Rigid3d& b, double alpha);

// Angle of the rotation between two orientations, radians in [0, pi].
double AngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);

// Umeyama (1991) least-squares alignment: the transform target_from_source minimising
// sum |target_i - T(source_i)|^2. With `with_scale` false the scale is fixed to 1 (SE(3)).
// Throws InvalidArgumentError when the point sets differ in size, have fewer than 3 points, or
// are degenerate (collinear or coincident), so that the rotation is not determined.
Sim3d AlignUmeyama(const Eigen::Matrix3Xd& source, const Eigen::Matrix3Xd& target, bool with_scale);

}  // namespace evloc
