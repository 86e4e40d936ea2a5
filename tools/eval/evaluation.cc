#include "tools/eval/evaluation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>

#include "core/common/error.h"

namespace evloc {
namespace {

constexpr double kRadiansToDegrees = 180.0 / M_PI;

int64_t SecondsToNanoseconds(double seconds) { return std::llround(seconds * 1e9); }

double RootMeanSquare(const std::vector<double>& values) {
  double sum_of_squares = 0.0;
  for (const double value : values) sum_of_squares += value * value;
  return std::sqrt(sum_of_squares / static_cast<double>(values.size()));
}

// Index of the element of the sorted `times_ns` closest to `t_ns` (the earlier one on a tie).
size_t ClosestIndex(const std::vector<int64_t>& times_ns, int64_t t_ns) {
  const auto after = std::lower_bound(times_ns.begin(), times_ns.end(), t_ns);
  if (after == times_ns.begin()) return 0;
  if (after == times_ns.end()) return times_ns.size() - 1;
  const size_t index = static_cast<size_t>(after - times_ns.begin());
  return (t_ns - times_ns[index - 1] <= times_ns[index] - t_ns) ? index - 1 : index;
}

// The relative pose error of the pair (i, j): E = (gt_i^-1 gt_j)^-1 (est_i^-1 est_j).
Rigid3d RelativeError(const MatchedPose& i, const MatchedPose& j) {
  const Rigid3d gt_relative = i.gt_world_from_cam.Inverse() * j.gt_world_from_cam;
  const Rigid3d est_relative = i.est_world_from_cam.Inverse() * j.est_world_from_cam;
  return gt_relative.Inverse() * est_relative;
}

std::string FormatNumber(double value, int decimals) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*f", decimals, value);
  return buffer;
}

}  // namespace

std::string AlignmentName(Alignment alignment) {
  switch (alignment) {
    case Alignment::kNone:
      return "none";
    case Alignment::kSe3:
      return "se3";
    case Alignment::kSim3:
      return "sim3";
  }
  throw InvalidArgumentError("unknown alignment value");
}

Alignment ParseAlignment(std::string_view name) {
  if (name == "none") return Alignment::kNone;
  if (name == "se3") return Alignment::kSe3;
  if (name == "sim3") return Alignment::kSim3;
  throw InvalidArgumentError("alignment '" + std::string(name) +
                             "' is unknown; use none, se3 or sim3");
}

void EvaluationOptions::Check() const {
  const auto check_positive = [](double value, const char* name) {
    if (!std::isfinite(value) || value <= 0.0) {
      throw InvalidArgumentError(std::string(name) + " must be a positive number, got " +
                                 std::to_string(value));
    }
  };
  check_positive(delta_s, "delta_s (--delta)");
  check_positive(max_dt_s, "max_dt_s (--max-dt)");
  check_positive(fail_cm, "fail_cm (--fail-cm)");
  check_positive(coverage_max_gap_s, "coverage_max_gap_s (--coverage-gap)");
  for (const double length : segment_lengths_m) {
    check_positive(length, "each of segment_lengths_m (--segments)");
  }
}

std::vector<MatchedPose> Associate(const Trajectory& ground_truth, const Trajectory& estimate,
                                   int64_t max_dt_ns) {
  std::vector<MatchedPose> matches;
  const std::vector<TimedPose>& gt = ground_truth.poses();
  if (gt.empty()) return matches;
  for (const TimedPose& est : estimate.poses()) {
    // The samples around the estimate: `before` at or before it, `after` strictly after it.
    const std::optional<size_t> at_or_before = ground_truth.IndexAtOrBefore(est.t_ns);
    const bool has_before = at_or_before.has_value();
    const size_t before = has_before ? *at_or_before : 0;
    const size_t after = has_before ? before + 1 : 0;
    const bool has_after = after < gt.size();
    size_t nearest = has_before ? before : after;
    if (has_before && has_after && gt[after].t_ns - est.t_ns < est.t_ns - gt[before].t_ns) {
      nearest = after;
    }
    const int64_t distance_ns = std::abs(gt[nearest].t_ns - est.t_ns);
    if (distance_ns > max_dt_ns) continue;

    MatchedPose match;
    match.t_ns = est.t_ns;
    match.est_world_from_cam = est.world_from_cam;
    match.gt_world_from_cam = gt[nearest].world_from_cam;
    if (has_before && has_after && gt[before].t_ns != est.t_ns &&
        gt[after].t_ns - gt[before].t_ns <= 2 * max_dt_ns) {
      match.gt_world_from_cam = *ground_truth.Lookup(est.t_ns);
    }
    matches.push_back(match);
  }
  return matches;
}

Sim3d AlignEstimate(const std::vector<MatchedPose>& matches, Alignment alignment) {
  if (alignment == Alignment::kNone) return Sim3d();
  Eigen::Matrix3Xd est_positions(3, matches.size());
  Eigen::Matrix3Xd gt_positions(3, matches.size());
  for (size_t i = 0; i < matches.size(); ++i) {
    est_positions.col(i) = matches[i].est_world_from_cam.translation;
    gt_positions.col(i) = matches[i].gt_world_from_cam.translation;
  }
  return AlignUmeyama(est_positions, gt_positions, alignment == Alignment::kSim3);
}

ErrorStatistics ComputeErrorStatistics(std::vector<double> values) {
  if (values.empty()) throw InvalidArgumentError("error statistics of an empty set");
  ErrorStatistics statistics;
  statistics.rmse = RootMeanSquare(values);
  statistics.mean =
      std::accumulate(values.begin(), values.end(), 0.0) / static_cast<double>(values.size());
  statistics.max = *std::max_element(values.begin(), values.end());
  std::sort(values.begin(), values.end());
  const size_t middle = values.size() / 2;
  statistics.median =
      values.size() % 2 == 1 ? values[middle] : 0.5 * (values[middle - 1] + values[middle]);
  return statistics;
}

std::vector<RelativePoseError> ComputeRelativePoseErrors(const std::vector<MatchedPose>& matches,
                                                         int64_t delta_ns) {
  std::vector<RelativePoseError> errors;
  if (matches.size() < 2) return errors;
  std::vector<int64_t> times_ns;
  times_ns.reserve(matches.size());
  for (const MatchedPose& match : matches) times_ns.push_back(match.t_ns);
  // Pairs may span delta +- half the median spacing, so that with regular sampling the pose
  // nearest to t_i + delta is accepted and no pair is formed past the end of the estimate.
  std::vector<int64_t> spacings_ns;
  for (size_t i = 1; i < times_ns.size(); ++i) spacings_ns.push_back(times_ns[i] - times_ns[i - 1]);
  std::nth_element(spacings_ns.begin(), spacings_ns.begin() + spacings_ns.size() / 2,
                   spacings_ns.end());
  const int64_t tolerance_ns = spacings_ns[spacings_ns.size() / 2] / 2;

  for (size_t i = 0; i < matches.size(); ++i) {
    const int64_t target_ns = times_ns[i] + delta_ns;
    const size_t j = ClosestIndex(times_ns, target_ns);
    if (j <= i || std::abs(times_ns[j] - target_ns) > tolerance_ns) continue;
    const Rigid3d error = RelativeError(matches[i], matches[j]);
    RelativePoseError pair;
    pair.t_i_ns = times_ns[i];
    pair.t_j_ns = times_ns[j];
    pair.translation_m = error.translation.norm();
    pair.rotation_rad = LogSO3(error.rotation).norm();
    errors.push_back(pair);
  }
  return errors;
}

std::vector<SegmentDrift> ComputeSegmentDrift(const std::vector<MatchedPose>& matches,
                                              const std::vector<double>& lengths_m) {
  // Distance travelled along the ground truth up to each matched pose.
  std::vector<double> travelled_m(matches.size(), 0.0);
  for (size_t k = 1; k < matches.size(); ++k) {
    travelled_m[k] = travelled_m[k - 1] + (matches[k].gt_world_from_cam.translation -
                                           matches[k - 1].gt_world_from_cam.translation)
                                              .norm();
  }
  std::vector<SegmentDrift> drift;
  for (const double length_m : lengths_m) {
    SegmentDrift figures;
    figures.length_m = length_m;
    double translation_sum = 0.0;
    double rotation_sum = 0.0;
    for (size_t i = 0; i < matches.size(); ++i) {
      const auto end = std::lower_bound(travelled_m.begin() + static_cast<std::ptrdiff_t>(i),
                                        travelled_m.end(), travelled_m[i] + length_m);
      if (end == travelled_m.end()) break;
      const size_t j = static_cast<size_t>(end - travelled_m.begin());
      const Rigid3d error = RelativeError(matches[i], matches[j]);
      translation_sum += error.translation.norm() / length_m;
      rotation_sum += LogSO3(error.rotation).norm() / length_m;
      ++figures.segments;
    }
    if (figures.segments > 0) {
      const double count = static_cast<double>(figures.segments);
      figures.translation_percent = 100.0 * translation_sum / count;
      figures.rotation_deg_per_m = kRadiansToDegrees * rotation_sum / count;
    }
    drift.push_back(figures);
  }
  return drift;
}

double ComputeCoverage(const Trajectory& ground_truth, const Trajectory& estimate,
                       int64_t max_gap_ns) {
  if (ground_truth.empty() || ground_truth.duration_ns() == 0) return 0.0;
  const int64_t span_start = ground_truth.start_ns();
  const int64_t span_end = ground_truth.end_ns();
  const std::vector<TimedPose>& poses = estimate.poses();
  int64_t covered_ns = 0;
  for (size_t k = 1; k < poses.size(); ++k) {
    if (poses[k].t_ns - poses[k - 1].t_ns > max_gap_ns) continue;
    const int64_t begin = std::max(poses[k - 1].t_ns, span_start);
    const int64_t end = std::min(poses[k].t_ns, span_end);
    if (end > begin) covered_ns += end - begin;
  }
  return static_cast<double>(covered_ns) / static_cast<double>(span_end - span_start);
}

EvaluationResult EvaluateTrajectory(const Trajectory& ground_truth, const Trajectory& estimate,
                                    const EvaluationOptions& options) {
  options.Check();
  if (ground_truth.empty()) throw InvalidArgumentError("the ground-truth trajectory is empty");
  const int64_t max_dt_ns = SecondsToNanoseconds(options.max_dt_s);
  std::vector<MatchedPose> matches = Associate(ground_truth, estimate, max_dt_ns);
  if (matches.empty()) {
    throw InvalidArgumentError(
        "no estimated pose lies within " + FormatNumber(options.max_dt_s, 3) +
        " s (--max-dt) of a ground-truth pose; check that both files use the same clock");
  }

  EvaluationResult result;
  result.options = options;
  result.matched_poses = matches.size();
  result.gt_from_est = AlignEstimate(matches, options.alignment);
  for (MatchedPose& match : matches) {
    match.est_world_from_cam = result.gt_from_est.TransformPose(match.est_world_from_cam);
  }

  std::vector<double> rotation_errors_deg;
  for (const MatchedPose& match : matches) {
    const double translation_error_cm =
        100.0 * (match.est_world_from_cam.translation - match.gt_world_from_cam.translation).norm();
    const double time_s = static_cast<double>(match.t_ns - ground_truth.start_ns()) * 1e-9;
    result.error_times_s.push_back(time_s);
    result.translation_errors_cm.push_back(translation_error_cm);
    rotation_errors_deg.push_back(
        kRadiansToDegrees *
        AngleBetween(match.gt_world_from_cam.rotation, match.est_world_from_cam.rotation));
    if (!result.failed_at_s && translation_error_cm > options.fail_cm) result.failed_at_s = time_s;
  }
  result.ate_translation_cm = ComputeErrorStatistics(result.translation_errors_cm);
  result.ate_rotation_deg = ComputeErrorStatistics(rotation_errors_deg);

  const std::vector<RelativePoseError> relative_errors =
      ComputeRelativePoseErrors(matches, SecondsToNanoseconds(options.delta_s));
  result.rpe_pairs = relative_errors.size();
  if (!relative_errors.empty()) {
    std::vector<double> translations_m;
    std::vector<double> rotations_rad;
    for (const RelativePoseError& pair : relative_errors) {
      translations_m.push_back(pair.translation_m);
      rotations_rad.push_back(pair.rotation_rad);
    }
    result.rpe_translation_rmse_cm_s = 100.0 * RootMeanSquare(translations_m) / options.delta_s;
    result.rpe_rotation_rmse_deg_s =
        kRadiansToDegrees * RootMeanSquare(rotations_rad) / options.delta_s;
  }
  result.drift = ComputeSegmentDrift(matches, options.segment_lengths_m);
  result.coverage =
      ComputeCoverage(ground_truth, estimate, SecondsToNanoseconds(options.coverage_max_gap_s));
  return result;
}

nlohmann::json EvaluationToJson(const EvaluationResult& result) {
  const auto optional_number = [](const std::optional<double>& value) {
    return value ? nlohmann::json(*value) : nlohmann::json(nullptr);
  };
  nlohmann::json json;
  json["ate_t_rmse_cm"] = result.ate_translation_cm.rmse;
  json["ate_t_mean_cm"] = result.ate_translation_cm.mean;
  json["ate_t_median_cm"] = result.ate_translation_cm.median;
  json["ate_t_max_cm"] = result.ate_translation_cm.max;
  json["ate_r_rmse_deg"] = result.ate_rotation_deg.rmse;
  json["rpe_t_rmse_cm_s"] = optional_number(result.rpe_translation_rmse_cm_s);
  json["rpe_r_rmse_deg_s"] = optional_number(result.rpe_rotation_rmse_deg_s);
  json["coverage"] = result.coverage;
  json["failed_at_s"] = optional_number(result.failed_at_s);
  json["alignment"] = AlignmentName(result.options.alignment);
  json["delta_s"] = result.options.delta_s;
  json["matched_poses"] = result.matched_poses;
  json["max_dt_s"] = result.options.max_dt_s;
  json["fail_cm"] = result.options.fail_cm;
  json["coverage_max_gap_s"] = result.options.coverage_max_gap_s;
  json["rpe_pairs"] = result.rpe_pairs;
  json["drift"] = nlohmann::json::array();
  for (const SegmentDrift& figures : result.drift) {
    const bool measured = figures.segments > 0;
    json["drift"].push_back(
        {{"length_m", figures.length_m},
         {"segments", figures.segments},
         {"t_percent", measured ? nlohmann::json(figures.translation_percent) : nullptr},
         {"r_deg_per_m", measured ? nlohmann::json(figures.rotation_deg_per_m) : nullptr}});
  }
  return json;
}

std::string FormatEvaluationTable(const EvaluationResult& result) {
  const EvaluationOptions& options = result.options;
  const auto optional_text = [](const std::optional<double>& value, const std::string& unit,
                                const std::string& absent) {
    return value ? FormatNumber(*value, 3) + " " + unit : absent;
  };
  std::string table;
  const auto row = [&table](const std::string& name, const std::string& value) {
    table += name;
    table.append(name.size() < 26 ? 26 - name.size() : 1, ' ');
    table += value + "\n";
  };
  row("alignment", AlignmentName(options.alignment));
  row("association tolerance", FormatNumber(options.max_dt_s, 3) + " s");
  row("matched poses", std::to_string(result.matched_poses));
  row("ATE translation RMSE", FormatNumber(result.ate_translation_cm.rmse, 3) + " cm");
  row("ATE translation mean", FormatNumber(result.ate_translation_cm.mean, 3) + " cm");
  row("ATE translation median", FormatNumber(result.ate_translation_cm.median, 3) + " cm");
  row("ATE translation max", FormatNumber(result.ate_translation_cm.max, 3) + " cm");
  row("ATE rotation RMSE", FormatNumber(result.ate_rotation_deg.rmse, 3) + " deg");
  row("RPE delta",
      FormatNumber(options.delta_s, 3) + " s (" + std::to_string(result.rpe_pairs) + " pairs)");
  row("RPE translation RMSE",
      optional_text(result.rpe_translation_rmse_cm_s, "cm/s", "n/a (no pair spans delta)"));
  row("RPE rotation RMSE",
      optional_text(result.rpe_rotation_rmse_deg_s, "deg/s", "n/a (no pair spans delta)"));
  for (const SegmentDrift& figures : result.drift) {
    row("drift over " + FormatNumber(figures.length_m, 2) + " m",
        figures.segments > 0 ? FormatNumber(figures.translation_percent, 3) + " %, " +
                                   FormatNumber(figures.rotation_deg_per_m, 3) + " deg/m (" +
                                   std::to_string(figures.segments) + " segments)"
                             : "n/a (the path is shorter)");
  }
  row("coverage", FormatNumber(100.0 * result.coverage, 1) + " % (gaps over " +
                      FormatNumber(options.coverage_max_gap_s, 3) + " s uncovered)");
  row("failed at", optional_text(result.failed_at_s, "s", "never") + " (error over " +
                       FormatNumber(options.fail_cm, 1) + " cm)");
  return table;
}

}  // namespace evloc
