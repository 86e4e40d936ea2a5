// Trajectory accuracy against ground truth: association, alignment, absolute trajectory error
// (ATE), relative pose error (RPE) over a fixed time step, drift over path lengths, coverage and
// the failure time. The definitions are in docs/accuracy.md, "How evloc measures accuracy".
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/geometry/rigid3.h"
#include "core/trajectory/trajectory.h"

namespace evloc {

// How the estimate is aligned to the ground truth before errors are measured.
enum class Alignment {
  // No alignment: a map-based tracker lives in the map (ground-truth) frame.
  kNone,
  // Rigid SE(3) Umeyama alignment of the matched positions.
  kSe3,
  // Similarity Sim(3) Umeyama alignment of the matched positions (scale estimated).
  kSim3,
};

// "none", "se3" or "sim3".
std::string AlignmentName(Alignment alignment);
// Parses "none", "se3" or "sim3"; throws InvalidArgumentError otherwise.
Alignment ParseAlignment(std::string_view name);

// Options of EvaluateTrajectory(); each maps to one evloc-eval flag.
struct EvaluationOptions {
  // Alignment of the estimate to the ground truth (--align).
  Alignment alignment = Alignment::kNone;
  // RPE time step, seconds (--delta).
  double delta_s = 1.0;
  // Association tolerance, seconds: an estimate is matched only when a ground-truth sample lies
  // within this time of it (--max-dt).
  double max_dt_s = 0.02;
  // Translation error, centimetres, above which the estimate counts as failed (--fail-cm).
  double fail_cm = 10.0;
  // Coverage: consecutive estimates at most this far apart, seconds, cover the time between
  // them (--coverage-gap).
  double coverage_max_gap_s = 0.1;
  // Path lengths of the ground truth over which the drift is measured, metres (--segments);
  // none: no drift figures.
  std::vector<double> segment_lengths_m;

  // Throws InvalidArgumentError unless every value is finite and positive.
  void Check() const;
};

// One estimate paired with the ground truth at its time.
struct MatchedPose {
  // Time of the estimate, nanoseconds.
  int64_t t_ns = 0;
  // Ground-truth pose at t_ns (interpolated or nearest sample, see Associate()).
  Rigid3d gt_world_from_cam;
  // Estimated pose at t_ns, in the estimate's own world frame.
  Rigid3d est_world_from_cam;
};

// Pairs every estimate with the ground truth. An estimate is matched when the nearest
// ground-truth sample is within `max_dt_ns`. Its ground truth is then interpolated at the
// estimate's time when ground-truth samples lie on both sides of it no more than 2 * max_dt_ns
// apart, and is the nearest sample otherwise (at the ends of the ground truth, or across a gap).
// Unmatched estimates are left out.
std::vector<MatchedPose> Associate(const Trajectory& ground_truth, const Trajectory& estimate,
                                   int64_t max_dt_ns);

// The transform gt_world_from_est_world that best aligns the matched estimated positions to the
// ground-truth positions (Umeyama); the identity for Alignment::kNone. Throws
// InvalidArgumentError when the positions do not determine it (fewer than 3, or collinear).
Sim3d AlignEstimate(const std::vector<MatchedPose>& matches, Alignment alignment);

// Summary statistics of a set of non-negative errors.
struct ErrorStatistics {
  // Root mean square.
  double rmse = 0.0;
  // Arithmetic mean.
  double mean = 0.0;
  // Median (mean of the two middle values for an even count).
  double median = 0.0;
  // Largest value.
  double max = 0.0;
};

// Statistics of `values`; throws InvalidArgumentError when it is empty.
ErrorStatistics ComputeErrorStatistics(std::vector<double> values);

// Relative pose error of one pose pair (i, j): E = (gt_i^-1 gt_j)^-1 (est_i^-1 est_j).
struct RelativePoseError {
  // Time of pose i, nanoseconds.
  int64_t t_i_ns = 0;
  // Time of pose j, nanoseconds.
  int64_t t_j_ns = 0;
  // |translation(E)|, metres.
  double translation_m = 0.0;
  // Rotation angle of E, radians.
  double rotation_rad = 0.0;
};

// RPE pairs over a fixed time step: for each matched pose i, j is the matched pose whose time is
// closest to t_i + delta; the pair is kept when j > i and |t_j - (t_i + delta)| is at most half
// the median spacing of the matched poses. Estimates are taken as given (align them first).
std::vector<RelativePoseError> ComputeRelativePoseErrors(const std::vector<MatchedPose>& matches,
                                                         int64_t delta_ns);

// Drift over one path length, as odometry benchmarks measure it (KITTI's translational and
// rotational error): from every matched pose i, j is the first matched pose at which the ground
// truth has travelled `length_m` further along its path; the segment's error is the relative
// pose error of (i, j), E = (gt_i^-1 gt_j)^-1 (est_i^-1 est_j), divided by the length.
struct SegmentDrift {
  // Path length of the segments, metres.
  double length_m = 0.0;
  // Segments measured (0: the path is shorter than length_m).
  size_t segments = 0;
  // Mean |translation(E)| / length_m, percent.
  double translation_percent = 0.0;
  // Mean rotation angle of E / length_m, degrees per metre.
  double rotation_deg_per_m = 0.0;
};

// The drift over each of `lengths_m` (in that order). Estimates are taken as given (align them
// first).
std::vector<SegmentDrift> ComputeSegmentDrift(const std::vector<MatchedPose>& matches,
                                              const std::vector<double>& lengths_m);

// Fraction of [gt start, gt end] covered by the estimate: the union of the intervals between
// consecutive estimates at most `max_gap_ns` apart, clipped to the ground-truth span, divided by
// its length. 0 when the ground truth spans no time or there are fewer than 2 estimates.
double ComputeCoverage(const Trajectory& ground_truth, const Trajectory& estimate,
                       int64_t max_gap_ns);

// Everything evloc-eval reports.
struct EvaluationResult {
  // The options used.
  EvaluationOptions options;
  // Number of estimates matched to the ground truth.
  size_t matched_poses = 0;
  // Alignment applied to the estimate: gt_world_from_est_world.
  Sim3d gt_from_est;
  // ATE translation statistics, centimetres.
  ErrorStatistics ate_translation_cm;
  // ATE rotation statistics, degrees.
  ErrorStatistics ate_rotation_deg;
  // RPE translation RMSE divided by delta, cm/s; std::nullopt when no pair spans delta.
  std::optional<double> rpe_translation_rmse_cm_s;
  // RPE rotation RMSE divided by delta, deg/s; std::nullopt when no pair spans delta.
  std::optional<double> rpe_rotation_rmse_deg_s;
  // Number of RPE pose pairs.
  size_t rpe_pairs = 0;
  // Drift over each of options.segment_lengths_m.
  std::vector<SegmentDrift> drift;
  // Coverage in [0, 1], see ComputeCoverage().
  double coverage = 0.0;
  // Seconds from the ground-truth start to the first matched estimate whose translation error
  // exceeds options.fail_cm; std::nullopt when none does.
  std::optional<double> failed_at_s;
  // Per matched pose: seconds from the ground-truth start.
  std::vector<double> error_times_s;
  // Per matched pose: translation error after alignment, centimetres.
  std::vector<double> translation_errors_cm;
};

// Evaluates `estimate` against `ground_truth`. Throws InvalidArgumentError for invalid options,
// an empty ground truth, no matched estimate, or an alignment the matches do not determine.
EvaluationResult EvaluateTrajectory(const Trajectory& ground_truth, const Trajectory& estimate,
                                    const EvaluationOptions& options);

// The JSON report: ate_t_rmse_cm, ate_t_mean_cm, ate_t_median_cm, ate_t_max_cm, ate_r_rmse_deg,
// rpe_t_rmse_cm_s, rpe_r_rmse_deg_s, coverage, failed_at_s, alignment, delta_s, matched_poses,
// drift (one object per segment length: length_m, segments, t_percent, r_deg_per_m; null
// figures when the path is shorter), and, to state the conditions, max_dt_s, fail_cm,
// coverage_max_gap_s and rpe_pairs. Unavailable values are null.
nlohmann::json EvaluationToJson(const EvaluationResult& result);

// A readable table of the same figures, one per line, with units and conditions.
std::string FormatEvaluationTable(const EvaluationResult& result);

}  // namespace evloc
