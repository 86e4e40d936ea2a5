#include "localizer/offline/offline_tracking.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <iostream>
#include <utility>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "localizer/offline/track_command.h"
#include "localizer/tracking/testing/synthetic_scene.h"

namespace evloc::tracking {
namespace {

Camera TestCamera() { return Camera::Pinhole(320, 240, 250, 250, 159.5, 119.5); }

constexpr int64_t kDurationNs = 600'000'000;

double MaxTranslationError(const OfflineTrackingResult& result) {
  double worst = 0;
  for (const TimedPose& pose : result.trajectory.poses()) {
    const Rigid3d truth = testing::SmoothMotion(pose.t_ns);
    worst = std::max(worst, (pose.world_from_cam.translation - truth.translation).norm());
  }
  return worst;
}

TEST(TrackEventStream, FollowsSyntheticMotionAndIgnoresReadBatchSize) {
  const auto rectangles = testing::DefaultRectangles();
  const Map map = testing::MakeRectangleMap(rectangles, 0.01);
  const Camera camera = TestCamera();
  const EventBuffer events = testing::SimulateEdgeEvents(
      map, camera, [](int64_t t) { return testing::SmoothMotion(t); }, 0, kDurationNs);
  ASSERT_GT(events.size(), 10000u);

  OfflineTrackingOptions options;
  options.tracker.step_rate_hz = 200;
  BufferEventReader reader(events);
  const OfflineTrackingResult result = TrackEventStream(
      reader, map, nullptr, camera, testing::SmoothMotion(20'000'000), 20'000'000, options);
  EXPECT_EQ(result.measurements, static_cast<int64_t>(events.size()));
  EXPECT_GE(result.steps.size(), 100u);
  EXPECT_EQ(result.lost_steps, 0);
  EXPECT_LT(MaxTranslationError(result), 0.02);

  // Read on the calling thread instead of the read-ahead thread: the same poses.
  OfflineTrackingOptions same_thread = options;
  same_thread.read_ahead_batches = 0;
  BufferEventReader same_thread_reader(events);
  const OfflineTrackingResult sequential =
      TrackEventStream(same_thread_reader, map, nullptr, camera, testing::SmoothMotion(20'000'000),
                       20'000'000, same_thread);
  ASSERT_EQ(sequential.trajectory.size(), result.trajectory.size());
  for (size_t i = 0; i < sequential.trajectory.size(); ++i) {
    EXPECT_EQ(sequential.trajectory.poses()[i].world_from_cam.translation,
              result.trajectory.poses()[i].world_from_cam.translation);
    EXPECT_EQ(sequential.trajectory.poses()[i].world_from_cam.rotation.coeffs(),
              result.trajectory.poses()[i].world_from_cam.rotation.coeffs());
  }

  options.read_batch_events = 777;
  BufferEventReader small_batches(events);
  const OfflineTrackingResult again = TrackEventStream(
      small_batches, map, nullptr, camera, testing::SmoothMotion(20'000'000), 20'000'000, options);
  ASSERT_EQ(again.trajectory.size(), result.trajectory.size());
  for (size_t i = 0; i < again.trajectory.size(); ++i) {
    EXPECT_EQ(again.trajectory.poses()[i].t_ns, result.trajectory.poses()[i].t_ns);
    EXPECT_EQ(again.trajectory.poses()[i].world_from_cam.translation,
              result.trajectory.poses()[i].world_from_cam.translation);
  }
}

// A run that starts mid-motion with the camera's velocity (OfflineTrackingOptions::
// initial_velocity, evloc-track --initial-velocity) does not fall behind in its first steps as a
// start at rest does (largest error over the first 50 ms 4.0 mm against 8.0 mm); a velocity
// without a pose is refused. The events fire when an edge crosses a pixel's centre, as rendered
// ones do: the started run's poses are stamped at their step time from its first step (it has
// a velocity) and the one at rest's only after 100 ms, and on events fired when a point enters a
// pixel (which show no lag) stamping overshoots (9.4 mm against 7.6 mm).
TEST(TrackEventStream, AnInitialVelocityStartsTheTrackerMoving) {
  // The test scene's motion three times as fast (about 1 m/s).
  constexpr double kSpeed = 3.0;
  const auto rectangles = testing::DefaultRectangles();
  const Map map = testing::MakeRectangleMap(rectangles, 0.01);
  const Camera camera = TestCamera();
  const EventBuffer events = testing::SimulateEdgeEvents(
      map, camera, [](int64_t t) { return testing::SmoothMotion(t, kSpeed); }, 0, kDurationNs,
      100'000, testing::EdgeEventTiming::kCrossCentre);
  std::vector<TimedPose> samples;
  for (int64_t t = 0; t <= kDurationNs; t += 1'000'000) {
    samples.push_back({t, testing::SmoothMotion(t, kSpeed)});
  }
  const Trajectory truth(std::move(samples));
  constexpr int64_t kStartNs = 300'000'000;
  const auto first_steps_error = [&](const std::optional<Vector6d>& velocity) {
    OfflineTrackingOptions options;
    options.tracker.step_rate_hz = 200;
    options.initial_velocity = velocity;
    BufferEventReader reader(events);
    const OfflineTrackingResult result = TrackEventStream(
        reader, map, nullptr, camera, testing::SmoothMotion(kStartNs, kSpeed), kStartNs, options);
    double worst = 0;
    for (const TimedPose& pose : result.trajectory.poses()) {
      if (pose.t_ns > kStartNs + 50'000'000) break;
      worst = std::max(worst, (pose.world_from_cam.translation -
                               testing::SmoothMotion(pose.t_ns, kSpeed).translation)
                                  .norm());
    }
    return worst;
  };
  const double at_rest = first_steps_error(std::nullopt);
  const double moving = first_steps_error(truth.Velocity(kStartNs, 20'000'000));
  std::cout << "largest error over the first 50 ms: at rest " << at_rest * 1e3
            << " mm, with the velocity " << moving * 1e3 << " mm\n";
  EXPECT_LT(moving, at_rest);

  OfflineTrackingOptions no_pose;
  no_pose.initial_velocity = Vector6d::Zero();
  BufferEventReader reader(events);
  EXPECT_THROW(TrackEventStream(reader, map, nullptr, camera, std::nullopt, 0, no_pose),
               InvalidArgumentError);
  no_pose.initial_velocity = Vector6d::Constant(std::nan(""));
  EXPECT_THROW(no_pose.Check(), InvalidArgumentError);
}

// Two identical places 20 m apart, keyframes beside the path at both: from no pose the search
// refuses the ambiguity; a search prior around either place finds the camera there, and the
// prior ends with the first TRACKING step.
TEST(TrackEventStream, ASearchPriorChoosesBetweenTwoIdenticalPlaces) {
  const Camera camera = Camera::Pinhole(240, 180, 200.0, 200.0, 119.5, 89.5);
  const Eigen::Vector3d shift(20.0, 0.0, 0.0);
  const Vector6d beside = (Vector6d() << 0.06, -0.03, 0.0, 0.0, 0.05, 0.0).finished();
  Map map = testing::MakeRectangleMap(testing::TwinRectangles(shift), 0.004);
  testing::AddKeyframesBesideThePath(&map, camera, 900'000'000, 150'000'000, beside);
  testing::AddKeyframesBesideThePath(&map, camera, 900'000'000, 150'000'000, beside, shift);
  const EventBuffer events = testing::SimulateEdgeEvents(
      map, camera, [](int64_t t) { return testing::SmoothMotion(t); }, 0, kDurationNs);

  const auto run = [&](const std::optional<Eigen::Vector3d>& prior) {
    OfflineTrackingOptions options;
    options.search_prior_center = prior;
    options.search_prior_radius_m = 1.0;
    BufferEventReader reader(events);
    return TrackEventStream(reader, map, nullptr, camera, std::nullopt, 0, options);
  };
  const auto tracking_steps = [](const OfflineTrackingResult& result) {
    std::vector<PoseEstimate> steps;
    for (const PoseEstimate& step : result.steps) {
      if (step.status == TrackingStatus::kTracking) steps.push_back(step);
    }
    return steps;
  };
  EXPECT_TRUE(tracking_steps(run(std::nullopt)).empty());
  for (const Eigen::Vector3d& place : {Eigen::Vector3d(Eigen::Vector3d::Zero()), shift}) {
    const std::vector<PoseEstimate> tracked = tracking_steps(run(place));
    ASSERT_FALSE(tracked.empty()) << place.transpose();
    for (const PoseEstimate& step : tracked) {
      Rigid3d truth = testing::SmoothMotion(step.t_ns);
      truth.translation += place;
      EXPECT_LT((step.world_from_cam.translation - truth.translation).norm(), 0.05)
          << place.transpose() << " at " << step.t_ns;
    }
  }

  OfflineTrackingOptions bad;
  bad.search_prior_center = Eigen::Vector3d::Zero();
  EXPECT_THROW(bad.Check(), InvalidArgumentError);  // no radius
  bad.search_prior_radius_m = 1.0;
  bad.search_prior_center = Eigen::Vector3d::Constant(NAN);
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
}

// A reader that fails after some events: the error reaches the caller whether the events are
// read on the calling thread or ahead on a second one, and the read-ahead thread stops cleanly.
class FailingEventReader : public EventReader {
 public:
  FailingEventReader(const EventBuffer& events, size_t fail_after)
      : events_(events), fail_after_(fail_after) {}
  size_t Read(size_t max_events, EventBuffer* out) override {
    if (next_ >= fail_after_) throw ParseError::AtByte("broken.evb", 1234, "corrupt chunk");
    const size_t count = std::min({max_events, events_.size() - next_, fail_after_ - next_});
    for (size_t i = 0; i < count; ++i) out->push_back(events_[next_ + i]);
    next_ += count;
    return count;
  }
  std::optional<SensorSize> sensor_size() const override { return std::nullopt; }

 private:
  const EventBuffer& events_;
  size_t fail_after_;
  size_t next_ = 0;
};

TEST(TrackEventStream, ReaderErrorsReachTheCallerWithOrWithoutReadAhead) {
  const Map map = testing::MakeRectangleMap(testing::DefaultRectangles(), 0.01);
  const Camera camera = TestCamera();
  const EventBuffer events = testing::SimulateEdgeEvents(
      map, camera, [](int64_t t) { return testing::SmoothMotion(t); }, 0, 200'000'000);
  ASSERT_GT(events.size(), 5000u);
  for (const int read_ahead : {0, 1, 4}) {
    OfflineTrackingOptions options;
    options.read_batch_events = 1000;
    options.read_ahead_batches = read_ahead;
    FailingEventReader reader(events, events.size() / 2);
    EXPECT_THROW(TrackEventStream(reader, map, nullptr, camera, testing::SmoothMotion(20'000'000),
                                  20'000'000, options),
                 ParseError)
        << read_ahead;
  }
  OfflineTrackingOptions bad;
  bad.read_ahead_batches = -1;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
}

TEST(TrackFrameSequence, FollowsRenderedFrames) {
  const auto rectangles = testing::DefaultRectangles();
  const Map map = testing::MakeRectangleMap(rectangles, 0.01);
  const Camera camera = TestCamera();
  const auto directory = evloc::testing::MakeTempDir("evloc-offline-frames");
  std::vector<FrameFile> frames;
  for (int64_t t = 0; t <= kDurationNs; t += 33'000'000) {
    const auto path = directory / ("frame_" + std::to_string(t) + ".png");
    cv::imwrite(path.string(),
                testing::RenderRectangles(rectangles, camera, testing::SmoothMotion(t)));
    frames.push_back({t, path});
  }
  OfflineTrackingOptions options;
  options.tracker.input = TrackerInput::kFrames;
  const OfflineTrackingResult result =
      TrackFrameSequence(frames, map, nullptr, camera, testing::SmoothMotion(0), 0, options);
  EXPECT_EQ(result.steps.size(), frames.size() - 1);
  // Canny places the rendered step edges up to half a pixel to one side (docs/tracking.md), so
  // the frame twin is held to 5 cm here; its accuracy is measured in docs/accuracy.md.
  EXPECT_LT(MaxTranslationError(result), 0.05);
  std::filesystem::remove_all(directory);
}

TEST(TrackFrames, SixteenBitAndColourFramesTrackLikeTheirGreyAndBadFramesAreNamedErrors) {
  const auto rectangles = testing::DefaultRectangles();
  const Map map = testing::MakeRectangleMap(rectangles, 0.01);
  const Camera camera = TestCamera();
  std::vector<std::pair<int64_t, cv::Mat>> grey;
  for (int64_t t = 0; t <= kDurationNs / 2; t += 33'000'000) {
    grey.emplace_back(t, testing::RenderRectangles(rectangles, camera, testing::SmoothMotion(t)));
  }
  OfflineTrackingOptions options;
  options.tracker.input = TrackerInput::kFrames;
  const auto run = [&](const std::function<cv::Mat(const cv::Mat&)>& as) {
    return TrackFrames(
        [&](const ImageSink& add) {
          for (const auto& [t_ns, pixels] : grey) add(t_ns, as(pixels));
        },
        "test frames", map, nullptr, camera, testing::SmoothMotion(0), 0, options);
  };
  const OfflineTrackingResult reference = run([](const cv::Mat& pixels) { return pixels; });
  ASSERT_EQ(reference.steps.size(), grey.size() - 1);
  const auto same_poses = [&](const OfflineTrackingResult& result) {
    ASSERT_EQ(result.steps.size(), reference.steps.size());
    for (size_t i = 0; i < result.steps.size(); ++i) {
      EXPECT_EQ(result.steps[i].world_from_cam.translation,
                reference.steps[i].world_from_cam.translation);
    }
  };
  // 16 bits: each 8-bit value v as 257 v; BGR and BGRA: three equal channels.
  same_poses(run([](const cv::Mat& pixels) {
    cv::Mat sixteen;
    pixels.convertTo(sixteen, CV_16U, 257.0);
    return sixteen;
  }));
  same_poses(run([](const cv::Mat& pixels) {
    cv::Mat bgr;
    cv::cvtColor(pixels, bgr, cv::COLOR_GRAY2BGR);
    return bgr;
  }));
  same_poses(run([](const cv::Mat& pixels) {
    cv::Mat bgra;
    cv::cvtColor(pixels, bgra, cv::COLOR_GRAY2BGRA);
    return bgra;
  }));
  // A frame of another size, a frame out of order, a float frame: errors naming the source.
  const auto error_of = [&](const FrameSource& source) {
    try {
      TrackFrames(source, "test frames", map, nullptr, camera, testing::SmoothMotion(0), 0,
                  options);
    } catch (const InvalidArgumentError& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  const std::string small = error_of([&](const ImageSink& add) {
    add(10, cv::Mat(camera.height / 2, camera.width / 2, CV_8UC1, cv::Scalar(0)));
  });
  EXPECT_NE(small.find("test frames: the frame at 0.000000010 s is 160x120, the camera 320x240"),
            std::string::npos)
      << small;
  const std::string back = error_of([&](const ImageSink& add) {
    add(grey[2].first, grey[2].second);
    add(grey[1].first, grey[1].second);
  });
  EXPECT_NE(back.find("does not come after the previous one"), std::string::npos) << back;
  const std::string floats = error_of([&](const ImageSink& add) {
    add(10, cv::Mat(camera.height, camera.width, CV_32FC1, cv::Scalar(0)));
  });
  EXPECT_NE(floats.find("8 or 16 bits"), std::string::npos) << floats;
}

TEST(TrackFrameSequence, UnreadableFrameIsAnIoError) {
  const Map map = testing::MakeRectangleMap(testing::DefaultRectangles(), 0.02);
  OfflineTrackingOptions options;
  options.tracker.input = TrackerInput::kFrames;
  EXPECT_THROW(TrackFrameSequence({{10, "/nonexistent/frame.png"}}, map, nullptr, TestCamera(),
                                  Rigid3d(), 0, options),
               IoError);
}

TEST(TrackCommandLine, ParsesFlagsAndRejectsBadValues) {
  const TrackCommandOptions options =
      ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o.txt", "--rate", "150",
                             "--variant", "EVT--", "--init-pose", "1 2 3 0 0 0 1"});
  EXPECT_EQ(options.tracking.tracker.step_rate_hz, 150);
  EXPECT_FALSE(options.tracking.tracker.use_polarity);
  EXPECT_FALSE(options.tracking.tracker.use_occlusion_culling);
  ASSERT_TRUE(options.initial_world_from_cam.has_value());
  EXPECT_EQ(options.initial_world_from_cam->translation, Eigen::Vector3d(1, 2, 3));
  EXPECT_THROW(ParseTrackCommandLine({"--map", "m", "--dataset", "d"}), InvalidArgumentError);
  EXPECT_THROW(
      ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--rate", "fast"}),
      InvalidArgumentError);
  EXPECT_THROW(
      ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--init-pose", "1 2 3"}),
      InvalidArgumentError);
  EXPECT_THROW(
      ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--bogus", "1"}),
      InvalidArgumentError);
}

// The tracker's flags are kept with their values for DEVO's tracker; odometry refuses the map
// search's flags, and VO (no event tracker) the tracker's.
TEST(TrackCommandLine, KeepsTheTrackersFlagsForOdometry) {
  const TrackCommandOptions devo =
      ParseTrackCommandLine({"--mode", "devo", "--dataset", "d", "--out", "o", "--rate", "150",
                             "--stamp-at-step-time", "on"});
  ASSERT_EQ(devo.tracker_flags.size(), 2u);
  EXPECT_EQ(devo.tracker_flags[0], std::make_pair(std::string("--rate"), std::string("150")));
  EXPECT_EQ(devo.tracker_flags[1].first, "--stamp-at-step-time");
  EXPECT_TRUE(devo.search_flags.empty());
  const std::vector<std::string> vo = {"--mode", "vo", "--dataset", "d", "--out", "o"};
  EXPECT_NO_THROW(ParseTrackCommandLine(vo));
  std::vector<std::string> vo_rate = vo;
  vo_rate.insert(vo_rate.end(), {"--rate", "100"});
  EXPECT_THROW(ParseTrackCommandLine(vo_rate), InvalidArgumentError);
  for (const std::string mode : {"vo", "devo"}) {
    EXPECT_THROW(ParseTrackCommandLine(
                     {"--mode", mode, "--dataset", "d", "--out", "o", "--search-grid", "2"}),
                 InvalidArgumentError)
        << mode;
  }
  // With a map, the search's flags are the map tracker's as before.
  EXPECT_EQ(
      ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--search-grid", "2"})
          .tracking.tracker.relocalization_grid_radius_m,
      2);
}

TEST(TrackCommandLine, ParsesTheBinningAndRefusesItForDevo) {
  EXPECT_EQ(ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o"})
                .tracking.tracker.binning,
            1);
  EXPECT_EQ(ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--binning", "2"})
                .tracking.tracker.binning,
            2);
  EXPECT_EQ(
      ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--binning", "auto"})
          .tracking.tracker.binning,
      tracking::kAutoBinning);
  for (const std::string binning : {"2", "auto"}) {
    EXPECT_THROW(ParseTrackCommandLine(
                     {"--mode", "devo", "--dataset", "d", "--out", "o", "--binning", binning}),
                 InvalidArgumentError)
        << binning;
  }
}

TEST(TrackCommandLine, ParsesTheInitialVelocity) {
  const std::vector<std::string> base = {"--map", "m", "--dataset", "d", "--out", "o"};
  const auto parse = [&](std::vector<std::string> extra) {
    std::vector<std::string> arguments = base;
    arguments.insert(arguments.end(), extra.begin(), extra.end());
    return ParseTrackCommandLine(arguments);
  };
  EXPECT_FALSE(parse({}).initial_velocity.has_value());
  EXPECT_FALSE(parse({}).initial_velocity_from_truth);
  EXPECT_TRUE(parse({"--initial-velocity", "truth"}).initial_velocity_from_truth);
  const TrackCommandOptions given = parse({"--initial-velocity", "5 0 0.1 0 0.2 -0.3"});
  ASSERT_TRUE(given.initial_velocity.has_value());
  EXPECT_EQ((*given.initial_velocity)[0], 5);
  EXPECT_EQ((*given.initial_velocity)[5], -0.3);
  for (const std::string bad : {"fast", "1 2 3", "1 2 3 4 5 6 7", "1 2 3 4 5 nan"}) {
    EXPECT_THROW(parse({"--initial-velocity", bad}), InvalidArgumentError) << bad;
  }
  // It starts map tracking of events from a pose.
  EXPECT_THROW(parse({"--initial-velocity", "truth", "--init-pose", "none"}), InvalidArgumentError);
  EXPECT_THROW(parse({"--initial-velocity", "truth", "--mode", "frames"}), InvalidArgumentError);
  EXPECT_THROW(ParseTrackCommandLine({"--mode", "devo", "--dataset", "d", "--out", "o",
                                      "--initial-velocity", "truth"}),
               InvalidArgumentError);
}

TEST(TrackCommandLine, ParsesStartingWithoutAPoseAndTheBlackout) {
  const TrackCommandOptions options = ParseTrackCommandLine({"--map",
                                                             "m",
                                                             "--dataset",
                                                             "d",
                                                             "--out",
                                                             "o",
                                                             "--init-pose",
                                                             "none",
                                                             "--start",
                                                             "0.5",
                                                             "--blackout",
                                                             "1:1.5",
                                                             "--relocalize-after",
                                                             "12",
                                                             "--give-up",
                                                             "2",
                                                             "--search-distinct-depth",
                                                             "0.03",
                                                             "--search-probe-margin",
                                                             "0.08",
                                                             "--search-verify-s-per-m",
                                                             "0.01",
                                                             "--motion-prior",
                                                             "2,15",
                                                             "--velocity-decay-time",
                                                             "0.015"});
  EXPECT_TRUE(options.no_initial_pose);
  EXPECT_FALSE(options.initial_world_from_cam.has_value());
  EXPECT_EQ(options.start_s, 0.5);
  EXPECT_EQ(options.blackout_begin_s, 1.0);
  EXPECT_EQ(options.blackout_end_s, 1.5);
  EXPECT_EQ(options.tracking.tracker.lost_steps_before_relocalization, 12);
  EXPECT_EQ(options.tracking.tracker.relocalization_give_up_s, 2.0);
  EXPECT_EQ(options.tracking.tracker.relocalization_distinct_depth_fraction, 0.03);
  EXPECT_EQ(options.tracking.tracker.relocalization_probe_margin, 0.08);
  EXPECT_EQ(options.tracking.tracker.relocalization_verify_s_per_depth_m, 0.01);
  EXPECT_EQ(options.tracking.tracker.motion_prior_velocity_sigma_mps, 2.0);
  EXPECT_EQ(options.tracking.tracker.motion_prior_angular_velocity_sigma_dps, 15.0);
  EXPECT_EQ(options.tracking.tracker.velocity_decay_time_s, 0.015);
  EXPECT_FALSE(options.gnss.has_value());
  const TrackCommandOptions with_fix =
      ParseTrackCommandLine({"--map", "m", "--dataset", "d", "--out", "o", "--init-pose", "none",
                             "--gnss", "47.3769,8.5417,408,3,5"});
  ASSERT_TRUE(with_fix.gnss.has_value());
  EXPECT_EQ(with_fix.gnss->position.latitude_deg, 47.3769);
  EXPECT_EQ(with_fix.gnss->vertical_accuracy_m, 5.0);
  const std::vector<std::vector<std::string>> bad = {{"--start", "-1"},
                                                     {"--blackout", "2:1"},
                                                     {"--blackout", "1"},
                                                     {"--search-distinct-depth", "0.9"},
                                                     {"--search-probe-margin", "1.5"},
                                                     {"--search-verify-s-per-m", "-0.1"},
                                                     {"--motion-prior", "2"},
                                                     {"--motion-prior", "-1,0"},
                                                     {"--motion-prior", "2,x"},
                                                     {"--velocity-decay-time", "-1"},
                                                     {"--init-pose", "none", "--mode", "frames"},
                                                     {"--gnss", "47.3,8.5,400,3"},
                                                     {"--init-pose", "none", "--gnss", "47.3,8.5"},
                                                     {"--init-pose", "none", "--gnss", "91,8,0,3"}};
  for (const std::vector<std::string>& flags : bad) {
    std::vector<std::string> arguments = {"--map", "m", "--dataset", "d", "--out", "o"};
    arguments.insert(arguments.end(), flags.begin(), flags.end());
    EXPECT_THROW(ParseTrackCommandLine(arguments), InvalidArgumentError) << flags[0];
  }
}

}  // namespace
}  // namespace evloc::tracking
