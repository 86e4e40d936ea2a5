#include "core/geometry/rigid3.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/common/error.h"

namespace evloc {
namespace {

Rigid3d RandomRigid(std::mt19937& rng, double max_angle = M_PI) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Eigen::Vector3d axis(uniform(rng), uniform(rng), uniform(rng));
  axis.normalize();
  const double angle = max_angle * std::abs(uniform(rng));
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(angle, axis)),
                 Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng)) * 3.0);
}

void ExpectNear(const Rigid3d& a, const Rigid3d& b, double tolerance) {
  EXPECT_LT(AngleBetween(a.rotation, b.rotation), tolerance);
  EXPECT_LT((a.translation - b.translation).norm(), tolerance);
}

TEST(Rigid3d, ComposesByDirection) {
  std::mt19937 rng(1);
  const Rigid3d b_from_a = RandomRigid(rng);
  const Rigid3d c_from_b = RandomRigid(rng);
  const Eigen::Vector3d p_a(0.3, -1.2, 2.5);
  const Rigid3d c_from_a = c_from_b * b_from_a;
  EXPECT_LT((c_from_a * p_a - c_from_b * (b_from_a * p_a)).norm(), 1e-12);
  EXPECT_LT((c_from_a.ToMatrix4() - c_from_b.ToMatrix4() * b_from_a.ToMatrix4()).norm(), 1e-12);
}

TEST(Rigid3d, InverseUndoesTransform) {
  std::mt19937 rng(2);
  for (int i = 0; i < 100; ++i) {
    const Rigid3d b_from_a = RandomRigid(rng);
    ExpectNear(b_from_a * b_from_a.Inverse(), Rigid3d::Identity(), 1e-12);
    ExpectNear(b_from_a.Inverse() * b_from_a, Rigid3d::Identity(), 1e-12);
  }
}

TEST(Rigid3d, MatrixRoundTrip) {
  std::mt19937 rng(3);
  const Rigid3d transform = RandomRigid(rng);
  ExpectNear(Rigid3d::FromMatrix(transform.ToMatrix4()), transform, 1e-12);
  ExpectNear(Rigid3d::FromMatrix(transform.ToMatrix3x4()), transform, 1e-12);
}

TEST(SO3, ExpLogRoundTrip) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (int i = 0; i < 200; ++i) {
    Eigen::Vector3d omega(uniform(rng), uniform(rng), uniform(rng));
    omega *= (M_PI - 1e-6) * std::abs(uniform(rng)) / omega.norm();
    EXPECT_LT((LogSO3(ExpSO3(omega)) - omega).norm(), 1e-9) << omega.transpose();
  }
  // Tiny angles use the series and stay accurate.
  const Eigen::Vector3d tiny(1e-10, -2e-10, 3e-11);
  EXPECT_LT((LogSO3(ExpSO3(tiny)) - tiny).norm(), 1e-20);
}

TEST(SO3, ExpMatchesAngleAxis) {
  const Eigen::Vector3d omega(0.2, -0.5, 0.9);
  const Eigen::Quaterniond expected(Eigen::AngleAxisd(omega.norm(), omega.normalized()));
  EXPECT_LT(AngleBetween(ExpSO3(omega), expected), 1e-12);
}

TEST(SE3, ExpLogRoundTrip) {
  std::mt19937 rng(5);
  for (int i = 0; i < 200; ++i) {
    const Rigid3d transform = RandomRigid(rng, M_PI - 1e-3);
    ExpectNear(ExpSE3(LogSE3(transform)), transform, 1e-9);
  }
  Vector6d xi;
  xi << 0.1, -0.2, 0.3, 1e-12, 0, -1e-12;
  EXPECT_LT((LogSE3(ExpSE3(xi)) - xi).norm(), 1e-12);
}

TEST(SE3, ExpOfPureTranslationIsTranslation) {
  Vector6d xi = Vector6d::Zero();
  xi.head<3>() << 1, 2, 3;
  ExpectNear(ExpSE3(xi), Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 2, 3)), 1e-15);
}

TEST(SE3, ExpMatchesMatrixExponentialSeries) {
  Vector6d xi;
  xi << 0.4, -0.1, 0.7, 0.3, -0.6, 0.2;
  Eigen::Matrix4d generator = Eigen::Matrix4d::Zero();
  generator.topLeftCorner<3, 3>() = Hat(xi.tail<3>());
  generator.topRightCorner<3, 1>() = xi.head<3>();
  Eigen::Matrix4d series = Eigen::Matrix4d::Identity();
  Eigen::Matrix4d term = Eigen::Matrix4d::Identity();
  for (int k = 1; k < 30; ++k) {
    term = term * generator / k;
    series += term;
  }
  EXPECT_LT((ExpSE3(xi).ToMatrix4() - series).norm(), 1e-12);
}

TEST(Interpolate, EndPointsAndMidpoint) {
  std::mt19937 rng(6);
  const Rigid3d a = RandomRigid(rng);
  const Rigid3d b = RandomRigid(rng);
  ExpectNear(Interpolate(a, b, 0.0), a, 1e-12);
  ExpectNear(Interpolate(a, b, 1.0), b, 1e-9);
  const Rigid3d middle = Interpolate(a, b, 0.5);
  EXPECT_NEAR(AngleBetween(a.rotation, middle.rotation), AngleBetween(middle.rotation, b.rotation),
              1e-9);
  EXPECT_LT((middle.translation - 0.5 * (a.translation + b.translation)).norm(), 1e-12);
}

TEST(AlignUmeyama, RecoversKnownSimilarity) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-5.0, 5.0);
  Eigen::Matrix3Xd source(3, 50);
  for (int i = 0; i < source.cols(); ++i) source.col(i) << uniform(rng), uniform(rng), uniform(rng);
  const Rigid3d rigid = RandomRigid(rng);
  Sim3d truth;
  truth.scale = 2.7;
  truth.rotation = rigid.rotation;
  truth.translation = rigid.translation;
  Eigen::Matrix3Xd target(3, source.cols());
  for (int i = 0; i < source.cols(); ++i) target.col(i) = truth * Eigen::Vector3d(source.col(i));

  const Sim3d similarity = AlignUmeyama(source, target, /*with_scale=*/true);
  EXPECT_NEAR(similarity.scale, 2.7, 1e-9);
  EXPECT_LT(AngleBetween(similarity.rotation, truth.rotation), 1e-9);
  EXPECT_LT((similarity.translation - truth.translation).norm(), 1e-9);

  // Without scale, a pure rigid motion is recovered exactly.
  for (int i = 0; i < source.cols(); ++i) target.col(i) = rigid * Eigen::Vector3d(source.col(i));
  const Sim3d rigid_fit = AlignUmeyama(source, target, /*with_scale=*/false);
  EXPECT_EQ(rigid_fit.scale, 1.0);
  EXPECT_LT(AngleBetween(rigid_fit.rotation, rigid.rotation), 1e-9);
  EXPECT_LT((rigid_fit.translation - rigid.translation).norm(), 1e-9);
}

TEST(AlignUmeyama, RejectsDegenerateInput) {
  Eigen::Matrix3Xd two(3, 2);
  two.setRandom();
  EXPECT_THROW(AlignUmeyama(two, two, true), InvalidArgumentError);
  Eigen::Matrix3Xd collinear(3, 5);
  for (int i = 0; i < 5; ++i) collinear.col(i) = Eigen::Vector3d(1, 2, 3) * i;
  EXPECT_THROW(AlignUmeyama(collinear, collinear, true), InvalidArgumentError);
  Eigen::Matrix3Xd other(3, 4);
  other.setRandom();
  Eigen::Matrix3Xd three(3, 3);
  three.setRandom();
  EXPECT_THROW(AlignUmeyama(other, three, true), InvalidArgumentError);
}

TEST(Sim3d, InverseAndPoseTransform) {
  Sim3d similarity;
  similarity.scale = 0.5;
  similarity.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  similarity.translation = Eigen::Vector3d(1, 2, 3);
  const Eigen::Vector3d p(4, -5, 6);
  EXPECT_LT((similarity.Inverse() * (similarity * p) - p).norm(), 1e-12);
  const Rigid3d world_from_cam(Eigen::Quaterniond::Identity(), p);
  const Rigid3d moved = similarity.TransformPose(world_from_cam);
  EXPECT_LT((moved.translation - similarity * p).norm(), 1e-12);
  EXPECT_LT(AngleBetween(moved.rotation, similarity.rotation), 1e-12);
}

}  // namespace
}  // namespace evloc
