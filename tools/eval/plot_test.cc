#include "tools/eval/plot.h"

#include <cmath>
#include <functional>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/common/error.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

// Counts pixels whose colour (BGR) satisfies `predicate`.
int CountPixels(const cv::Mat& image, const std::function<bool(const cv::Vec3b&)>& predicate) {
  int count = 0;
  for (int row = 0; row < image.rows; ++row) {
    for (int column = 0; column < image.cols; ++column) {
      if (predicate(image.at<cv::Vec3b>(row, column))) ++count;
    }
  }
  return count;
}

Trajectory Circle(double radius_m, double offset_m) {
  Trajectory trajectory;
  for (int k = 0; k <= 400; ++k) {
    const double t = k * 0.01;
    trajectory.Append({k * 10'000'000LL,
                       Rigid3d(Eigen::Quaterniond::Identity(),
                               {radius_m * std::cos(t) + offset_m, radius_m * std::sin(t), 0.5})});
  }
  return trajectory;
}

TEST(EvaluationPlot, DrawsBothTrajectoriesAndWritesAReadablePng) {
  const Trajectory ground_truth = Circle(1.0, 0.0);
  const Trajectory estimate = Circle(1.0, 0.05);
  EvaluationOptions options;
  options.fail_cm = 4.0;
  const EvaluationResult result = EvaluateTrajectory(ground_truth, estimate, options);
  const cv::Mat image = RenderEvaluationPlot(ground_truth, estimate, result);
  EXPECT_EQ(image.cols, 1000);
  EXPECT_EQ(image.rows, 1000);
  // Estimate drawn in red, ground truth in dark grey, the threshold in orange.
  const int red =
      CountPixels(image, [](const cv::Vec3b& p) { return p[2] > 170 && p[1] < 100 && p[0] < 100; });
  const int dark =
      CountPixels(image, [](const cv::Vec3b& p) { return p[0] < 70 && p[1] < 70 && p[2] < 70; });
  const int orange = CountPixels(image, [](const cv::Vec3b& p) {
    return p[2] > 200 && p[1] > 100 && p[1] < 180 && p[0] < 60;
  });
  EXPECT_GT(red, 1000);
  EXPECT_GT(dark, 1000);
  EXPECT_GT(orange, 300);

  const std::filesystem::path directory = testing::MakeTempDir("eval_plot");
  const std::filesystem::path path = directory / "plot.png";
  WriteEvaluationPlot(path, ground_truth, estimate, result);
  const cv::Mat read = cv::imread(path.string());
  ASSERT_FALSE(read.empty());
  EXPECT_EQ(cv::norm(read, image, cv::NORM_INF), 0.0);
  std::filesystem::remove_all(directory);
}

TEST(EvaluationPlot, RejectsTinyImages) {
  EvaluationPlotOptions options;
  options.width_px = 100;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc
