#include "tools/sim/events_from_frames.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/common/test_data.h"

namespace evloc::sim {
namespace {

// A smooth pattern shifted right by `shift` pixels.
cv::Mat Pattern(double shift) {
  cv::Mat image(40, 60, CV_32FC1);
  for (int row = 0; row < image.rows; ++row) {
    for (int col = 0; col < image.cols; ++col) {
      const double x = col - shift;
      image.at<float>(row, col) = static_cast<float>(0.5 + 0.3 * std::sin(2 * M_PI * x / 20.0) *
                                                               std::cos(2 * M_PI * row / 25.0));
    }
  }
  return image;
}

TEST(InterpolateFrame, WarpsAlongTheFlow) {
  const double shift = 4.0;
  const cv::Mat frame0 = Pattern(0);
  const cv::Mat frame1 = Pattern(shift);
  const cv::Mat flow01(frame0.size(), CV_32FC2, cv::Scalar(shift, 0));
  const cv::Mat flow10(frame0.size(), CV_32FC2, cv::Scalar(-shift, 0));
  for (double alpha : {0.25, 0.5, 0.75}) {
    const cv::Mat interpolated = InterpolateFrame(frame0, frame1, flow01, flow10, alpha);
    const cv::Mat truth = Pattern(alpha * shift);
    const cv::Rect inner(8, 2, 44, 36);  // away from the replicated border
    double worst = cv::norm(interpolated(inner), truth(inner), cv::NORM_INF);
    EXPECT_LT(worst, 0.01) << alpha;
    // A plain cross-fade is far worse: the interpolation really follows the motion.
    cv::Mat faded;
    cv::addWeighted(frame0, 1 - alpha, frame1, alpha, 0, faded);
    EXPECT_GT(cv::norm(faded(inner), truth(inner), cv::NORM_INF), 10 * worst) << alpha;
  }
}

TEST(EventsFromFrames, RealDavisFramesGiveOrderedEventsInsideTheSequence) {
  EVLOC_REQUIRE_SHARED_DATA(list, "ecd/slider_depth/images.txt");
  std::vector<TimedFile> images = ReadTimedFileList(list, list.parent_path());
  images.resize(12);
  EventsFromFramesOptions options;
  EventBuffer events;
  const EventsFromFramesStats stats =
      EventsFromFrames(images, options, [&](const EventBuffer& batch) { events.Append(batch); });
  EXPECT_EQ(stats.num_input_frames, 12);
  EXPECT_GT(stats.max_flow_px, 0.5);  // the slider moves a few pixels per frame
  EXPECT_GE(stats.num_interpolated_frames,
            11 * static_cast<int64_t>(std::floor(stats.max_flow_px / 0.5)) / 4);
  ASSERT_EQ(static_cast<int64_t>(events.size()), stats.num_events);
  ASSERT_GT(events.size(), 10'000u);
  for (size_t i = 1; i < events.size(); ++i) ASSERT_LE(events.t_ns[i - 1], events.t_ns[i]);
  EXPECT_GT(events.t_ns.front(), images.front().t_ns);
  EXPECT_LE(events.t_ns.back(), images.back().t_ns);
}

}  // namespace
}  // namespace evloc::sim
