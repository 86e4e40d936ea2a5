#include "tools/sim/simulate.h"

#include <cmath>

#include <gtest/gtest.h>

namespace evloc::sim {
namespace {

constexpr double kPlaneDepth = 2.0;

// A textured plane z = kPlaneDepth (world), radiance 0.5 + 0.4 sin(2 pi x / 0.1 m).
void RenderPlane(const Camera& camera, const Rigid3d& world_from_cam, cv::Mat* gray, cv::Mat* rgb,
                 cv::Mat* depth) {
  gray->create(camera.height, camera.width, CV_32FC1);
  if (rgb) rgb->create(camera.height, camera.width, CV_32FC3);
  if (depth) depth->create(camera.height, camera.width, CV_32FC1);
  const Eigen::Matrix3d rotation = world_from_cam.RotationMatrix();
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      Eigen::Vector3d ray;
      camera.Unproject(Eigen::Vector2d(col, row), &ray);
      const Eigen::Vector3d ray_world = rotation * ray;
      const double s = (kPlaneDepth - world_from_cam.translation.z()) / ray_world.z();
      const Eigen::Vector3d point = world_from_cam.translation + s * ray_world;
      const auto value = static_cast<float>(0.5 + 0.4 * std::sin(2 * M_PI * point.x() / 0.1));
      gray->at<float>(row, col) = value;
      if (rgb) rgb->at<cv::Vec3f>(row, col) = cv::Vec3f(value, value, value);
      if (depth) depth->at<float>(row, col) = static_cast<float>(s);
    }
  }
}

// Translation along x at constant speed.
class SlideMotion : public CameraMotion {
 public:
  SlideMotion(double speed, int64_t duration_ns) : speed_(speed), duration_ns_(duration_ns) {}
  Rigid3d WorldFromCam(int64_t t_ns) const override {
    return Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(speed_ * t_ns * 1e-9, 0, 0));
  }
  int64_t duration_ns() const override { return duration_ns_; }

 private:
  double speed_;
  int64_t duration_ns_;
};

TEST(SimulateSequence, RendersOftenEnoughFramesOnTimeEventsOrdered) {
  const Camera camera = Camera::Pinhole(64, 48, 60, 60, 31.5, 23.5);
  const double speed = 5.0;  // m/s -> 60 * 5 / 2 = 150 px/s
  const SlideMotion motion(speed, 400'000'000);
  SequenceOptions options;
  options.max_render_interval_ns = 50'000'000;
  options.frames.fps = 20;
  options.frames.exposure_s = 0.01;
  EventBuffer all_events;
  std::vector<int64_t> frame_times;
  const SequenceStats stats = SimulateSequence(
      [&](const Rigid3d& pose, cv::Mat* gray, cv::Mat* rgb, cv::Mat* depth) {
        RenderPlane(camera, pose, gray, rgb, depth);
      },
      camera, motion, options, [&](const EventBuffer& events) { all_events.Append(events); },
      [&](int64_t t_ns, const cv::Mat& image, const cv::Mat& depth) {
        frame_times.push_back(t_ns);
        EXPECT_EQ(image.type(), CV_8UC3);
        EXPECT_NEAR(depth.at<float>(10, 10), kPlaneDepth, 1e-5);
      });
  const double image_speed_px_per_s = camera.fx * speed / kPlaneDepth;
  EXPECT_LE(stats.max_measured_motion_px, options.max_pixel_motion_px + 1e-9);
  EXPECT_GE(stats.num_renders + stats.num_interpolated,
            image_speed_px_per_s * 0.4 / options.max_pixel_motion_px);
  EXPECT_LT(stats.num_renders, stats.num_interpolated);  // renders every ~3 px, not every 0.5
  // Frames every 50 ms, stamped mid-exposure, the last exposure ending inside the sequence.
  ASSERT_EQ(frame_times.size(), 8u);
  for (size_t i = 0; i < frame_times.size(); ++i)
    EXPECT_EQ(frame_times[i], i * 50'000'000 + 5'000'000);
  ASSERT_EQ(static_cast<int64_t>(all_events.size()), stats.num_events);
  ASSERT_GT(all_events.size(), 1000u);
  for (size_t i = 1; i < all_events.size(); ++i) {
    ASSERT_LE(all_events.t_ns[i - 1], all_events.t_ns[i]);
  }
  EXPECT_GT(all_events.t_ns.front(), 0);
  EXPECT_LE(all_events.t_ns.back(), motion.duration_ns());
}

// Clean pixel: over a whole number of grating periods each pixel emits about
// (total |d log I| travelled) / C events, whether every image is rendered or interpolated.
class EventCountTest : public ::testing::TestWithParam<double> {};

TEST_P(EventCountTest, MatchesTheLogIntensityTravelled) {
  const Camera camera = Camera::Pinhole(32, 8, 60, 60, 15.5, 3.5);
  const double period_px = 60 * 0.1 / kPlaneDepth;  // 3 px
  const SlideMotion motion(0.2, 500'000'000);       // 6 px/s -> one period per 0.5 s
  SequenceOptions options;
  options.esim = options.esim.Clean();
  options.max_render_motion_px = GetParam();
  options.max_render_interval_ns = 200'000'000;  // the motion bound decides
  options.frames.fps = 10;
  options.frames.exposure_s = 0.005;
  EventBuffer all_events;
  SimulateSequence([&](const Rigid3d& pose, cv::Mat* gray, cv::Mat* rgb,
                       cv::Mat* depth) { RenderPlane(camera, pose, gray, rgb, depth); },
                   camera, motion, options,
                   [&](const EventBuffer& events) { all_events.Append(events); },
                   [](int64_t, const cv::Mat&, const cv::Mat&) {});
  ASSERT_NEAR(motion.duration_ns() * 1e-9 * 60 * 0.2 / kPlaneDepth, period_px, 1e-9);
  // Over one full period each pixel's log I rises and falls by
  // delta = log(0.9 + eps) - log(0.1 + eps). A monotone run of length delta that starts with the
  // reference a uniform fraction of C past the extremum emits on average delta / C - 1 events;
  // the period splits into 3 runs for a pixel starting mid-slope (2 runs and 2 partial ones), so
  // each pixel emits about 2 delta / C - 3 events.
  const double delta = std::log(0.9 + 1e-3) - std::log(0.1 + 1e-3);
  const double per_pixel = static_cast<double>(all_events.size()) / (camera.width * camera.height);
  EXPECT_NEAR(per_pixel, 2 * delta / 0.2 - 3, 0.5);
}

INSTANTIATE_TEST_SUITE_P(RenderEveryImageOrInterpolate, EventCountTest,
                         ::testing::Values(0.5, 2.0));

}  // namespace
}  // namespace evloc::sim
