#include "localizer/tracking/registration.h"

#include <cmath>
#include <typeinfo>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "core/common/error.h"
#include "localizer/tracking/time_surface.h"

namespace evloc::tracking {
namespace {

// With the early stop on (min_relative_decrease > 0), a trial whose increment moves the points by
// less than this in the image ends the solve: the bilinear field of edges rounded to pixels has
// no meaningful minimum below that scale, and the trials after such a step only chase its
// roughness. Measured (docs/tracking.md, "Performance"): on 10 s of simulated mid motion at
// 640x480, 0.2 px halves the LM trials (5.8 -> 2.9 per step) with the same ATE.
constexpr double kNegligibleMotionPx = 0.2;

// After a rejected trial, the next increment must differ from the rejected one by at least this
// fraction of its length; the damping is raised (at most kMaxDampingRaises times, without
// evaluating the cost) until it does. Measured (docs/tracking.md, "Performance"): on the
// fr1_xyz-driven sequence, 4.19 -> 3.49 LM trials per step with the same ATE.
constexpr double kMinRetryChange = 0.25;
constexpr int kMaxDampingRaises = 30;

// The image motion of increment (v, omega), pixels, for points at the given mean inverse depth:
// f * (|v| / z + |omega|), an estimate for points near the image centre.
double IncrementMotionPx(const Vector6d& increment, double focal_px, double mean_inverse_depth) {
  return focal_px * (increment.head<3>().norm() * mean_inverse_depth + increment.tail<3>().norm());
}

// Normal equations and cost of all points at one pose.
struct Linearization {
  Matrix6d information = Matrix6d::Zero();
  Vector6d gradient = Vector6d::Zero();
  double cost = 0;
  double weighted_squared_residuals = 0;
  double sum_residuals = 0;
  // Sum of 1 / depth over the points used (their mean inverse depth scales image motion).
  double sum_inverse_depths = 0;
  int points_used = 0;
};

// The pose cam_from_world as a row-major 3x4 matrix of plain doubles: the hot loop transforms
// with it without Eigen's expression machinery (which the compiler does not always inline).
struct PoseMatrix {
  double r[9];
  double t[3];

  explicit PoseMatrix(const Rigid3d& cam_from_world) {
    const Eigen::Matrix3d rotation = cam_from_world.RotationMatrix();
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) r[3 * i + j] = rotation(i, j);
      t[i] = cam_from_world.translation(i);
    }
  }
};

// A point transformed into the camera at one pose and projected: camera coordinates, inverse
// depth, normalised coordinates (x, y) and pixel (u, v).
struct ProjectedPoint {
  double cam_x;
  double cam_y;
  double z;
  double inverse_z;
  double x;
  double y;
  double u;
  double v;
};

// Projects `position_world` at `pose` (cam_from_world). False when the point is behind the camera
// or its pixel is not inside the `width` x `height` image shrunk by `margin_px`.
[[gnu::always_inline]] inline bool ProjectPoint(const PinholeIntrinsics& intrinsics,
                                                const PoseMatrix& pose,
                                                const Eigen::Vector3d& position_world,
                                                double margin_px, int width, int height,
                                                ProjectedPoint* projected) {
  const double* r = pose.r;
  const double px = position_world.x();
  const double py = position_world.y();
  const double pz = position_world.z();
  // The sums in the order Eigen's `rotation * p + t` uses (results are bit-identical to it).
  const double cam_x = (r[0] * px + r[1] * py + r[2] * pz) + pose.t[0];
  const double cam_y = (r[3] * px + r[4] * py + r[5] * pz) + pose.t[1];
  const double z = (r[6] * px + (r[7] * py + r[8] * pz)) + pose.t[2];
  if (!(z > Camera::kMinDepth)) return false;
  const double inverse_z = 1.0 / z;
  const double x = cam_x * inverse_z;
  const double y = cam_y * inverse_z;
  const double u = intrinsics.fx * x + intrinsics.cx;
  const double v = intrinsics.fy * y + intrinsics.cy;
  if (!(u >= margin_px && v >= margin_px && u <= width - 1 - margin_px &&
        v <= height - 1 - margin_px)) {
    return false;
  }
  *projected = {cam_x, cam_y, z, inverse_z, x, y, u, v};
  return true;
}

// The residual of a projected point and, when `jacobian` (6 values) is not null, its derivative
// with respect to the left increment. `Field` is the concrete field type so that the per-sample
// call is not virtual in the hot loop. False when the field has no value there.
template <typename Field>
[[gnu::always_inline]] inline bool SampleProjected(Field& field,
                                                   const PinholeIntrinsics& intrinsics,
                                                   const ProjectedPoint& point, double* residual,
                                                   double* jacobian) {
  Eigen::Vector2d field_gradient;
  if (!field.Sample(point.u, point.v, residual, jacobian ? &field_gradient : nullptr)) {
    return false;
  }
  if (jacobian != nullptr) {
    // dr/dp = grad F * d pi/d p; dr/d omega = dr/dp * (-Hat(p)) = p x dr/dp.
    const double a0 = field_gradient.x() * intrinsics.fx * point.inverse_z;
    const double a1 = field_gradient.y() * intrinsics.fy * point.inverse_z;
    const double a2 = -(a0 * point.x + a1 * point.y);
    jacobian[0] = a0;
    jacobian[1] = a1;
    jacobian[2] = a2;
    jacobian[3] = point.cam_y * a2 - point.z * a1;
    jacobian[4] = point.z * a0 - point.cam_x * a2;
    jacobian[5] = point.cam_x * a1 - point.cam_y * a0;
  }
  return true;
}

// Hints the cell a concrete field will sample at (u, v) into the cache; nothing for fields of
// unknown type.
template <typename Field>
inline void PrefetchCell(const Field& field, double u, double v) {
  field.Prefetch(u, v);
}
template <>
inline void PrefetchCell<PotentialField>(const PotentialField&, double, double) {}

// What one used point contributes to the normal equations: its Jacobian row, robust weight and
// residual. Linearize writes the rows; Accumulate sums them only for the linearisations the
// solver keeps (a rejected trial needs its cost alone).
struct JacobianRow {
  double jacobian[6];
  double weight;
  double residual;
};

// The per-point storage of Linearize, reused across trials and solves.
struct LinearizeWorkspace {
  // Jacobian rows of the used points (see Accumulate).
  std::vector<JacobianRow> rows;
  // Per point, its projection at the pose being linearised, and whether it is valid.
  std::vector<ProjectedPoint> projected;
  std::vector<uint8_t> inside;
};

// How many points ahead Linearize prefetches the field cell a point will sample: the cells of
// successive points lie far apart in the image, and most of a sample's time was the wait for
// its memo's cache lines.
constexpr size_t kPrefetchDistance = 8;

// Cost of all points at one pose, and their Jacobian rows in `rows` (one per used point, in point
// order; information and gradient are left to Accumulate). `Field` is the concrete type of every
// point's field (PotentialField when they differ); `kLoss` the robust loss, so that the weight
// and cost are inline in the loop. Two passes: every point is projected first, then the fields
// are sampled with the cells of later points prefetched.
template <typename Field, RobustLoss kLoss>
Linearization Linearize(const std::vector<RegistrationPoint>& points,
                        const PinholeIntrinsics& intrinsics, const Rigid3d& cam_from_world,
                        const RegistrationOptions& options, LinearizeWorkspace* workspace) {
  std::vector<JacobianRow>* rows = &workspace->rows;
  std::vector<ProjectedPoint>* projected = &workspace->projected;
  std::vector<uint8_t>* inside = &workspace->inside;
  Linearization result;
  const double scale = options.robust_scale;
  // Points outside the image cost as much as a point far from every edge (residual 1), so that
  // costs at different poses compare the same point set.
  const double outside_cost = RobustCost(kLoss, scale, 1.0);
  const PoseMatrix pose(cam_from_world);
  const size_t num_points = points.size();
  if (rows->size() < num_points) rows->resize(num_points);
  if (projected->size() < num_points) projected->resize(num_points);
  if (inside->size() < num_points) inside->resize(num_points);
  ProjectedPoint* projection = projected->data();
  uint8_t* is_inside = inside->data();
  for (size_t i = 0; i < num_points; ++i) {
    const Field& field = static_cast<const Field&>(*points[i].field);
    is_inside[i] = ProjectPoint(intrinsics, pose, points[i].position_world, options.image_margin_px,
                                field.width(), field.height(), &projection[i]);
  }
  for (size_t i = 0; i < std::min(num_points, kPrefetchDistance); ++i) {
    if (is_inside[i]) {
      PrefetchCell(static_cast<const Field&>(*points[i].field), projection[i].u, projection[i].v);
    }
  }
  JacobianRow* row = rows->data();
  double cost = 0;
  double weighted_squared_residuals = 0;
  double sum_residuals = 0;
  double sum_inverse_depths = 0;
  int points_used = 0;
  for (size_t i = 0; i < num_points; ++i) {
    const size_t ahead = i + kPrefetchDistance;
    if (ahead < num_points && is_inside[ahead]) {
      PrefetchCell(static_cast<const Field&>(*points[ahead].field), projection[ahead].u,
                   projection[ahead].v);
    }
    double residual;
    if (!is_inside[i] || !SampleProjected(static_cast<Field&>(*points[i].field), intrinsics,
                                          projection[i], &residual, row->jacobian)) {
      cost += outside_cost;
      continue;
    }
    const double weight = RobustWeight(kLoss, scale, residual);
    row->weight = weight;
    row->residual = residual;
    ++row;
    cost += RobustCost(kLoss, scale, residual);
    weighted_squared_residuals += weight * residual * residual;
    sum_residuals += residual;
    sum_inverse_depths += projection[i].inverse_z;
    ++points_used;
  }
  result.cost = cost;
  result.weighted_squared_residuals = weighted_squared_residuals;
  result.sum_residuals = sum_residuals;
  result.sum_inverse_depths = sum_inverse_depths;
  result.points_used = points_used;
  return result;
}

// Two doubles in one SIMD register (SSE2 on x86-64, NEON on ARM64; GCC and Clang).
typedef double Double2 __attribute__((vector_size(16)));

// The information J^T W J and gradient J^T W r of the first linearization->points_used rows.
// Each entry is summed in point order with the products formed as (w J_i) J_j and (w J_i) r, so
// the result is bit-identical to a scalar loop; pairs of entries share one SIMD operation.
void Accumulate(const std::vector<JacobianRow>& rows, Linearization* linearization) {
  // Upper-triangle rows as pairs: row i holds columns from 2 * floor(i / 2) on.
  Double2 h0[3] = {}, h1[3] = {}, h2[2] = {}, h3[2] = {}, h4 = {}, h5 = {}, g[3] = {};
  for (int n = 0; n < linearization->points_used; ++n) {
    const JacobianRow& row = rows[n];
    const Double2 j01 = {row.jacobian[0], row.jacobian[1]};
    const Double2 j23 = {row.jacobian[2], row.jacobian[3]};
    const Double2 j45 = {row.jacobian[4], row.jacobian[5]};
    const double w = row.weight;
    const Double2 weighted01 = j01 * w;
    const Double2 weighted23 = j23 * w;
    const Double2 weighted45 = j45 * w;
    g[0] += weighted01 * row.residual;
    g[1] += weighted23 * row.residual;
    g[2] += weighted45 * row.residual;
    h0[0] += weighted01[0] * j01;
    h0[1] += weighted01[0] * j23;
    h0[2] += weighted01[0] * j45;
    h1[0] += weighted01[1] * j01;
    h1[1] += weighted01[1] * j23;
    h1[2] += weighted01[1] * j45;
    h2[0] += weighted23[0] * j23;
    h2[1] += weighted23[0] * j45;
    h3[0] += weighted23[1] * j23;
    h3[1] += weighted23[1] * j45;
    h4 += weighted45[0] * j45;
    h5 += weighted45[1] * j45;
  }
  const double upper[6][6] = {
      {h0[0][0], h0[0][1], h0[1][0], h0[1][1], h0[2][0], h0[2][1]},
      {0, h1[0][1], h1[1][0], h1[1][1], h1[2][0], h1[2][1]},
      {0, 0, h2[0][0], h2[0][1], h2[1][0], h2[1][1]},
      {0, 0, 0, h3[0][1], h3[1][0], h3[1][1]},
      {0, 0, 0, 0, h4[0], h4[1]},
      {0, 0, 0, 0, 0, h5[1]},
  };
  for (int i = 0; i < 6; ++i) {
    linearization->gradient(i) = g[i / 2][i % 2];
    for (int j = i; j < 6; ++j) {
      linearization->information(i, j) = upper[i][j];
      linearization->information(j, i) = upper[i][j];
    }
  }
}

// The concrete field type shared by every point, so that Linearize samples without a virtual
// call; PotentialField (virtual calls) when the points use different kinds of field.
enum class FieldKind { kTimeSurface, kDense, kMixed };

FieldKind CommonFieldKind(const std::vector<RegistrationPoint>& points) {
  bool all_time_surface = true;
  bool all_dense = true;
  for (const RegistrationPoint& point : points) {
    const std::type_info& type = typeid(*point.field);
    all_time_surface &= type == typeid(TimeSurfaceField);
    all_dense &= type == typeid(DenseField);
  }
  if (all_time_surface) return FieldKind::kTimeSurface;
  if (all_dense) return FieldKind::kDense;
  return FieldKind::kMixed;
}

template <RobustLoss kLoss>
Linearization LinearizeWithLoss(FieldKind kind, const std::vector<RegistrationPoint>& points,
                                const PinholeIntrinsics& intrinsics, const Rigid3d& cam_from_world,
                                const RegistrationOptions& options, LinearizeWorkspace* workspace) {
  switch (kind) {
    case FieldKind::kTimeSurface:
      return Linearize<TimeSurfaceField, kLoss>(points, intrinsics, cam_from_world, options,
                                                workspace);
    case FieldKind::kDense:
      return Linearize<DenseField, kLoss>(points, intrinsics, cam_from_world, options, workspace);
    case FieldKind::kMixed:
      break;
  }
  return Linearize<PotentialField, kLoss>(points, intrinsics, cam_from_world, options, workspace);
}

// Linearize for the loss of `options`; the rows go to workspace->rows (see Accumulate).
Linearization LinearizeAny(FieldKind kind, const std::vector<RegistrationPoint>& points,
                           const PinholeIntrinsics& intrinsics, const Rigid3d& cam_from_world,
                           const RegistrationOptions& options, LinearizeWorkspace* workspace) {
  if (options.loss == RobustLoss::kCauchy) {
    return LinearizeWithLoss<RobustLoss::kCauchy>(kind, points, intrinsics, cam_from_world, options,
                                                  workspace);
  }
  return LinearizeWithLoss<RobustLoss::kHuber>(kind, points, intrinsics, cam_from_world, options,
                                               workspace);
}

// The prior's residual at `cam_from_world`: the left increment from the prior to it.
Vector6d PriorResidual(const PosePrior& prior, const Rigid3d& cam_from_world) {
  return LogSE3(cam_from_world * prior.cam_from_world.Inverse());
}

// Adds the prior's cost at `cam_from_world` to `linearization` (not its normal equations).
void AddPriorCost(const PosePrior* prior, const Rigid3d& cam_from_world,
                  Linearization* linearization) {
  if (prior == nullptr) return;
  const Vector6d residual = PriorResidual(*prior, cam_from_world);
  linearization->cost += 0.5 * residual.dot(prior->information * residual);
}

// Adds the prior's term to the normal equations of `linearization` at `cam_from_world` (its cost
// is added by AddPriorCost). The residual's derivative with respect to the left increment is
// taken as the identity (exact at the prior; the prior and the pose differ by one step's
// prediction error, centimetres and fractions of a degree).
void AddPriorToSystem(const PosePrior* prior, const Rigid3d& cam_from_world,
                      Linearization* linearization) {
  if (prior == nullptr) return;
  const Vector6d residual = PriorResidual(*prior, cam_from_world);
  linearization->gradient += prior->information * residual;
  linearization->information += prior->information;
}

// sigma^2: the weighted residual variance of the points (1 without redundancy).
double ResidualVariance(const Linearization& linearization) {
  const int redundancy = linearization.points_used - 6;
  return redundancy > 0 ? linearization.weighted_squared_residuals / redundancy : 1.0;
}

// sigma^2 H^-1, with unconstrained directions given a large variance.
Matrix6d Covariance(const Linearization& linearization, bool* well_conditioned) {
  const double variance = ResidualVariance(linearization);
  const Eigen::SelfAdjointEigenSolver<Matrix6d> solver(linearization.information);
  const Vector6d eigenvalues = solver.eigenvalues();
  const double largest = eigenvalues.cwiseAbs().maxCoeff();
  Vector6d inverse_eigenvalues;
  *well_conditioned = largest > 0;
  for (int i = 0; i < 6; ++i) {
    if (largest > 0 && eigenvalues(i) > 1e-12 * largest) {
      inverse_eigenvalues(i) = variance / eigenvalues(i);
    } else {
      inverse_eigenvalues(i) = kUnconstrainedVariance;
      *well_conditioned = false;
    }
  }
  return solver.eigenvectors() * inverse_eigenvalues.asDiagonal() *
         solver.eigenvectors().transpose();
}

}  // namespace

bool EvaluatePointResidual(PotentialField& field, const PinholeIntrinsics& intrinsics,
                           const Rigid3d& cam_from_world, const Eigen::Vector3d& position_world,
                           double margin_px, double* residual, RowVector6d* jacobian) {
  ProjectedPoint projected;
  return ProjectPoint(intrinsics, PoseMatrix(cam_from_world), position_world, margin_px,
                      field.width(), field.height(), &projected) &&
         SampleProjected(field, intrinsics, projected, residual,
                         jacobian ? jacobian->data() : nullptr);
}

RegistrationResult RegisterPoints(const std::vector<RegistrationPoint>& points,
                                  const PinholeIntrinsics& intrinsics,
                                  const Rigid3d& initial_cam_from_world,
                                  const RegistrationOptions& options, const PosePrior* prior) {
  for (const RegistrationPoint& point : points) {
    if (point.field == nullptr) {
      throw InvalidArgumentError("RegisterPoints: every point needs a field.");
    }
  }
  if (prior != nullptr && !prior->information.allFinite()) {
    throw InvalidArgumentError("RegisterPoints: the prior's information is not finite.");
  }
  RegistrationResult result;
  result.cam_from_world = initial_cam_from_world;
  const FieldKind kind = CommonFieldKind(points);
  // Reused across solves (a tracker solves at every step).
  thread_local LinearizeWorkspace workspace;
  Linearization current =
      LinearizeAny(kind, points, intrinsics, initial_cam_from_world, options, &workspace);
  Accumulate(workspace.rows, &current);
  AddPriorCost(prior, initial_cam_from_world, &current);
  AddPriorToSystem(prior, initial_cam_from_world, &current);
  double damping = options.initial_damping;
  double growth = 2.0;
  const double focal_px = std::max(intrinsics.fx, intrinsics.fy);
  auto solve = [&current](double damping_factor) -> Vector6d {
    Matrix6d damped = current.information;
    damped.diagonal() += damping_factor * current.information.diagonal() +
                         Vector6d::Constant(1e-9 * current.information.trace());
    return damped.ldlt().solve(-current.gradient);
  };
  // The increment of the last trial when it was rejected (zero otherwise).
  Vector6d rejected = Vector6d::Zero();
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    if (current.points_used < 6) break;
    Vector6d increment = solve(damping);
    // After a rejection, raise the damping until the step differs from the rejected one by a
    // meaningful fraction: with the small relative damping of a well-constrained solve, the
    // first few doublings barely change it, and a trial at a nearly identical pose would be
    // rejected again (logged: runs of 4-5 such trials).
    for (int raise = 0; raise < kMaxDampingRaises && !rejected.isZero() &&
                        (increment - rejected).norm() < kMinRetryChange * rejected.norm();
         ++raise) {
      damping *= growth;
      growth *= 2.0;
      increment = solve(damping);
    }
    if (!increment.allFinite()) break;
    ++result.iterations;
    const Rigid3d candidate = ExpSE3(increment) * result.cam_from_world;
    Linearization trial = LinearizeAny(kind, points, intrinsics, candidate, options, &workspace);
    AddPriorCost(prior, candidate, &trial);
    const bool small = increment.head<3>().norm() < options.min_increment &&
                       increment.tail<3>().norm() < options.min_increment;
    // Gain ratio: actual over predicted decrease of the (robust) cost (Nielsen's LM update).
    const double predicted_decrease =
        -(increment.dot(current.gradient) + 0.5 * increment.dot(current.information * increment));
    const double gain =
        predicted_decrease > 0 ? (current.cost - trial.cost) / predicted_decrease : -1;
    // Below this change of cost the field's pixel-level roughness dominates: further trials
    // only trade sub-millimetre moves (measured: without it every solve ran to max_iterations).
    const double negligible = options.min_relative_decrease * current.cost;
    const double mean_inverse_depth = current.sum_inverse_depths / current.points_used;
    bool converged =
        small || (options.min_relative_decrease > 0 &&
                  IncrementMotionPx(increment, focal_px, mean_inverse_depth) < kNegligibleMotionPx);
    if (trial.cost < current.cost) {
      converged |= current.cost - trial.cost < negligible;
      result.cam_from_world = candidate;
      Accumulate(workspace.rows, &trial);
      AddPriorToSystem(prior, candidate, &trial);
      current = trial;
      const double factor = 2 * gain - 1;
      damping *= std::max(1.0 / 3.0, 1.0 - factor * factor * factor);
      damping = std::max(damping, 1e-8);
      growth = 2.0;
      rejected.setZero();
    } else {
      converged |= predicted_decrease < negligible;
      damping *= growth;
      growth *= 2.0;
      rejected = increment;
    }
    if (converged) {
      result.converged = true;
      break;
    }
  }
  result.cost = current.cost;
  result.information = current.information;
  result.points_used = current.points_used;
  result.mean_residual = current.points_used > 0 ? current.sum_residuals / current.points_used : 1;
  result.covariance = Covariance(current, &result.well_conditioned);
  result.residual_variance = ResidualVariance(current);
  if (prior != nullptr) {
    // Conditioned by the points alone: a prior fills in what they do not constrain.
    Linearization points_only = current;
    points_only.information -= prior->information;
    Covariance(points_only, &result.well_conditioned);
  }
  return result;
}

}  // namespace evloc::tracking
