#include "core/geometry/rigid3.h"

#include <Eigen/SVD>
#include <cmath>
#include <string>

#include "core/common/error.h"

namespace evloc {

Rigid3d Rigid3d::FromMatrix(const Matrix3x4d& matrix) {
  // Project onto SO(3) so that a slightly non-orthonormal input still gives a rotation.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(matrix.leftCols<3>(),
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d rotation = svd.matrixU() * svd.matrixV().transpose();
  if (rotation.determinant() < 0) {
    Eigen::Matrix3d u = svd.matrixU();
    u.col(2) *= -1;
    rotation = u * svd.matrixV().transpose();
  }
  return Rigid3d(Eigen::Quaterniond(rotation), matrix.col(3));
}

Matrix3x4d Rigid3d::ToMatrix3x4() const {
  Matrix3x4d matrix;
  matrix.leftCols<3>() = RotationMatrix();
  matrix.col(3) = translation;
  return matrix;
}

Eigen::Matrix4d Rigid3d::ToMatrix4() const {
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();
  matrix.topRows<3>() = ToMatrix3x4();
  return matrix;
}

Rigid3d Rigid3d::Inverse() const {
  const Eigen::Quaterniond inverse_rotation = rotation.conjugate();
  return Rigid3d(inverse_rotation, -(inverse_rotation * translation));
}

bool Rigid3d::IsFinite() const { return rotation.coeffs().allFinite() && translation.allFinite(); }

Rigid3d operator*(const Rigid3d& c_from_b, const Rigid3d& b_from_a) {
  return Rigid3d(c_from_b.rotation * b_from_a.rotation,
                 c_from_b.rotation * b_from_a.translation + c_from_b.translation);
}

Sim3d Sim3d::Inverse() const {
  Sim3d inverse;
  inverse.scale = 1.0 / scale;
  inverse.rotation = rotation.conjugate();
  inverse.translation = -(inverse.scale * (inverse.rotation * translation));
  return inverse;
}

Rigid3d Sim3d::TransformPose(const Rigid3d& source_from_cam) const {
  return Rigid3d(rotation * source_from_cam.rotation, (*this) * source_from_cam.translation);
}

Eigen::Matrix3d Hat(const Eigen::Vector3d& v) {
  Eigen::Matrix3d matrix;
  matrix << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return matrix;
}

Eigen::Quaterniond ExpSO3(const Eigen::Vector3d& omega) {
  const double theta_squared = omega.squaredNorm();
  const double theta = std::sqrt(theta_squared);
  double real;
  double imaginary_factor;
  if (theta < 1e-8) {
    // Taylor expansion: sin(theta/2)/theta ~ 1/2 - theta^2/48.
    real = 1.0 - theta_squared / 8.0;
    imaginary_factor = 0.5 - theta_squared / 48.0;
  } else {
    real = std::cos(0.5 * theta);
    imaginary_factor = std::sin(0.5 * theta) / theta;
  }
  return Eigen::Quaterniond(real, imaginary_factor * omega.x(), imaginary_factor * omega.y(),
                            imaginary_factor * omega.z())
      .normalized();
}

Eigen::Vector3d LogSO3(const Eigen::Quaterniond& rotation) {
  Eigen::Quaterniond q = rotation.normalized();
  if (q.w() < 0) q.coeffs() *= -1;  // Angle in [0, pi].
  const Eigen::Vector3d imaginary = q.vec();
  const double sin_half = imaginary.norm();
  if (sin_half < 1e-8) {
    // theta ~ 2 sin(theta/2), with the next term of the series.
    return (2.0 / q.w()) * (1.0 - sin_half * sin_half / (3.0 * q.w() * q.w())) * imaginary;
  }
  const double theta = 2.0 * std::atan2(sin_half, q.w());
  return (theta / sin_half) * imaginary;
}

namespace {

// Left Jacobian of SO(3), V in t = V v.
Eigen::Matrix3d LeftJacobianSO3(const Eigen::Vector3d& omega) {
  const double theta_squared = omega.squaredNorm();
  const Eigen::Matrix3d omega_hat = Hat(omega);
  if (theta_squared < 1e-10) {
    return Eigen::Matrix3d::Identity() + 0.5 * omega_hat + omega_hat * omega_hat / 6.0;
  }
  const double theta = std::sqrt(theta_squared);
  return Eigen::Matrix3d::Identity() + (1.0 - std::cos(theta)) / theta_squared * omega_hat +
         (theta - std::sin(theta)) / (theta_squared * theta) * omega_hat * omega_hat;
}

// Inverse of the left Jacobian of SO(3).
Eigen::Matrix3d InverseLeftJacobianSO3(const Eigen::Vector3d& omega) {
  const double theta_squared = omega.squaredNorm();
  const Eigen::Matrix3d omega_hat = Hat(omega);
  if (theta_squared < 1e-10) {
    return Eigen::Matrix3d::Identity() - 0.5 * omega_hat + omega_hat * omega_hat / 12.0;
  }
  const double theta = std::sqrt(theta_squared);
  const double half = 0.5 * theta;
  const double factor = (1.0 - half * std::cos(half) / std::sin(half)) / theta_squared;
  return Eigen::Matrix3d::Identity() - 0.5 * omega_hat + factor * omega_hat * omega_hat;
}

}  // namespace

Rigid3d ExpSE3(const Vector6d& xi) {
  const Eigen::Vector3d v = xi.head<3>();
  const Eigen::Vector3d omega = xi.tail<3>();
  return Rigid3d(ExpSO3(omega), LeftJacobianSO3(omega) * v);
}

Vector6d LogSE3(const Rigid3d& transform) {
  const Eigen::Vector3d omega = LogSO3(transform.rotation);
  Vector6d xi;
  xi.head<3>() = InverseLeftJacobianSO3(omega) * transform.translation;
  xi.tail<3>() = omega;
  return xi;
}

Rigid3d Interpolate(const Rigid3d& a, const Rigid3d& b, double alpha) {
  // Slerp along the shorter arc; Eigen's slerp handles the sign of the dot product.
  const Eigen::Quaterniond relative = a.rotation.conjugate() * b.rotation;
  Eigen::Vector3d omega = LogSO3(relative);
  const Eigen::Quaterniond rotation = a.rotation * ExpSO3(alpha * omega);
  return Rigid3d(rotation, (1.0 - alpha) * a.translation + alpha * b.translation);
}

double AngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return LogSO3(a.conjugate() * b).norm();
}

Sim3d AlignUmeyama(const Eigen::Matrix3Xd& source, const Eigen::Matrix3Xd& target,
                   bool with_scale) {
  const Eigen::Index count = source.cols();
  if (count != target.cols()) {
    throw InvalidArgumentError("alignment: " + std::to_string(count) + " source points but " +
                               std::to_string(target.cols()) + " target points");
  }
  if (count < 3) {
    throw InvalidArgumentError("alignment needs at least 3 point pairs, got " +
                               std::to_string(count));
  }
  if (!source.allFinite() || !target.allFinite()) {
    throw InvalidArgumentError("alignment: points contain NaN or infinity");
  }
  const Eigen::Vector3d source_mean = source.rowwise().mean();
  const Eigen::Vector3d target_mean = target.rowwise().mean();
  const Eigen::Matrix3Xd source_centred = source.colwise() - source_mean;
  const Eigen::Matrix3Xd target_centred = target.colwise() - target_mean;
  const double source_variance = source_centred.squaredNorm() / static_cast<double>(count);
  const Eigen::Matrix3d covariance =
      target_centred * source_centred.transpose() / static_cast<double>(count);

  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance,
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d singular = svd.singularValues();
  // The rotation is determined when at least two singular values are non-zero (points not all
  // on one line).
  if (source_variance <= 1e-18 || singular(1) <= 1e-12 * std::max(1.0, singular(0))) {
    throw InvalidArgumentError(
        "alignment is degenerate: the points are coincident or collinear, so the rotation is not "
        "determined; give at least 3 non-collinear positions");
  }
  Eigen::Vector3d signs = Eigen::Vector3d::Ones();
  if ((svd.matrixU().determinant() * svd.matrixV().determinant()) < 0) signs(2) = -1;
  const Eigen::Matrix3d rotation = svd.matrixU() * signs.asDiagonal() * svd.matrixV().transpose();

  Sim3d result;
  result.rotation = Eigen::Quaterniond(rotation).normalized();
  result.scale = with_scale ? singular.dot(signs) / source_variance : 1.0;
  result.translation = target_mean - result.scale * (rotation * source_mean);
  return result;
}

}  // namespace evloc
