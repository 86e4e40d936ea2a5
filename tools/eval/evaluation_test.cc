#include "tools/eval/evaluation.h"

#include <cmath>
#include <functional>
#include <random>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/trajectory/tum_io.h"

namespace evloc {
namespace {

constexpr int64_t kSecond = 1'000'000'000;
constexpr double kDegree = M_PI / 180.0;

// Samples `pose_at(seconds)` at `rate_hz` over [0, duration_s] (inclusive).
Trajectory Sample(const std::function<Rigid3d(double)>& pose_at, double duration_s, double rate_hz,
                  int64_t start_ns = 0) {
  Trajectory trajectory;
  const int count = static_cast<int>(std::lround(duration_s * rate_hz));
  for (int k = 0; k <= count; ++k) {
    const int64_t t_ns = start_ns + std::llround(k * 1e9 / rate_hz);
    trajectory.Append({t_ns, pose_at(static_cast<double>(t_ns - start_ns) * 1e-9)});
  }
  return trajectory;
}

Eigen::Quaterniond AboutZ(double angle_rad) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle_rad, Eigen::Vector3d::UnitZ()));
}

// A straight line along x at 1 m/s, constant orientation.
Rigid3d StraightLine(double t_s) {
  return Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(t_s, 0.0, 0.0));
}

// A non-planar curve with turning orientation (determines SE(3) and Sim(3) alignments).
Rigid3d Helix(double t_s) {
  return Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * t_s, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Vector3d(std::cos(0.5 * t_s), 0.8 * std::sin(0.5 * t_s), 0.1 * t_s));
}

TEST(ErrorStatistics, RmseMeanMedianMax) {
  const ErrorStatistics statistics = ComputeErrorStatistics({3, 1, 2, 4});
  EXPECT_DOUBLE_EQ(statistics.rmse, std::sqrt(7.5));
  EXPECT_DOUBLE_EQ(statistics.mean, 2.5);
  EXPECT_DOUBLE_EQ(statistics.median, 2.5);
  EXPECT_DOUBLE_EQ(statistics.max, 4.0);
  EXPECT_DOUBLE_EQ(ComputeErrorStatistics({5, 1, 2}).median, 2.0);
  EXPECT_THROW(ComputeErrorStatistics({}), InvalidArgumentError);
}

TEST(EvaluationOptions, CheckRejectsNonPositiveValues) {
  EvaluationOptions options;
  EXPECT_NO_THROW(options.Check());
  options.delta_s = 0.0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = EvaluationOptions();
  options.max_dt_s = -1.0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = EvaluationOptions();
  options.fail_cm = std::nan("");
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  EXPECT_EQ(ParseAlignment("sim3"), Alignment::kSim3);
  EXPECT_THROW(ParseAlignment("SE3x"), InvalidArgumentError);
}

TEST(EvaluateTrajectory, ConstantOffsetGivesAteEqualToOffsetAndZeroRpe) {
  const Trajectory ground_truth = Sample(StraightLine, 5.0, 100.0);
  const Eigen::Vector3d offset(0.03, 0.04, 0.0);  // 5 cm.
  const Trajectory estimate = Sample(
      [&](double t) {
        return Rigid3d(Eigen::Quaterniond::Identity(), StraightLine(t).translation + offset);
      },
      5.0, 100.0);
  const EvaluationResult result = EvaluateTrajectory(ground_truth, estimate, EvaluationOptions());
  EXPECT_EQ(result.matched_poses, 501u);
  EXPECT_NEAR(result.ate_translation_cm.rmse, 5.0, 1e-9);
  EXPECT_NEAR(result.ate_translation_cm.mean, 5.0, 1e-9);
  EXPECT_NEAR(result.ate_translation_cm.median, 5.0, 1e-9);
  EXPECT_NEAR(result.ate_translation_cm.max, 5.0, 1e-9);
  EXPECT_NEAR(result.ate_rotation_deg.rmse, 0.0, 1e-9);
  // Pairs i with t_i + 1 s inside [0, 5]: 401 of them (the end is not overshot).
  EXPECT_EQ(result.rpe_pairs, 401u);
  ASSERT_TRUE(result.rpe_translation_rmse_cm_s.has_value());
  EXPECT_NEAR(*result.rpe_translation_rmse_cm_s, 0.0, 1e-9);
  EXPECT_NEAR(*result.rpe_rotation_rmse_deg_s, 0.0, 1e-9);
  EXPECT_NEAR(result.coverage, 1.0, 1e-12);
  EXPECT_FALSE(result.failed_at_s.has_value());
}

TEST(EvaluateTrajectory, DriftOverPathLengths) {
  const Trajectory ground_truth = Sample(StraightLine, 5.0, 100.0);
  EvaluationOptions options;
  options.segment_lengths_m = {1.0, 2.0, 10.0};
  // A scale error of 1 %: every segment's translation is 1 % too long.
  const Trajectory scaled = Sample(
      [](double t) {
        return Rigid3d(Eigen::Quaterniond::Identity(), 1.01 * StraightLine(t).translation);
      },
      5.0, 100.0);
  const EvaluationResult result = EvaluateTrajectory(ground_truth, scaled, options);
  ASSERT_EQ(result.drift.size(), 3u);
  EXPECT_DOUBLE_EQ(result.drift[0].length_m, 1.0);
  // Segments start at every pose from which the path goes on 1 m (t <= 4 s): 401 of 501.
  EXPECT_NEAR(static_cast<double>(result.drift[0].segments), 401.0, 1.0);
  EXPECT_NEAR(result.drift[0].translation_percent, 1.0, 0.02);
  EXPECT_NEAR(result.drift[0].rotation_deg_per_m, 0.0, 1e-9);
  EXPECT_NEAR(static_cast<double>(result.drift[1].segments), 301.0, 1.0);
  EXPECT_NEAR(result.drift[1].translation_percent, 1.0, 0.02);
  // The path is 5 m long: no 10 m segment.
  EXPECT_EQ(result.drift[2].segments, 0u);
  const nlohmann::json json = EvaluationToJson(result);
  ASSERT_EQ(json["drift"].size(), 3u);
  EXPECT_NEAR(json["drift"][0]["t_percent"].get<double>(), 1.0, 0.02);
  EXPECT_TRUE(json["drift"][2]["t_percent"].is_null());
  const std::string table = FormatEvaluationTable(result);
  EXPECT_NE(table.find("drift over 1.00 m"), std::string::npos) << table;
  EXPECT_NE(table.find("n/a (the path is shorter)"), std::string::npos) << table;

  // A constant offset drifts nothing; a heading that turns by 2 degrees per second (per metre
  // at 1 m/s) drifts 2 deg/m.
  const Trajectory offset = Sample(
      [](double t) {
        return Rigid3d(Eigen::Quaterniond::Identity(),
                       StraightLine(t).translation + Eigen::Vector3d(0.05, 0.0, 0.0));
      },
      5.0, 100.0);
  EXPECT_NEAR(EvaluateTrajectory(ground_truth, offset, options).drift[0].translation_percent, 0.0,
              1e-9);
  const Trajectory turning = Sample(
      [](double t) { return Rigid3d(AboutZ(2.0 * kDegree * t), StraightLine(t).translation); }, 5.0,
      100.0);
  EXPECT_NEAR(EvaluateTrajectory(ground_truth, turning, options).drift[1].rotation_deg_per_m, 2.0,
              0.03);
  // No lengths: no drift figures.
  EXPECT_TRUE(EvaluateTrajectory(ground_truth, scaled, EvaluationOptions()).drift.empty());
  options.segment_lengths_m = {1.0, 0.0};
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

TEST(EvaluateTrajectory, KnownRotationOffset) {
  // The estimate is rotated by 2 degrees about the camera z axis; positions are exact.
  const Trajectory ground_truth = Sample(StraightLine, 5.0, 100.0);
  const Trajectory estimate =
      Sample([](double t) { return Rigid3d(AboutZ(2.0 * kDegree), StraightLine(t).translation); },
             5.0, 100.0);
  const EvaluationResult result = EvaluateTrajectory(ground_truth, estimate, EvaluationOptions());
  EXPECT_NEAR(result.ate_translation_cm.max, 0.0, 1e-9);
  EXPECT_NEAR(result.ate_rotation_deg.rmse, 2.0, 1e-9);
  // E = A^-1 D^-1 A D with A a 1 m move along x and D the 2 degree rotation: E translates by
  // R_D^T a - a, of length 2 sin(1 deg) * 1 m; E does not rotate.
  ASSERT_TRUE(result.rpe_translation_rmse_cm_s.has_value());
  EXPECT_NEAR(*result.rpe_translation_rmse_cm_s, 100.0 * 2.0 * std::sin(1.0 * kDegree), 1e-9);
  EXPECT_NEAR(*result.rpe_rotation_rmse_deg_s, 0.0, 1e-9);
}

TEST(EvaluateTrajectory, LinearDriftGivesRpeEqualToDriftRateAndFailureTime) {
  const double drift_m_per_s = 0.02;
  const Trajectory ground_truth = Sample(StraightLine, 5.0, 100.0);
  const Trajectory estimate = Sample(
      [&](double t) {
        return Rigid3d(Eigen::Quaterniond::Identity(),
                       StraightLine(t).translation + Eigen::Vector3d(0, drift_m_per_s * t, 0));
      },
      5.0, 100.0);
  EvaluationOptions options;
  options.fail_cm = 5.0;
  const EvaluationResult result = EvaluateTrajectory(ground_truth, estimate, options);
  ASSERT_TRUE(result.rpe_translation_rmse_cm_s.has_value());
  EXPECT_NEAR(*result.rpe_translation_rmse_cm_s, 2.0, 1e-9);
  EXPECT_NEAR(result.ate_translation_cm.max, 10.0, 1e-9);
  EXPECT_NEAR(result.ate_translation_cm.mean, 5.0, 1e-9);
  // sqrt(mean((2 t)^2)) over t = 0, 0.01, ..., 5.
  double sum_of_squares = 0.0;
  for (int k = 0; k <= 500; ++k) sum_of_squares += std::pow(2.0 * k * 0.01, 2);
  EXPECT_NEAR(result.ate_translation_cm.rmse, std::sqrt(sum_of_squares / 501.0), 1e-9);
  // 2 cm/s exceeds 5 cm just after 2.5 s.
  ASSERT_TRUE(result.failed_at_s.has_value());
  EXPECT_GE(*result.failed_at_s, 2.5 - 1e-9);
  EXPECT_LE(*result.failed_at_s, 2.51 + 1e-9);
  // Longer delta: still the drift rate.
  options.delta_s = 2.0;
  EXPECT_NEAR(*EvaluateTrajectory(ground_truth, estimate, options).rpe_translation_rmse_cm_s, 2.0,
              1e-9);
}

TEST(EvaluateTrajectory, RotationDriftGivesRpeEqualToRate) {
  const double rate_deg_per_s = 0.7;
  const Trajectory ground_truth = Sample(
      [](double) {
        return Rigid3d(Eigen::Quaterniond::Identity(), {1, 2, 3});
      },
      4.0, 50.0);
  const Trajectory estimate = Sample(
      [&](double t) {
        return Rigid3d(AboutZ(rate_deg_per_s * kDegree * t), {1, 2, 3});
      },
      4.0, 50.0);
  const EvaluationResult result = EvaluateTrajectory(ground_truth, estimate, EvaluationOptions());
  EXPECT_NEAR(*result.rpe_rotation_rmse_deg_s, rate_deg_per_s, 1e-9);
  EXPECT_NEAR(*result.rpe_translation_rmse_cm_s, 0.0, 1e-9);
}

TEST(EvaluateTrajectory, Se3AlignmentRecoversKnownTransform) {
  const Trajectory ground_truth = Sample(Helix, 10.0, 50.0);
  Sim3d est_from_gt;
  est_from_gt.rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.8, Eigen::Vector3d(0.2, -1, 0.5).normalized()));
  est_from_gt.translation = Eigen::Vector3d(2.0, -1.0, 0.5);
  const Trajectory estimate =
      Sample([&](double t) { return est_from_gt.TransformPose(Helix(t)); }, 10.0, 50.0);

  EvaluationOptions options;
  const EvaluationResult unaligned = EvaluateTrajectory(ground_truth, estimate, options);
  EXPECT_GT(unaligned.ate_translation_cm.rmse, 100.0);

  options.alignment = Alignment::kSe3;
  const EvaluationResult aligned = EvaluateTrajectory(ground_truth, estimate, options);
  EXPECT_LT(aligned.ate_translation_cm.max, 1e-6);
  EXPECT_LT(aligned.ate_rotation_deg.rmse, 1e-6);
  EXPECT_NEAR(aligned.gt_from_est.scale, 1.0, 1e-12);
  const Sim3d expected = est_from_gt.Inverse();
  EXPECT_LT(AngleBetween(aligned.gt_from_est.rotation, expected.rotation), 1e-9);
  EXPECT_LT((aligned.gt_from_est.translation - expected.translation).norm(), 1e-9);
}

TEST(EvaluateTrajectory, Sim3AlignmentRecoversScale) {
  const Trajectory ground_truth = Sample(Helix, 10.0, 50.0);
  Sim3d est_from_gt;
  est_from_gt.scale = 1.7;
  est_from_gt.rotation = AboutZ(0.4);
  est_from_gt.translation = Eigen::Vector3d(-0.5, 0.3, 1.0);
  const Trajectory estimate =
      Sample([&](double t) { return est_from_gt.TransformPose(Helix(t)); }, 10.0, 50.0);

  EvaluationOptions options;
  options.alignment = Alignment::kSe3;
  EXPECT_GT(EvaluateTrajectory(ground_truth, estimate, options).ate_translation_cm.rmse, 10.0);
  options.alignment = Alignment::kSim3;
  const EvaluationResult aligned = EvaluateTrajectory(ground_truth, estimate, options);
  EXPECT_LT(aligned.ate_translation_cm.max, 1e-6);
  EXPECT_LT(aligned.ate_rotation_deg.rmse, 1e-6);
  EXPECT_NEAR(aligned.gt_from_est.scale, 1.0 / 1.7, 1e-9);
  // The scale applies to relative motion too: the RPE vanishes after Sim(3) alignment.
  EXPECT_LT(*aligned.rpe_translation_rmse_cm_s, 1e-6);
}

TEST(Associate, InterpolatesGroundTruthAtJitteredTimes) {
  // Ground truth at 100 Hz; motion linear in translation and rotating at a constant rate about
  // a fixed axis, which the interpolation reproduces exactly.
  const auto motion = [](double t) { return Rigid3d(AboutZ(0.5 * t), {t, -0.5 * t, 0.2}); };
  const Trajectory ground_truth = Sample(motion, 3.0, 100.0, 5 * kSecond);
  std::mt19937 generator(42);
  std::uniform_int_distribution<int64_t> jitter_ns(-4'000'000, 4'000'000);
  Trajectory estimate;
  for (size_t k = 0; k + 1 < ground_truth.size(); k += 3) {
    const int64_t t_ns = ground_truth.poses()[k].t_ns + 5'000'000 + jitter_ns(generator);
    estimate.Append({t_ns, motion(static_cast<double>(t_ns - 5 * kSecond) * 1e-9)});
  }
  const size_t inside = estimate.size();
  // Outside the ground truth: 15 ms after its end (matched to the last sample) and 50 ms after
  // (beyond the 20 ms tolerance).
  const int64_t end_ns = ground_truth.end_ns();
  estimate.Append({end_ns + 15'000'000, motion(3.015)});
  estimate.Append({end_ns + 50'000'000, motion(3.05)});

  const std::vector<MatchedPose> matches = Associate(ground_truth, estimate, 20'000'000);
  ASSERT_EQ(matches.size(), inside + 1);
  for (size_t k = 0; k < inside; ++k) {
    EXPECT_LT((matches[k].gt_world_from_cam.translation - matches[k].est_world_from_cam.translation)
                  .norm(),
              1e-12);
    EXPECT_LT(
        AngleBetween(matches[k].gt_world_from_cam.rotation, matches[k].est_world_from_cam.rotation),
        1e-9);
  }
  // The pose past the end is compared with the last sample, 1.5 cm behind along x at 1 m/s.
  EXPECT_NEAR((matches.back().gt_world_from_cam.translation - motion(3.0).translation).norm(), 0.0,
              1e-12);

  const EvaluationResult result = EvaluateTrajectory(ground_truth, estimate, EvaluationOptions());
  EXPECT_EQ(result.matched_poses, inside + 1);
  EXPECT_NEAR(result.ate_translation_cm.max,
              100.0 * (motion(3.015).translation - motion(3.0).translation).norm(), 1e-6);
  EXPECT_LT(result.ate_translation_cm.median, 1e-9);
}

TEST(Associate, NearestSampleAcrossGroundTruthGap) {
  // Ground truth with a 1 s hole: an estimate in the hole within tolerance of a sample gets that
  // sample, not an interpolation across the hole.
  Trajectory ground_truth;
  ground_truth.Append({0, Rigid3d(Eigen::Quaterniond::Identity(), {0, 0, 0})});
  ground_truth.Append({kSecond, Rigid3d(Eigen::Quaterniond::Identity(), {1, 0, 0})});
  Trajectory estimate;
  estimate.Append({10'000'000, Rigid3d()});
  estimate.Append({500'000'000, Rigid3d()});
  const std::vector<MatchedPose> matches = Associate(ground_truth, estimate, 20'000'000);
  ASSERT_EQ(matches.size(), 1u);
  EXPECT_EQ(matches[0].gt_world_from_cam.translation, Eigen::Vector3d::Zero());
}

TEST(ComputeCoverage, CountsIntervalsBetweenCloseEstimatesWithinGroundTruthSpan) {
  const Trajectory ground_truth = Sample(StraightLine, 10.0, 10.0);
  Trajectory estimate;
  for (int k = 0; k <= 400; ++k) estimate.Append({k * 10'000'000LL, Rigid3d()});
  for (int k = 600; k <= 1000; ++k) estimate.Append({k * 10'000'000LL, Rigid3d()});
  EXPECT_NEAR(ComputeCoverage(ground_truth, estimate, kSecond / 10), 0.8, 1e-12);
  // A gap tolerance above 2 s bridges the hole.
  EXPECT_NEAR(ComputeCoverage(ground_truth, estimate, 3 * kSecond), 1.0, 1e-12);

  Trajectory early;  // From -1 s to 5 s: only [0, 5] counts.
  for (int k = -100; k <= 500; ++k) early.Append({k * 10'000'000LL, Rigid3d()});
  EXPECT_NEAR(ComputeCoverage(ground_truth, early, kSecond / 10), 0.5, 1e-12);
  EXPECT_EQ(ComputeCoverage(ground_truth, Trajectory({{0, Rigid3d()}}), kSecond), 0.0);
}

TEST(EvaluateTrajectory, ThrowsWhenNothingMatches) {
  const Trajectory ground_truth = Sample(StraightLine, 1.0, 100.0);
  const Trajectory estimate = Sample(StraightLine, 1.0, 100.0, 100 * kSecond);
  EXPECT_THROW(EvaluateTrajectory(ground_truth, estimate, EvaluationOptions()),
               InvalidArgumentError);
}

TEST(EvaluationToJson, HasTheDocumentedKeysAndNullWhenNeverFailed) {
  const Trajectory ground_truth = Sample(StraightLine, 0.5, 100.0);
  const EvaluationResult result =
      EvaluateTrajectory(ground_truth, ground_truth, EvaluationOptions());
  const nlohmann::json json = EvaluationToJson(result);
  for (const char* key : {"ate_t_rmse_cm", "ate_t_mean_cm", "ate_t_median_cm", "ate_t_max_cm",
                          "ate_r_rmse_deg", "rpe_t_rmse_cm_s", "rpe_r_rmse_deg_s", "coverage",
                          "failed_at_s", "alignment", "delta_s", "matched_poses"}) {
    EXPECT_TRUE(json.contains(key)) << key;
  }
  EXPECT_TRUE(json["failed_at_s"].is_null());
  // 0.5 s of data cannot span a 1 s delta.
  EXPECT_TRUE(json["rpe_t_rmse_cm_s"].is_null());
  EXPECT_EQ(json["alignment"], "none");
  EXPECT_EQ(json["matched_poses"], 51);
  EXPECT_NE(FormatEvaluationTable(result).find("ATE translation RMSE"), std::string::npos);
}

// The real TUM fr1_xyz trajectory against a copy with a known perturbation: a constant world
// offset and a rotation drift about the camera z axis. Expected values are computed here from
// the definitions with 4x4 matrices, independently of the library.
TEST(EvaluateTrajectory, AgreesWithTumDefinitionsOnRealTrajectory) {
  EVLOC_REQUIRE_SHARED_DATA(path, "tum-trajectories/fr1_xyz_groundtruth.txt");
  const Trajectory ground_truth = ReadTumTrajectory(path);
  const Eigen::Vector3d offset(0.02, -0.01, 0.03);
  const double drift_rad_per_s = 0.5 * kDegree;
  Trajectory estimate;
  std::vector<Eigen::Matrix4d> gt_matrices;
  std::vector<Eigen::Matrix4d> est_matrices;
  std::vector<double> times_s;
  for (const TimedPose& pose : ground_truth.poses()) {
    const double tau = static_cast<double>(pose.t_ns - ground_truth.start_ns()) * 1e-9;
    const Rigid3d perturbed(pose.world_from_cam.rotation * AboutZ(drift_rad_per_s * tau),
                            pose.world_from_cam.translation + offset);
    estimate.Append({pose.t_ns, perturbed});
    gt_matrices.push_back(pose.world_from_cam.ToMatrix4());
    est_matrices.push_back(perturbed.ToMatrix4());
    times_s.push_back(tau);
  }
  const EvaluationResult result = EvaluateTrajectory(ground_truth, estimate, EvaluationOptions());
  const size_t count = ground_truth.size();
  EXPECT_EQ(result.matched_poses, count);

  // ATE: every translation error is |offset|; the rotation error of pose i is drift * tau_i.
  EXPECT_NEAR(result.ate_translation_cm.rmse, 100.0 * offset.norm(), 1e-9);
  EXPECT_NEAR(result.ate_translation_cm.max, 100.0 * offset.norm(), 1e-9);
  double sum_of_squared_angles = 0.0;
  for (const double tau : times_s) sum_of_squared_angles += std::pow(drift_rad_per_s * tau, 2);
  EXPECT_NEAR(result.ate_rotation_deg.rmse, std::sqrt(sum_of_squared_angles / count) / kDegree,
              1e-6);

  // RPE, Sturm et al. 2012: E_i = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j), j the pose closest to t_i + 1 s,
  // accepted within half the median sampling interval.
  std::vector<int64_t> times_ns;
  for (const TimedPose& pose : ground_truth.poses()) times_ns.push_back(pose.t_ns);
  std::vector<int64_t> intervals_ns;
  for (size_t i = 1; i < count; ++i) intervals_ns.push_back(times_ns[i] - times_ns[i - 1]);
  std::sort(intervals_ns.begin(), intervals_ns.end());
  const int64_t tolerance_ns = intervals_ns[intervals_ns.size() / 2] / 2;
  EXPECT_NEAR(static_cast<double>(tolerance_ns), 5e6, 1e5);
  double translation_squares = 0.0;
  double rotation_squares = 0.0;
  size_t pairs = 0;
  for (size_t i = 0; i < count; ++i) {
    const int64_t target_ns = times_ns[i] + kSecond;
    size_t best = i;
    for (size_t j = i; j < count && times_ns[j] < target_ns + kSecond; ++j) {
      if (std::abs(times_ns[j] - target_ns) < std::abs(times_ns[best] - target_ns)) best = j;
    }
    if (best == i || std::abs(times_ns[best] - target_ns) > tolerance_ns) continue;
    const Eigen::Matrix4d error = (gt_matrices[i].inverse() * gt_matrices[best]).inverse() *
                                  (est_matrices[i].inverse() * est_matrices[best]);
    translation_squares += error.block<3, 1>(0, 3).squaredNorm();
    const double cosine = std::clamp((error.block<3, 3>(0, 0).trace() - 1.0) / 2.0, -1.0, 1.0);
    rotation_squares += std::pow(std::acos(cosine), 2);
    ++pairs;
  }
  ASSERT_GT(pairs, 2500u);
  EXPECT_EQ(result.rpe_pairs, pairs);
  EXPECT_NEAR(*result.rpe_translation_rmse_cm_s, 100.0 * std::sqrt(translation_squares / pairs),
              1e-6);
  EXPECT_NEAR(*result.rpe_rotation_rmse_deg_s, std::sqrt(rotation_squares / pairs) / kDegree, 1e-4);
  // The constant offset cancels in relative motion; only the drift remains.
  EXPECT_GT(*result.rpe_rotation_rmse_deg_s, 0.1);

  // Coverage: the estimate has the ground-truth times, so only sampling gaps over 0.1 s count.
  int64_t covered_ns = 0;
  for (size_t i = 1; i < count; ++i) {
    if (times_ns[i] - times_ns[i - 1] <= kSecond / 10) covered_ns += times_ns[i] - times_ns[i - 1];
  }
  EXPECT_NEAR(result.coverage,
              static_cast<double>(covered_ns) / static_cast<double>(times_ns.back() - times_ns[0]),
              1e-12);
  EXPECT_GT(result.coverage, 0.99);
}

TEST(EvaluateTrajectory, Sim3AlignmentOnRealTrajectory) {
  EVLOC_REQUIRE_SHARED_DATA(path, "tum-trajectories/fr1_xyz_groundtruth.txt");
  const Trajectory ground_truth = ReadTumTrajectory(path);
  Sim3d est_from_gt;
  est_from_gt.scale = 0.6;
  est_from_gt.rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(2.0, Eigen::Vector3d(1, 1, 0).normalized()));
  est_from_gt.translation = Eigen::Vector3d(3, 1, -2);
  Trajectory estimate;
  for (const TimedPose& pose : ground_truth.poses()) {
    estimate.Append({pose.t_ns, est_from_gt.TransformPose(pose.world_from_cam)});
  }
  EvaluationOptions options;
  options.alignment = Alignment::kSim3;
  const EvaluationResult result = EvaluateTrajectory(ground_truth, estimate, options);
  EXPECT_LT(result.ate_translation_cm.max, 1e-6);
  EXPECT_LT(result.ate_rotation_deg.max, 1e-6);
  EXPECT_NEAR(result.gt_from_est.scale, 1.0 / 0.6, 1e-9);
}

}  // namespace
}  // namespace evloc
