// The evaluation figure: a top view (projection along the axis of least extent) of the ground-truth
// and estimated trajectories above the translation error over time, titled with the main figures.
// Drawn with OpenCV.
#pragma once

#include <filesystem>

#include <opencv2/core.hpp>

#include "core/trajectory/trajectory.h"
#include "tools/eval/evaluation.h"

namespace evloc {

// Size and look of the evaluation figure.
struct EvaluationPlotOptions {
  // Image width, pixels.
  int width_px = 1000;
  // Image height, pixels.
  int height_px = 1000;

  // Throws InvalidArgumentError unless the image is at least 400 x 400 pixels.
  void Check() const;
};

// Renders the figure (8-bit BGR). `estimate` is in its own frame; result.gt_from_est is applied.
// The top view shows the two world axes along which the trajectories extend most, with equal
// scale and metre ticks; the lower panel the translation error of each matched pose (cm) against
// seconds since the ground-truth start, with the --fail-cm threshold.
cv::Mat RenderEvaluationPlot(const Trajectory& ground_truth, const Trajectory& estimate,
                             const EvaluationResult& result,
                             const EvaluationPlotOptions& options = {});

// Renders the figure and writes it atomically as a PNG. Throws IoError when it cannot.
void WriteEvaluationPlot(const std::filesystem::path& path, const Trajectory& ground_truth,
                         const Trajectory& estimate, const EvaluationResult& result,
                         const EvaluationPlotOptions& options = {});

}  // namespace evloc
