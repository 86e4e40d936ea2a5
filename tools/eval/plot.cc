#include "tools/eval/plot.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc {
namespace {

const cv::Scalar kWhite(255, 255, 255);
const cv::Scalar kBlack(0, 0, 0);
const cv::Scalar kGrid(225, 225, 225);
const cv::Scalar kAxisText(60, 60, 60);
const cv::Scalar kGroundTruthColor(40, 40, 40);
const cv::Scalar kEstimateColor(30, 30, 220);
const cv::Scalar kThresholdColor(0, 140, 255);
constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;

std::string FormatNumber(double value, int decimals) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*f", decimals, value);
  return buffer;
}

// A "nice" tick step (1, 2 or 5 times a power of ten) giving about `target_ticks` ticks.
double NiceStep(double extent, int target_ticks) {
  const double raw = std::max(extent, 1e-9) / target_ticks;
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  for (const double factor : {1.0, 2.0, 5.0}) {
    if (factor * power >= raw) return factor * power;
  }
  return 10.0 * power;
}

// Decimals needed to print multiples of `step`.
int DecimalsFor(double step) {
  return std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
}

void PutText(cv::Mat& image, const std::string& text, cv::Point origin, double scale,
             const cv::Scalar& color, int thickness = 1) {
  cv::putText(image, text, origin, kFont, scale, color, thickness, cv::LINE_AA);
}

// Puts text centred horizontally on x.
void PutCentredText(cv::Mat& image, const std::string& text, int x, int y, double scale,
                    const cv::Scalar& color) {
  int baseline = 0;
  const cv::Size size = cv::getTextSize(text, kFont, scale, 1, &baseline);
  PutText(image, text, cv::Point(x - size.width / 2, y), scale, color);
}

// Puts text right-aligned at x.
void PutRightText(cv::Mat& image, const std::string& text, int x, int y, double scale,
                  const cv::Scalar& color) {
  int baseline = 0;
  const cv::Size size = cv::getTextSize(text, kFont, scale, 1, &baseline);
  PutText(image, text, cv::Point(x - size.width, y), scale, color);
}

// Maps data coordinates (u right, v up) into a pixel rectangle.
struct PanelMapping {
  cv::Rect rect;
  double u_min = 0.0;
  double v_min = 0.0;
  double u_scale = 1.0;  // Pixels per unit along u.
  double v_scale = 1.0;  // Pixels per unit along v.

  cv::Point ToPixel(double u, double v) const {
    return cv::Point(static_cast<int>(std::lround(rect.x + (u - u_min) * u_scale)),
                     static_cast<int>(std::lround(rect.y + rect.height - (v - v_min) * v_scale)));
  }
  double UMax() const { return u_min + rect.width / u_scale; }
  double VMax() const { return v_min + rect.height / v_scale; }
};

// Grid, ticks and labels of a panel.
void DrawAxes(cv::Mat& image, const PanelMapping& mapping, const std::string& u_label,
              const std::string& v_label) {
  const double u_step = NiceStep(mapping.UMax() - mapping.u_min, 8);
  const double v_step = NiceStep(mapping.VMax() - mapping.v_min, 7);
  const int bottom = mapping.rect.y + mapping.rect.height;
  for (double u = std::ceil(mapping.u_min / u_step) * u_step; u <= mapping.UMax() + 1e-12;
       u += u_step) {
    const int x = mapping.ToPixel(u, mapping.v_min).x;
    cv::line(image, {x, mapping.rect.y}, {x, bottom}, kGrid, 1);
    cv::line(image, {x, bottom}, {x, bottom + 5}, kBlack, 1);
    PutCentredText(image, FormatNumber(u, DecimalsFor(u_step)), x, bottom + 20, 0.45, kAxisText);
  }
  for (double v = std::ceil(mapping.v_min / v_step) * v_step; v <= mapping.VMax() + 1e-12;
       v += v_step) {
    const int y = mapping.ToPixel(mapping.u_min, v).y;
    cv::line(image, {mapping.rect.x, y}, {mapping.rect.x + mapping.rect.width, y}, kGrid, 1);
    cv::line(image, {mapping.rect.x - 5, y}, {mapping.rect.x, y}, kBlack, 1);
    PutRightText(image, FormatNumber(v, DecimalsFor(v_step)), mapping.rect.x - 8, y + 5, 0.45,
                 kAxisText);
  }
  cv::rectangle(image, mapping.rect, kBlack, 1);
  PutCentredText(image, u_label, mapping.rect.x + mapping.rect.width / 2, bottom + 42, 0.5, kBlack);
  PutText(image, v_label, {mapping.rect.x, mapping.rect.y - 8}, 0.5, kBlack);
}

// Draws a polyline through `points`, broken where consecutive times differ by more than
// `max_gap_ns`.
void DrawPath(cv::Mat& image, const std::vector<cv::Point>& points,
              const std::vector<int64_t>& times_ns, int64_t max_gap_ns, const cv::Scalar& color,
              int thickness) {
  for (size_t k = 1; k < points.size(); ++k) {
    if (times_ns[k] - times_ns[k - 1] > max_gap_ns) continue;
    cv::line(image, points[k - 1], points[k], color, thickness, cv::LINE_AA);
  }
}

void DrawDashedLine(cv::Mat& image, cv::Point from, cv::Point to, const cv::Scalar& color) {
  if (from == to) return;
  const double length = std::hypot(to.x - from.x, to.y - from.y);
  constexpr double kDash = 8.0;
  for (double s = 0.0; s < length; s += 2 * kDash) {
    const double e = std::min(s + kDash, length);
    const cv::Point a(from.x + static_cast<int>((to.x - from.x) * s / length),
                      from.y + static_cast<int>((to.y - from.y) * s / length));
    const cv::Point b(from.x + static_cast<int>((to.x - from.x) * e / length),
                      from.y + static_cast<int>((to.y - from.y) * e / length));
    cv::line(image, a, b, color, 2, cv::LINE_AA);
  }
}

}  // namespace

void EvaluationPlotOptions::Check() const {
  if (width_px < 400 || height_px < 400) {
    throw InvalidArgumentError("evaluation plot must be at least 400 x 400 pixels, got " +
                               std::to_string(width_px) + " x " + std::to_string(height_px));
  }
}

cv::Mat RenderEvaluationPlot(const Trajectory& ground_truth, const Trajectory& estimate,
                             const EvaluationResult& result, const EvaluationPlotOptions& options) {
  options.Check();
  if (ground_truth.empty()) throw InvalidArgumentError("cannot plot an empty ground truth");
  const EvaluationOptions& evaluation = result.options;
  cv::Mat image(options.height_px, options.width_px, CV_8UC3, kWhite);
  const int width = options.width_px;
  const int height = options.height_px;

  // Title: the main figures and the conditions they hold under.
  const std::string rpe_text = result.rpe_translation_rmse_cm_s
                                   ? FormatNumber(*result.rpe_translation_rmse_cm_s, 2) +
                                         " cm/s, " +
                                         FormatNumber(*result.rpe_rotation_rmse_deg_s, 2) + " deg/s"
                                   : std::string("n/a");
  PutText(image,
          "ATE " + FormatNumber(result.ate_translation_cm.rmse, 2) + " cm, " +
              FormatNumber(result.ate_rotation_deg.rmse, 2) + " deg RMSE   RPE " + rpe_text +
              " RMSE",
          {20, 28}, 0.62, kBlack, 2);
  PutText(image,
          "alignment " + AlignmentName(evaluation.alignment) + ", delta " +
              FormatNumber(evaluation.delta_s, 2) + " s, tolerance " +
              FormatNumber(evaluation.max_dt_s, 3) + " s, " + std::to_string(result.matched_poses) +
              " matched poses, coverage " + FormatNumber(100.0 * result.coverage, 1) +
              " %, failed at " +
              (result.failed_at_s ? FormatNumber(*result.failed_at_s, 2) + " s" : "never"),
          {20, 54}, 0.48, kAxisText);

  // Positions in the ground-truth frame.
  std::vector<Eigen::Vector3d> gt_positions;
  std::vector<int64_t> gt_times;
  for (const TimedPose& pose : ground_truth.poses()) {
    gt_positions.push_back(pose.world_from_cam.translation);
    gt_times.push_back(pose.t_ns);
  }
  std::vector<Eigen::Vector3d> est_positions;
  std::vector<int64_t> est_times;
  for (const TimedPose& pose : estimate.poses()) {
    est_positions.push_back(result.gt_from_est * pose.world_from_cam.translation);
    est_times.push_back(pose.t_ns);
  }

  // The two axes along which the trajectories extend most, in x, y, z order.
  Eigen::Vector3d lower = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d upper = -lower;
  for (const auto* positions : {&gt_positions, &est_positions}) {
    for (const Eigen::Vector3d& position : *positions) {
      lower = lower.cwiseMin(position);
      upper = upper.cwiseMax(position);
    }
  }
  const Eigen::Vector3d extent = upper - lower;
  int dropped_axis = 0;
  extent.minCoeff(&dropped_axis);
  std::array<int, 2> axes{};
  for (int axis = 0, k = 0; axis < 3; ++axis) {
    if (axis != dropped_axis) axes[k++] = axis;
  }
  const std::array<const char*, 3> axis_names = {"x", "y", "z"};

  // Top view with equal scale on both axes.
  const int left = 90;
  const int right_margin = 30;
  const int view_top = 90;
  const int view_height = static_cast<int>(0.55 * height);
  PanelMapping view;
  view.rect = cv::Rect(left, view_top, width - left - right_margin, view_height);
  const double u_extent = std::max(extent[axes[0]], 1e-3) * 1.1;
  const double v_extent = std::max(extent[axes[1]], 1e-3) * 1.1;
  const double pixels_per_metre = std::min(view.rect.width / u_extent, view.rect.height / v_extent);
  view.u_scale = view.v_scale = pixels_per_metre;
  view.u_min = 0.5 * (lower[axes[0]] + upper[axes[0]]) - 0.5 * view.rect.width / pixels_per_metre;
  view.v_min = 0.5 * (lower[axes[1]] + upper[axes[1]]) - 0.5 * view.rect.height / pixels_per_metre;
  DrawAxes(image, view, std::string(axis_names[axes[0]]) + " [m]",
           std::string(axis_names[axes[1]]) + " [m]   (projection along " +
               axis_names[dropped_axis] + ", the axis of least extent; ground-truth frame)");
  const int64_t max_gap_ns = std::llround(evaluation.coverage_max_gap_s * 1e9);
  const auto project = [&](const std::vector<Eigen::Vector3d>& positions) {
    std::vector<cv::Point> points;
    for (const Eigen::Vector3d& position : positions) {
      points.push_back(view.ToPixel(position[axes[0]], position[axes[1]]));
    }
    return points;
  };
  const std::vector<cv::Point> gt_points = project(gt_positions);
  const std::vector<cv::Point> est_points = project(est_positions);
  DrawPath(image, gt_points, gt_times, std::numeric_limits<int64_t>::max(), kGroundTruthColor, 2);
  DrawPath(image, est_points, est_times, max_gap_ns, kEstimateColor, 2);
  cv::circle(image, gt_points.front(), 6, kGroundTruthColor, 2, cv::LINE_AA);
  if (!est_points.empty()) cv::circle(image, est_points.front(), 4, kEstimateColor, -1);

  // Legend, top-right inside the view.
  const cv::Rect legend(view.rect.x + view.rect.width - 300, view.rect.y + 10, 290, 58);
  cv::rectangle(image, legend, kWhite, -1);
  cv::rectangle(image, legend, kBlack, 1);
  cv::line(image, {legend.x + 10, legend.y + 18}, {legend.x + 45, legend.y + 18}, kGroundTruthColor,
           2, cv::LINE_AA);
  PutText(image, "ground truth (circle: start)", {legend.x + 55, legend.y + 23}, 0.45, kBlack);
  cv::line(image, {legend.x + 10, legend.y + 42}, {legend.x + 45, legend.y + 42}, kEstimateColor, 2,
           cv::LINE_AA);
  PutText(image,
          evaluation.alignment == Alignment::kNone
              ? std::string("estimate (no alignment)")
              : "estimate (" + AlignmentName(evaluation.alignment) + "-aligned)",
          {legend.x + 55, legend.y + 47}, 0.45, kBlack);

  // Translation error over time.
  PanelMapping errors;
  const int errors_top = view_top + view_height + 85;
  errors.rect = cv::Rect(left, errors_top, width - left - right_margin, height - errors_top - 60);
  const double duration_s = std::max(static_cast<double>(ground_truth.duration_ns()) * 1e-9, 1e-3);
  double max_error_cm = evaluation.fail_cm;
  for (const double error : result.translation_errors_cm)
    max_error_cm = std::max(max_error_cm, error);
  errors.u_min = 0.0;
  errors.v_min = 0.0;
  errors.u_scale = errors.rect.width / duration_s;
  errors.v_scale = errors.rect.height / (1.1 * max_error_cm);
  DrawAxes(image, errors, "time since ground-truth start [s]", "translation error [cm]");
  std::vector<cv::Point> error_points;
  std::vector<int64_t> error_times;
  for (size_t k = 0; k < result.translation_errors_cm.size(); ++k) {
    error_points.push_back(
        errors.ToPixel(result.error_times_s[k], result.translation_errors_cm[k]));
    error_times.push_back(std::llround(result.error_times_s[k] * 1e9));
  }
  DrawPath(image, error_points, error_times, max_gap_ns, kEstimateColor, 2);
  const int threshold_y = errors.ToPixel(0.0, evaluation.fail_cm).y;
  DrawDashedLine(image, {errors.rect.x, threshold_y},
                 {errors.rect.x + errors.rect.width, threshold_y}, kThresholdColor);
  PutText(image, "fail threshold " + FormatNumber(evaluation.fail_cm, 1) + " cm",
          {errors.rect.x + 6, threshold_y - 6}, 0.45, kThresholdColor);
  if (result.failed_at_s) {
    const int x = errors.ToPixel(*result.failed_at_s, 0.0).x;
    DrawDashedLine(image, {x, errors.rect.y}, {x, errors.rect.y + errors.rect.height},
                   kThresholdColor);
    const std::string label = "failed at " + FormatNumber(*result.failed_at_s, 2) + " s";
    if (x > errors.rect.x + errors.rect.width / 2) {
      PutRightText(image, label, x - 6, errors.rect.y + 16, 0.45, kThresholdColor);
    } else {
      PutText(image, label, {x + 6, errors.rect.y + 16}, 0.45, kThresholdColor);
    }
  }
  return image;
}

void WriteEvaluationPlot(const std::filesystem::path& path, const Trajectory& ground_truth,
                         const Trajectory& estimate, const EvaluationResult& result,
                         const EvaluationPlotOptions& options) {
  const cv::Mat image = RenderEvaluationPlot(ground_truth, estimate, result, options);
  std::vector<uchar> png;
  if (!cv::imencode(".png", image, png)) {
    throw IoError("cannot encode the evaluation plot as PNG for " + path.string());
  }
  WriteFileAtomically(path,
                      std::string_view(reinterpret_cast<const char*>(png.data()), png.size()));
}

}  // namespace evloc
