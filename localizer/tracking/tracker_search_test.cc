// The tracker's global search (INITIALIZING / RELOCALIZING; docs/relocalization.md, "Events") on
// the synthetic rectangle scene: from no pose, after a blackout, against unrelated events, and
// the verification's refusal of an ambiguous round.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "core/common/thread_cpu_time.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "localizer/tracking/tracker.h"

namespace evloc::tracking {
namespace {

constexpr double kDegree = M_PI / 180.0;
const Camera kCamera = Camera::Pinhole(240, 180, 200.0, 200.0, 119.5, 89.5);

// The rectangle map with keyframes along a path beside the one the events are simulated on:
// every 150 ms of SmoothMotion, displaced by 6 cm and turned by 3 degrees (a map built from
// another pass through the scene).
Map MapWithKeyframes(const std::vector<testing::Rectangle>& rectangles,
                     const Eigen::Vector3d& shift = Eigen::Vector3d::Zero(),
                     const Vector6d& displacement =
                         (Vector6d() << 0.06, -0.03, 0.0, 0.0, 3 * kDegree, 0).finished()) {
  Map map = testing::MakeRectangleMap(rectangles, 0.004);
  testing::AddKeyframesBesideThePath(&map, kCamera, 900'000'000, 150'000'000, displacement, shift);
  return map;
}

const Map& SceneMap() {
  static const Map map = MapWithKeyframes(testing::DefaultRectangles());
  return map;
}

EventBuffer SceneEvents(int64_t t_end_ns) {
  return testing::SimulateEdgeEvents(
      SceneMap(), kCamera, [](int64_t t_ns) { return testing::SmoothMotion(t_ns); }, 0, t_end_ns);
}

double PositionError(const PoseEstimate& estimate) {
  return testing::PositionErrorToSmoothMotion(estimate.world_from_cam, estimate.t_ns);
}

double RotationError(const PoseEstimate& estimate) {
  return testing::RotationErrorToSmoothMotion(estimate.world_from_cam, estimate.t_ns);
}

// Every estimate that is not TRACKING carries no information; every TRACKING pose is within
// 5 cm / 3 degrees of the truth. Returns the time of the first TRACKING step (or -1).
int64_t CheckEstimates(const std::vector<PoseEstimate>& estimates, const TrackerOptions& options) {
  int64_t first_tracking_ns = -1;
  for (const PoseEstimate& estimate : estimates) {
    EXPECT_LE(estimate.search.prescored, options.relocalization_prescores_per_step);
    EXPECT_LE(estimate.search.refined, options.relocalization_refinements_per_step);
    if (estimate.status != TrackingStatus::kTracking) {
      EXPECT_GE(estimate.covariance.diagonal().minCoeff(), kUnconstrainedVariance) << estimate.t_ns;
      continue;
    }
    if (first_tracking_ns < 0) first_tracking_ns = estimate.t_ns;
    EXPECT_LT(PositionError(estimate), 0.05) << estimate.t_ns;
    EXPECT_LT(RotationError(estimate), 3 * kDegree) << estimate.t_ns;
  }
  return first_tracking_ns;
}

TEST(TrackerSearch, FindsItselfFromNoPoseAndEveryTrackingPoseIsRight) {
  const EventBuffer events = SceneEvents(600'000'000);
  TrackerOptions options;
  Tracker tracker(SceneMap(), nullptr, kCamera, options);
  tracker.StartWithoutPose(0);
  EXPECT_EQ(tracker.status(), TrackingStatus::kInitializing);
  const std::vector<PoseEstimate> estimates = tracker.AddEvents(events);
  ASSERT_FALSE(estimates.empty());
  EXPECT_EQ(estimates.front().t_ns, 0);  // The first step is at the start time.
  EXPECT_EQ(estimates.front().status, TrackingStatus::kInitializing);
  const int64_t first_tracking_ns = CheckEstimates(estimates, options);
  ASSERT_GE(first_tracking_ns, 0) << "never TRACKING";
  std::cout << "from no pose: TRACKING at " << first_tracking_ns * 1e-9 << " s\n";
  // Measured: TRACKING at 0.09 s (30 ms to fill the surfaces, then one round and the
  // 10-step verification). The target is 1 s.
  EXPECT_LT(first_tracking_ns, 300'000'000);
  // Once found it stays found.
  int tracking_after = 0;
  for (const PoseEstimate& estimate : estimates) {
    if (estimate.t_ns > first_tracking_ns) {
      tracking_after += estimate.status == TrackingStatus::kTracking ? 1 : 0;
    }
  }
  EXPECT_GT(tracking_after, 100);
  EXPECT_EQ(tracker.status(), TrackingStatus::kTracking);
}

// Calls `step(window, end_ns)` with the events of each step period [end_ns - period_ns, end_ns) in
// turn (one step's events at a time, as a live session gets them, and so that the CPU of each
// step is measured alone), until `step` returns false or the events end.
template <typename Step>
void ForEachStepWindow(const EventBuffer& events, int64_t period_ns, Step&& step) {
  size_t begin = 0;
  for (int64_t end_ns = period_ns; begin < events.size(); end_ns += period_ns) {
    size_t end = begin;
    while (end < events.size() && events.t_ns[end] < end_ns) ++end;
    EventBuffer window;
    window.Append(events, begin, end - begin);
    if (!step(window, end_ns)) return;
    begin = end;
  }
}

// CPU time of the searching steps of an unbounded search from no pose, until it is TRACKING:
// what the whole search costs on this machine at this moment, ingestion of the steps included.
int64_t UnboundedSearchCpuNs(const EventBuffer& events, const TrackerOptions& options) {
  Tracker tracker(SceneMap(), nullptr, kCamera, options);
  tracker.StartWithoutPose(0);
  const int64_t period_ns = std::llround(1e9 / options.step_rate_hz);
  int64_t cpu_ns = 0;
  ForEachStepWindow(events, period_ns, [&](const EventBuffer& window, int64_t) {
    const int64_t before = ThreadCpuTimeNs();
    tracker.AddEvents(window);
    if (tracker.status() == TrackingStatus::kTracking) return false;
    cpu_ns += ThreadCpuTimeNs() - before;
    return true;
  });
  return cpu_ns;
}

// With a CPU share the search defers steps once it has used its budget (a live session then
// keeps up with its events), still finds itself, and its work per second of events stays within
// the share (plus the saved-up burst and the overshoot of the last step that had credit). The
// share is set from what an unbounded search costs here and now, so that the search is spread
// over the same span of events (about half a second) on a fast or a slow, idle or loaded machine:
// a share fixed in CPU seconds spread it over 0.3 s on an idle machine and over 3 s and more on a
// loaded one, whose hypotheses were then too old to be verified (a fresh clone's parallel test run
// never found it in 3 s). The first round, whose cost the search does not know yet, is spread
// widest; a later round waits until the budget covers the last round's cost and runs on
// consecutive steps.
TEST(TrackerSearch, ACpuShareBoundsTheSearchWorkAndItStillFindsItself) {
  const EventBuffer events = SceneEvents(3'000'000'000);
  TrackerOptions options;
  const int64_t unbounded_ns = UnboundedSearchCpuNs(events, options);
  ASSERT_GT(unbounded_ns, 0);
  // Measured on the development machines: 25-48 ms. The share spreads it over 0.5 s of events,
  // a fifth of it as the initial burst.
  options.relocalization_cpu_share = std::min(0.5, unbounded_ns * 1e-9 / 0.5);
  options.relocalization_cpu_burst_s = unbounded_ns * 1e-9 / 5;
  std::cout << "unbounded search: " << unbounded_ns * 1e-6 << " ms of CPU; share "
            << options.relocalization_cpu_share << ", burst "
            << options.relocalization_cpu_burst_s * 1e3 << " ms\n";
  Tracker tracker(SceneMap(), nullptr, kCamera, options);
  tracker.StartWithoutPose(0);
  const int64_t period_ns = std::llround(1e9 / options.step_rate_hz);
  std::vector<PoseEstimate> estimates;
  int64_t search_cpu_ns = 0;
  int64_t longest_step_ns = 0;
  int64_t searched_until_ns = 0;
  int deferred = 0;
  int working = 0;
  int64_t deferred_cpu_ns = 0;
  int last_round = 0;
  ForEachStepWindow(events, period_ns, [&](const EventBuffer& window, int64_t) {
    const int64_t before = ThreadCpuTimeNs();
    const std::vector<PoseEstimate> step = tracker.AddEvents(window);
    const int64_t used = ThreadCpuTimeNs() - before;
    for (const PoseEstimate& estimate : step) {
      const bool searching =
          estimate.status != TrackingStatus::kTracking && estimate.search.verified_steps == 0;
      if (searching && estimate.search.deferred) {
        ++deferred;
        deferred_cpu_ns += used;
      } else if (searching) {
        ++working;
        search_cpu_ns += used;
        longest_step_ns = std::max(longest_step_ns, used);
        last_round = std::max(last_round, estimate.search.round);
      }
      if (searching) searched_until_ns = estimate.t_ns;
      estimates.push_back(estimate);
    }
    return true;
  });
  const int64_t first_tracking_ns = CheckEstimates(estimates, options);
  std::cout << "CPU share " << options.relocalization_cpu_share << ": TRACKING at "
            << first_tracking_ns * 1e-9 << " s in round " << last_round << ", " << deferred
            << " steps deferred, " << working << " working steps of " << search_cpu_ns * 1e-6
            << " ms over " << searched_until_ns * 1e-9 << " s of events (longest step "
            << longest_step_ns * 1e-6 << " ms)\n";
  ASSERT_GT(deferred, 0);
  ASSERT_GE(first_tracking_ns, 0) << "never TRACKING";
  EXPECT_EQ(tracker.status(), TrackingStatus::kTracking);
  // The budget covers the search work, not the ingestion of the step's events: a deferred step
  // is ingestion only, so its mean cost is taken off every working step.
  const double work_ns = static_cast<double>(search_cpu_ns) -
                         working * static_cast<double>(deferred_cpu_ns) / deferred;
  EXPECT_LE(work_ns,
            options.relocalization_cpu_share * static_cast<double>(searched_until_ns + period_ns) +
                options.relocalization_cpu_burst_s * 1e9 + static_cast<double>(longest_step_ns));
}

// At the hand-over the motion prior's velocity is measured on verified steps only, not from the
// accepted search pose (refined partly on distance fields built steps earlier: a centimetre of
// age over one step is decimetres per second of velocity).
TEST(TrackerSearch, VelocityAtTheHandOverComesFromVerifiedStepsOnly) {
  const EventBuffer events = SceneEvents(400'000'000);
  const TrackerOptions options;
  Tracker tracker(SceneMap(), nullptr, kCamera, options);
  tracker.StartWithoutPose(0);
  constexpr int64_t kChunkNs = 1'000'000;
  const double step_ns = 1e9 / options.step_rate_hz;
  size_t begin = 0;
  int64_t found_ns = -1;
  int checked = 0;
  for (int64_t end_ns = kChunkNs; begin < events.size() && found_ns < 0; end_ns += kChunkNs) {
    EventBuffer chunk;
    while (begin < events.size() && events.t_ns[begin] < end_ns) chunk.push_back(events[begin++]);
    const std::vector<PoseEstimate> estimates = tracker.AddEvents(chunk);
    for (const PoseEstimate& estimate : estimates) {
      if (estimate.status == TrackingStatus::kTracking) found_ns = estimate.t_ns;
    }
    // After a verification step (the tracker's state is that of the chunk's last estimate), the
    // velocity spans the verified steps alone, one step apart: none after the first.
    if (!estimates.empty() && estimates.back().status == TrackingStatus::kInitializing &&
        estimates.back().search.verified_steps > 0) {
      const int verified = estimates.back().search.verified_steps;
      EXPECT_LE(tracker.velocity_span_ns(), std::llround((verified - 1) * step_ns))
          << "after verified step " << verified;
      ++checked;
    }
  }
  ASSERT_GE(found_ns, 0) << "never TRACKING";
  ASSERT_GT(checked, 0) << "no verification step seen";
}

TEST(TrackerSearch, NeverTracksEventsOfAnUnrelatedSceneOrNoise) {
  // Another layout of rectangles (different sizes and places) seen along the same motion.
  std::vector<testing::Rectangle> other;
  for (const testing::Rectangle& rectangle : testing::DefaultRectangles()) {
    testing::Rectangle moved = rectangle;
    moved.centre = Eigen::Vector3d(-rectangle.centre.y(), rectangle.centre.x() * 0.8,
                                   rectangle.centre.z() + 0.4);
    moved.half_u = rectangle.half_v * 1.3;
    moved.half_v = rectangle.half_u * 0.7;
    other.push_back(moved);
  }
  const Map other_map = testing::MakeRectangleMap(other, 0.004);
  EventBuffer unrelated = testing::SimulateEdgeEvents(
      other_map, kCamera, [](int64_t t_ns) { return testing::SmoothMotion(t_ns); }, 0, 900'000'000);
  // Uniform noise: 2 M events per second over the sensor.
  EventBuffer noise;
  std::mt19937 random(7);
  std::uniform_int_distribution<int> x(0, 239);
  std::uniform_int_distribution<int> y(0, 179);
  for (int64_t t_ns = 0; t_ns < 900'000'000; t_ns += 500) {
    noise.push_back(Event{t_ns, static_cast<uint16_t>(x(random)), static_cast<uint16_t>(y(random)),
                          static_cast<int8_t>(t_ns % 1000 == 0 ? 1 : -1)});
  }
  for (const EventBuffer* events : {&unrelated, &noise}) {
    TrackerOptions options;
    Tracker tracker(SceneMap(), nullptr, kCamera, options);
    tracker.StartWithoutPose(0);
    const std::vector<PoseEstimate> estimates = tracker.AddEvents(*events);
    ASSERT_GT(estimates.size(), 250u);
    int rounds = 0;
    for (const PoseEstimate& estimate : estimates) {
      EXPECT_EQ(estimate.status, TrackingStatus::kInitializing) << estimate.t_ns;
      rounds = std::max(rounds, estimate.search.round);
    }
    // It kept searching (several rounds), and found nothing.
    EXPECT_GE(rounds, 3);
  }
}

TEST(TrackerSearch, RelocalizesOnItsOwnAfterABlackout) {
  const EventBuffer all = SceneEvents(900'000'000);
  constexpr int64_t kBlackoutBeginNs = 200'000'000;
  constexpr int64_t kBlackoutEndNs = 450'000'000;
  EventBuffer events;
  for (size_t i = 0; i < all.size(); ++i) {
    if (all.t_ns[i] < kBlackoutBeginNs || all.t_ns[i] >= kBlackoutEndNs) events.push_back(all[i]);
  }
  TrackerOptions options;
  Tracker tracker(SceneMap(), nullptr, kCamera, options);
  tracker.Reset(testing::SmoothMotion(50'000'000), 50'000'000);
  const std::vector<PoseEstimate> estimates = tracker.AddEvents(events);
  // The sequence of statuses, without repeats: TRACKING, LOST, RELOCALIZING, TRACKING.
  std::vector<TrackingStatus> sequence;
  for (const PoseEstimate& estimate : estimates) {
    if (sequence.empty() || sequence.back() != estimate.status) sequence.push_back(estimate.status);
  }
  const std::vector<TrackingStatus> expected = {TrackingStatus::kTracking, TrackingStatus::kLost,
                                                TrackingStatus::kRelocalizing,
                                                TrackingStatus::kTracking};
  EXPECT_EQ(sequence, expected);
  CheckEstimates(estimates, options);
  int64_t back_ns = -1;
  for (const PoseEstimate& estimate : estimates) {
    if (estimate.t_ns >= kBlackoutEndNs && estimate.status == TrackingStatus::kTracking) {
      back_ns = estimate.t_ns;
      break;
    }
  }
  ASSERT_GE(back_ns, 0);
  std::cout << "after the blackout: TRACKING " << (back_ns - kBlackoutEndNs) * 1e-9
            << " s after the events resume\n";
  // Measured: back 0.057 s after the events resume; the target is 1 s.
  EXPECT_LT(back_ns - kBlackoutEndNs, 300'000'000);
  // No round starts on the first milliseconds of the returning events: a round needs one decay
  // time of them, as at the start of a stream (on a 640x480 sequence, rounds on a few
  // milliseconds of events kept a search from finding the camera for over a second).
  const int64_t first_event_back_ns = [&] {
    for (size_t i = 0; i < events.size(); ++i) {
      if (events.t_ns[i] >= kBlackoutEndNs) return events.t_ns[i];
    }
    return int64_t{-1};
  }();
  int rounds_before = -1;
  for (const PoseEstimate& estimate : estimates) {
    if (estimate.status != TrackingStatus::kRelocalizing) continue;
    if (estimate.t_ns < first_event_back_ns + static_cast<int64_t>(options.decay_time_s * 1e9)) {
      if (rounds_before < 0) rounds_before = estimate.search.round;
      EXPECT_EQ(estimate.search.round, rounds_before) << "a round started at " << estimate.t_ns;
    }
  }
  EXPECT_GE(rounds_before, 0) << "no RELOCALIZING step in the blackout";
}

// Two identical copies of the scene 20 m apart (never in one view) with keyframes at both: the
// true pose and its copy align equally well, so no round may be accepted...
TEST(TrackerSearch, RefusesWhenTheSecondBestDistinctHypothesisIsAlmostAsGood) {
  const Eigen::Vector3d shift(20.0, 0.0, 0.0);
  Map map = MapWithKeyframes(testing::TwinRectangles(shift));
  testing::AddKeyframesBesideThePath(
      &map, kCamera, 900'000'000, 150'000'000,
      (Vector6d() << 0.06, -0.03, 0.0, 0.0, 3 * kDegree, 0).finished(), shift);
  const EventBuffer events = SceneEvents(600'000'000);

  TrackerOptions options;
  Tracker tracker(map, nullptr, kCamera, options);
  tracker.StartWithoutPose(0);
  const std::vector<PoseEstimate> estimates = tracker.AddEvents(events);
  int judged = 0;
  for (const PoseEstimate& estimate : estimates) {
    EXPECT_EQ(estimate.status, TrackingStatus::kInitializing) << estimate.t_ns;
    if (estimate.search.best_alignment > 0) {
      ++judged;
      // The best and the second best (the twin) are both good and nearly equal.
      EXPECT_GE(estimate.search.best_alignment, options.min_alignment);
      EXPECT_LT(estimate.search.best_alignment - estimate.search.second_alignment,
                options.relocalization_min_alignment_margin);
    }
  }
  EXPECT_GT(judged, 0);

  // ...without the margin the same search does accept one of the two (so it is the margin that
  // refused them)...
  TrackerOptions no_margin = options;
  no_margin.relocalization_min_alignment_margin = 0;
  Tracker accepting(map, nullptr, kCamera, no_margin);
  accepting.StartWithoutPose(0);
  int tracking = 0;
  for (const PoseEstimate& estimate : accepting.AddEvents(events)) {
    tracking += estimate.status == TrackingStatus::kTracking ? 1 : 0;
  }
  EXPECT_GT(tracking, 0);

  // ...and a search prior around one copy removes the ambiguity: found, at the right copy.
  Tracker with_prior(map, nullptr, kCamera, options);
  with_prior.SetSearchPrior(testing::SmoothMotion(0).translation, 1.0);
  with_prior.StartWithoutPose(0);
  const int64_t first_tracking_ns = CheckEstimates(with_prior.AddEvents(events), options);
  EXPECT_GE(first_tracking_ns, 0);
}

// The same scene and path ten times as large (depths 15-35 m, the events the same images), its
// map points off by 0.2 m (a built map's noise): registration then pins a pose down only to a
// fraction of the depth, and the refinements of one round that all converge on the truth lie
// decimetres apart. Judged against a fixed 5 cm they were each other's rivals and every round
// was refused as ambiguous (as the car park of docs/accuracy.md with a GNSS prior); against 2 %
// of the depth they are one place, and the search finds the camera within 0.3 s.
constexpr double kLargeScale = 10.0;

Rigid3d LargeMotion(int64_t t_ns) {
  Rigid3d world_from_cam = testing::SmoothMotion(t_ns);
  world_from_cam.translation *= kLargeScale;
  return world_from_cam;
}

struct LargeScene {
  Map map;
  EventBuffer events;
};

const LargeScene& NoisyLargeScene() {
  static const LargeScene scene = [] {
    std::vector<testing::Rectangle> rectangles = testing::DefaultRectangles();
    for (testing::Rectangle& rectangle : rectangles) {
      rectangle.centre *= kLargeScale;
      rectangle.half_u *= kLargeScale;
      rectangle.half_v *= kLargeScale;
    }
    LargeScene large;
    large.map = testing::MakeRectangleMap(rectangles, 0.004 * kLargeScale);
    large.map.cameras.push_back(kCamera);
    for (int64_t t_ns = 0; t_ns <= 900'000'000; t_ns += 150'000'000) {
      Rigid3d world_from_cam =
          testing::SmoothMotion(t_ns) *
          ExpSE3((Vector6d() << 0.06, -0.03, 0.0, 0.0, 3 * kDegree, 0).finished());
      world_from_cam.translation *= kLargeScale;
      Keyframe keyframe;
      keyframe.cam_from_world = world_from_cam.Inverse();
      keyframe.t_ns = t_ns;
      large.map.keyframes.push_back(keyframe);
    }
    large.events = testing::SimulateEdgeEvents(large.map, kCamera, LargeMotion, 0, 600'000'000);
    std::mt19937 random(7);
    std::normal_distribution<float> noise(0.0f, 0.2f);
    for (Eigen::Vector3f& position : large.map.positions) {
      position += Eigen::Vector3f(noise(random), noise(random), noise(random));
    }
    return large;
  }();
  return scene;
}

// The search's probes around a pose it did not judge (a hand-over's return from an odometry
// hint): around a pose of the rectangle scene, which every probe registers back to, the fit is
// unique; on a wall of long horizontal bars, a shift along them fits as well; and the
// check leaves the tracking as it was.
TEST(TrackerSearch, ProbesOfTheLastPoseTellAUniqueFitFromAnAmbiguousOne) {
  constexpr int64_t kCheckNs = 300'000'000;
  const EventBuffer all = SceneEvents(600'000'000);
  EventBuffer before;
  EventBuffer after;
  for (size_t i = 0; i < all.size(); ++i) {
    (all.t_ns[i] < kCheckNs ? before : after).push_back(all[i]);
  }
  TrackerOptions options;
  Tracker checked(SceneMap(), nullptr, kCamera, options);
  Tracker unchecked(SceneMap(), nullptr, kCamera, options);
  checked.Reset(testing::SmoothMotion(0), 0);
  unchecked.Reset(testing::SmoothMotion(0), 0);
  const std::vector<PoseEstimate> first = checked.AddEvents(before);
  unchecked.AddEvents(before);
  ASSERT_FALSE(first.empty());
  ASSERT_EQ(first.back().status, TrackingStatus::kTracking);
  const Tracker::ProbeCheck check = checked.ProbeLastPose();
  std::cout << "rectangle scene: alignment " << check.alignment << ", best distinct probe "
            << check.distinct_alignment << " of " << check.probes << " probes\n";
  EXPECT_EQ(check.probes, 6);
  EXPECT_GE(check.alignment, options.min_alignment);
  EXPECT_TRUE(check.unique);
  // The same poses after the check as without it.
  const std::vector<PoseEstimate> checked_after = checked.AddEvents(after);
  const std::vector<PoseEstimate> unchecked_after = unchecked.AddEvents(after);
  ASSERT_EQ(checked_after.size(), unchecked_after.size());
  ASSERT_FALSE(checked_after.empty());
  for (size_t i = 0; i < checked_after.size(); ++i) {
    EXPECT_EQ(checked_after[i].world_from_cam.translation,
              unchecked_after[i].world_from_cam.translation)
        << i;
    EXPECT_EQ(checked_after[i].world_from_cam.rotation.coeffs(),
              unchecked_after[i].world_from_cam.rotation.coeffs())
        << i;
  }

  // Long horizontal bars across the whole view (a wall of stripes): sliding along them changes
  // nothing the events see.
  std::vector<testing::Rectangle> bars;
  for (int i = -2; i <= 2; ++i) {
    bars.push_back(
        {{0.0, 0.35 * i, 5.0}, Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), 10.0, 0.07});
  }
  const Map flat = testing::MakeRectangleMap(bars, 0.01);
  const EventBuffer flat_events = testing::SimulateEdgeEvents(
      flat, kCamera, [](int64_t t_ns) { return testing::SmoothMotion(t_ns, 0.3); }, 0, kCheckNs);
  Tracker on_flat(flat, nullptr, kCamera, options);
  on_flat.Reset(testing::SmoothMotion(0, 0.3), 0);
  const std::vector<PoseEstimate> flat_estimates = on_flat.AddEvents(flat_events);
  ASSERT_FALSE(flat_estimates.empty());
  ASSERT_EQ(flat_estimates.back().status, TrackingStatus::kTracking);
  const Tracker::ProbeCheck flat_check = on_flat.ProbeLastPose();
  std::cout << "horizontal bars: alignment " << flat_check.alignment << ", best distinct probe "
            << flat_check.distinct_alignment << " of " << flat_check.probes << " probes\n";
  EXPECT_GE(flat_check.alignment, options.min_alignment);
  EXPECT_FALSE(flat_check.unique);
}

// A hand-over's search (docs/tracking.md, "Hand-over"): the map's keyframes all face 25 degrees
// away from where the camera looks, beyond what the search's turns and refinement reach, so
// from the keyframes alone it never finds the camera. An odometry hint that drifted 25 cm but
// only 1.5 degrees lends its orientation to the keyframes' positions, and the search finds the
// camera, every TRACKING pose right.
TEST(TrackerSearch, AHintsOrientationReachesWhereTheKeyframesFaceAway) {
  constexpr int64_t kEndNs = 600'000'000;
  constexpr int64_t kHintPeriodNs = 50'000'000;
  const Map map =
      MapWithKeyframes(testing::DefaultRectangles(), Eigen::Vector3d::Zero(),
                       (Vector6d() << 0.06, -0.03, 0.0, 0.0, 25 * kDegree, 0).finished());
  const EventBuffer events = testing::SimulateEdgeEvents(
      map, kCamera, [](int64_t t_ns) { return testing::SmoothMotion(t_ns); }, 0, kEndNs);
  const Vector6d drift = (Vector6d() << 0.2, -0.1, 0.1, 1.5 * kDegree, 0.0, 0.0).finished();
  const TrackerOptions options;
  // Events in the hand-over's probe intervals; before each, the prior (and the hint) follow the
  // drifted odometry.
  auto search = [&](bool with_hint) {
    Tracker tracker(map, nullptr, kCamera, options);
    tracker.StartWithoutPose(0);
    std::vector<PoseEstimate> estimates;
    for (int64_t t_ns = 0; t_ns < kEndNs; t_ns += kHintPeriodNs) {
      const Rigid3d odometry = testing::SmoothMotion(t_ns) * ExpSE3(drift);
      tracker.SetSearchPrior(odometry.translation, 0.5);
      if (with_hint) tracker.SetSearchHint(odometry);
      for (const PoseEstimate& estimate :
           tracker.AddEvents(testing::EventsBetween(events, t_ns, t_ns + kHintPeriodNs - 1))) {
        estimates.push_back(estimate);
      }
    }
    return estimates;
  };
  EXPECT_LT(CheckEstimates(search(false), options), 0) << "found from the keyframes alone";
  const std::vector<PoseEstimate> estimates = search(true);
  const int64_t first_tracking_ns = CheckEstimates(estimates, options);
  ASSERT_GE(first_tracking_ns, 0) << "never TRACKING with the hint";
  std::cout << "keyframes facing away, with the hint's orientation: TRACKING at "
            << first_tracking_ns * 1e-9 << " s\n";
  EXPECT_EQ(estimates.back().status, TrackingStatus::kTracking);
}

TEST(TrackerSearch, AtTensOfMetresRefinementsOfOnePlaceAreNotRivals) {
  const Map& map = NoisyLargeScene().map;
  const EventBuffer& events = NoisyLargeScene().events;
  const auto large_motion = LargeMotion;

  // The first TRACKING time (-1: never) and the largest TRACKING position error.
  const auto search = [&](const TrackerOptions& options, double* worst_m) {
    Tracker tracker(map, nullptr, kCamera, options);
    tracker.SetSearchPrior(large_motion(0).translation, 10.0);
    tracker.StartWithoutPose(0);
    int64_t first_ns = -1;
    *worst_m = 0;
    for (const PoseEstimate& estimate : tracker.AddEvents(events)) {
      if (estimate.status != TrackingStatus::kTracking) continue;
      if (first_ns < 0) first_ns = estimate.t_ns;
      *worst_m = std::max(
          *worst_m,
          (estimate.world_from_cam.translation - large_motion(estimate.t_ns).translation).norm());
    }
    return first_ns;
  };
  const TrackerOptions options;
  double worst_m = 0;
  const int64_t found_ns = search(options, &worst_m);
  std::cout << "ten times as large, noisy map: TRACKING at " << found_ns * 1e-9
            << " s, largest error " << worst_m << " m\n";
  ASSERT_GE(found_ns, 0) << "never TRACKING";
  EXPECT_LT(found_ns, 300'000'000);
  EXPECT_LT(worst_m, 1.0);  // 4 % of the median depth

  TrackerOptions fixed = options;
  fixed.relocalization_distinct_depth_fraction = 0;
  EXPECT_LT(search(fixed, &worst_m), 0) << "a fixed 5 cm no longer refuses: the test shows nothing";
}

// At range a found pose is verified over a time that grows with the depth it sees
// (relocalization_verify_s_per_depth_m): one instant of events fixes a pose along the optical
// axis only to a few percent of that depth, and a camera moving along it shows a pose found that
// far behind only once it has moved on. On the large scene (median depth about 25 m) the
// window lasts at least 0.005 s per metre and the pose that ends it is still right; without the
// term it is the 10 steps.
TEST(TrackerSearch, AtRangeTheVerificationLastsLongerTheDeeperThePlace) {
  const Map& map = NoisyLargeScene().map;
  const EventBuffer& events = NoisyLargeScene().events;
  // The verification window (first good verification step to the first TRACKING step) in steps
  // and seconds, and the first TRACKING pose's error; false when never TRACKING.
  struct Window {
    int steps = 0;
    double seconds = 0;
    double error_m = 0;
  };
  const auto verify = [&](const TrackerOptions& options, Window* window) {
    Tracker tracker(map, nullptr, kCamera, options);
    tracker.SetSearchPrior(LargeMotion(0).translation, 10.0);
    tracker.StartWithoutPose(0);
    int64_t start_ns = -1;
    for (const PoseEstimate& estimate : tracker.AddEvents(events)) {
      if (estimate.search.verified_steps == 1 && estimate.status != TrackingStatus::kTracking) {
        start_ns = estimate.t_ns;
      }
      if (estimate.status == TrackingStatus::kTracking) {
        window->steps = estimate.search.verified_steps;
        window->seconds = static_cast<double>(estimate.t_ns - start_ns) * 1e-9;
        window->error_m =
            (estimate.world_from_cam.translation - LargeMotion(estimate.t_ns).translation).norm();
        return start_ns >= 0;
      }
    }
    return false;
  };
  TrackerOptions options;  // 300 Hz steps
  Window deep;
  ASSERT_TRUE(verify(options, &deep)) << "never TRACKING";
  std::cout << "verified over " << deep.steps << " steps, " << deep.seconds << " s; error "
            << deep.error_m << " m\n";
  // 0.005 s/m at 15-35 m of depth: 0.075-0.175 s, 22-53 steps at 300 Hz.
  EXPECT_GE(deep.seconds, 0.075);
  EXPECT_GT(deep.steps, options.relocalization_verify_steps);
  EXPECT_LT(deep.error_m, 1.0);

  options.relocalization_verify_s_per_depth_m = 0;
  Window steps_only;
  ASSERT_TRUE(verify(options, &steps_only)) << "never TRACKING";
  EXPECT_EQ(steps_only.steps, options.relocalization_verify_steps);
  EXPECT_LT(steps_only.seconds, 0.04);
}

// The motion prior (TrackerOptions::motion_prior_velocity_sigma_mps) on the same scene, tracked
// from the true start pose: at 15-35 m through a map 0.2 m off, one step's events fix the pose to
// decimetres, and each pose jumps by that from the next (the second difference of the positions,
// which for this smooth path is under a millimetre). The prediction along the smooth velocity,
// trusted to 3 m/s (1 cm per 300 Hz step), steadies the track and keeps it closer.
TEST(TrackerMotionPrior, AtRangeItSteadiesTheTrackAndKeepsItCloser) {
  const Map& map = NoisyLargeScene().map;
  const EventBuffer& events = NoisyLargeScene().events;
  struct Track {
    double ate_m = 0;
    double jitter_m = 0;  // RMS second difference of the position errors
    int tracking = 0;
  };
  const auto track = [&](double sigma_mps) {
    TrackerOptions options;
    options.motion_prior_velocity_sigma_mps = sigma_mps;
    Tracker tracker(map, nullptr, kCamera, options);
    tracker.Reset(LargeMotion(0), 0);
    std::vector<Eigen::Vector3d> errors;
    double squared = 0;
    double jitter_squared = 0;
    int jitter_terms = 0;
    for (const PoseEstimate& estimate : tracker.AddEvents(events)) {
      EXPECT_EQ(estimate.status, TrackingStatus::kTracking) << estimate.t_ns;
      if (estimate.status != TrackingStatus::kTracking) continue;
      errors.push_back(estimate.world_from_cam.translation -
                       LargeMotion(estimate.t_ns).translation);
      squared += errors.back().squaredNorm();
      if (errors.size() >= 3) {
        const size_t n = errors.size();
        jitter_squared += (errors[n - 1] - 2 * errors[n - 2] + errors[n - 3]).squaredNorm();
        ++jitter_terms;
      }
    }
    Track result;
    result.tracking = static_cast<int>(errors.size());
    result.ate_m = std::sqrt(squared / std::max<size_t>(errors.size(), 1));
    result.jitter_m = std::sqrt(jitter_squared / std::max(jitter_terms, 1));
    return result;
  };
  const Track without = track(0.0);
  const Track with = track(3.0);
  std::cout << "motion prior off: ATE " << without.ate_m << " m, jitter " << without.jitter_m
            << " m; 3 m/s: ATE " << with.ate_m << " m, jitter " << with.jitter_m << " m\n";
  ASSERT_GE(without.tracking, 150);
  ASSERT_EQ(with.tracking, without.tracking);
  // Measured: jitter 0.205 -> 0.084 m, ATE 0.363 -> 0.251 m.
  EXPECT_LT(with.jitter_m, 0.6 * without.jitter_m);
  EXPECT_LT(with.ate_m, 0.9 * without.ate_m);
}

// The rectangle map with keyframes on a pass 0.78 m and 20 degrees from the events' path: beyond
// the reach of the search's own hypotheses (a 0.2 m grid and 8-degree turns around them).
const Map& FarMap() {
  static const Map map =
      MapWithKeyframes(testing::DefaultRectangles(), Eigen::Vector3d::Zero(),
                       (Vector6d() << 0.6, -0.4, 0.3, 0.0, 20 * kDegree, 0).finished());
  return map;
}

// An image source that "locates" each image at the true pose of its time displaced by `offset`
// (a located image of events is a few centimetres off), counting its calls.
class TruthImageSource final : public ImageHypothesisSource {
 public:
  explicit TruthImageSource(const Vector6d& offset) : offset_(offset) {}
  std::vector<Rigid3d> Hypotheses(const cv::Mat& image, int64_t t_ns) const override {
    ++calls;
    if (image.type() != CV_8UC1 || image.cols != kCamera.width || image.rows != kCamera.height) {
      ++bad_images;
    }
    return {testing::SmoothMotion(t_ns) * ExpSE3(offset_)};
  }
  mutable std::atomic<int> calls{0};
  mutable std::atomic<int> bad_images{0};

 private:
  Vector6d offset_;
};

// A tracker on the far map that asks `source` (which must outlive it) for image hypotheses,
// started without a pose.
std::unique_ptr<Tracker> FarMapTracker(const TrackerOptions& options,
                                       const ImageHypothesisSource& source) {
  auto tracker = std::make_unique<Tracker>(FarMap(), nullptr, kCamera, options);
  tracker->SetImageHypothesisSource(&source);
  tracker->StartWithoutPose(0);
  return tracker;
}

int ImageHypothesesRefined(const std::vector<PoseEstimate>& estimates) {
  int total = 0;
  for (const PoseEstimate& estimate : estimates) total += estimate.search.image_hypotheses;
  return total;
}

TEST(TrackerSearch, ImageHypothesesReachWhereTheMapsViewpointsDoNot) {
  const EventBuffer events = SceneEvents(900'000'000);
  const TrackerOptions options;
  // Without image hypotheses the far map's viewpoints do not reach the events' path...
  Tracker alone(FarMap(), nullptr, kCamera, options);
  alone.StartWithoutPose(0);
  EXPECT_LT(CheckEstimates(alone.AddEvents(events), options), 0) << "found without images";
  // ...with images located 2 cm and 1 degree off the truth, it is found, and every TRACKING pose
  // is right.
  const TruthImageSource source((Vector6d() << 0.02, 0.0, -0.01, 0.0, 0.0, kDegree).finished());
  const std::unique_ptr<Tracker> tracker = FarMapTracker(options, source);
  const std::vector<PoseEstimate> estimates = tracker->AddEvents(events);
  const int64_t first_tracking_ns = CheckEstimates(estimates, options);
  ASSERT_GE(first_tracking_ns, 0) << "never TRACKING";
  std::cout << "far map with image hypotheses: TRACKING at " << first_tracking_ns * 1e-9 << " s, "
            << source.calls << " image requests\n";
  // The first request needs relocalization_image_min_events_s (0.15 s) of events, then one
  // round and the verification.
  EXPECT_LT(first_tracking_ns, 400'000'000);
  EXPECT_GT(ImageHypothesesRefined(estimates), 0);
  EXPECT_EQ(source.bad_images, 0);
  EXPECT_EQ(tracker->status(), TrackingStatus::kTracking);
}

TEST(TrackerSearch, WrongImageHypothesesNeverGiveAWrongTrackingPose) {
  const EventBuffer events = SceneEvents(900'000'000);
  const TrackerOptions options;
  // 25 cm and 10 degrees off: refined, judged, and never a TRACKING pose beyond 5 cm / 3 degrees.
  const TruthImageSource source((Vector6d() << 0.25, -0.1, 0.1, 0.0, 10 * kDegree, 0).finished());
  const std::unique_ptr<Tracker> tracker = FarMapTracker(options, source);
  const std::vector<PoseEstimate> estimates = tracker->AddEvents(events);
  CheckEstimates(estimates, options);
  EXPECT_GT(ImageHypothesesRefined(estimates), 0);
}

// With a CPU share the image request still runs in the step that asked, so its poses are of that
// step's instant (taken at a later round, on a thread of their own, they were as old as the round
// took, and on the 640x480 far path the search never found the camera; docs/relocalization.md).
TEST(TrackerSearch, WithACpuShareImageHypothesesAreRefinedAtTheirOwnInstant) {
  const EventBuffer events = SceneEvents(900'000'000);
  TrackerOptions options;
  options.relocalization_cpu_share = 0.5;
  const TruthImageSource source((Vector6d() << 0.02, 0.0, -0.01, 0.0, 0.0, kDegree).finished());
  const std::unique_ptr<Tracker> tracker = FarMapTracker(options, source);
  // One step's events at a time, as a live session gets them.
  const int64_t period_ns = std::llround(1e9 / options.step_rate_hz);
  std::vector<PoseEstimate> estimates;
  ForEachStepWindow(events, period_ns, [&](const EventBuffer& window, int64_t) {
    for (PoseEstimate& estimate : tracker->AddEvents(window)) estimates.push_back(estimate);
    return true;
  });
  EXPECT_GE(CheckEstimates(estimates, options), 0) << "never TRACKING";
  EXPECT_GT(source.calls, 0);
  EXPECT_GT(ImageHypothesesRefined(estimates), 0);
}

// A round that spans hundreds of milliseconds of events (here: one coarse alignment per step,
// 0.3 s; in a live session, a CPU share and packets thinned while it is behind) must not accept
// its best refinement as it was when refined: the camera has moved on, and the verification
// would start from a pose that no longer registers. The best refinement follows the camera on
// every step of the round (FollowBestRefinement), so the round that located the image is the
// one that verifies it.
TEST(TrackerSearch, TheBestRefinementFollowsTheCameraThroughALongRound) {
  const EventBuffer events = SceneEvents(1'500'000'000);
  TrackerOptions options;
  options.relocalization_coarse_per_step = 1;
  const TruthImageSource source((Vector6d() << 0.02, 0.0, -0.01, 0.0, 0.0, kDegree).finished());
  const std::unique_ptr<Tracker> tracker = FarMapTracker(options, source);
  const std::vector<PoseEstimate> estimates = tracker->AddEvents(events);
  const int64_t first_tracking_ns = CheckEstimates(estimates, options);
  ASSERT_GE(first_tracking_ns, 0) << "never TRACKING";
  int first_image_round = -1;
  int64_t first_image_ns = -1;
  int tracking_round = -1;
  int followed = 0;
  for (const PoseEstimate& estimate : estimates) {
    if (first_image_round < 0 && estimate.search.image_hypotheses > 0) {
      first_image_round = estimate.search.round;
      first_image_ns = estimate.t_ns;
    }
    if (tracking_round < 0 && estimate.status == TrackingStatus::kTracking) {
      tracking_round = estimate.search.round;
    }
    followed += estimate.search.followed ? 1 : 0;
  }
  std::cout << "long round: image located at " << first_image_ns * 1e-9 << " s in round "
            << first_image_round << ", TRACKING at " << first_tracking_ns * 1e-9 << " s in round "
            << tracking_round << ", " << followed << " steps followed\n";
  ASSERT_GE(first_image_round, 1);
  EXPECT_EQ(tracking_round, first_image_round);
  // The round lasted more than 0.2 s after the image's step.
  EXPECT_GT(first_tracking_ns - first_image_ns, 200'000'000);
  EXPECT_GT(followed, 50);
}

// A silence in the middle of the verification (a live session's queue dropped packets, a
// blackout): the steps in it and the first decay time of returning events do not count, and the
// window starts again, aligned afresh, once the surfaces are full. Before, the steps in the
// silence counted although they saw no new event (the same old events again), and with a
// silence longer than the surfaces keep an event they ran on empty surfaces, failed, and the
// search began a new round (the 640x480 service run, docs/relocalization.md).
TEST(TrackerSearch, ASilenceInTheVerificationIsWaitedOut) {
  const EventBuffer events = SceneEvents(900'000'000);
  TrackerOptions options;
  Tracker tracker(SceneMap(), nullptr, kCamera, options);
  tracker.StartWithoutPose(0);
  const int64_t period_ns = std::llround(1e9 / options.step_rate_hz);
  constexpr int64_t kSilenceNs = 40'000'000;
  std::vector<PoseEstimate> estimates;
  int64_t silence_begin_ns = -1;
  ForEachStepWindow(events, period_ns, [&](const EventBuffer& window, int64_t end_ns) {
    if (silence_begin_ns >= 0 && end_ns <= silence_begin_ns + kSilenceNs) {
      return true;  // the silence: these events never arrive
    }
    for (PoseEstimate& estimate : tracker.AddEvents(window)) {
      if (silence_begin_ns < 0 && estimate.search.verified_steps >= 3) {
        silence_begin_ns = end_ns;
      }
      estimates.push_back(estimate);
    }
    return true;
  });
  ASSERT_GE(silence_begin_ns, 0) << "no verification";
  const int64_t first_tracking_ns = CheckEstimates(estimates, options);
  ASSERT_GE(first_tracking_ns, 0) << "never TRACKING";
  int round_before = -1;
  int waited = 0;
  for (const PoseEstimate& estimate : estimates) {
    if (estimate.t_ns <= silence_begin_ns) round_before = estimate.search.round;
    // In the silence and one decay time after it no verification step counts.
    const bool in_silence = estimate.t_ns > silence_begin_ns + 15'000'000 &&
                            estimate.t_ns < silence_begin_ns + kSilenceNs +
                                                static_cast<int64_t>(options.decay_time_s * 1e9);
    if (in_silence && estimate.status != TrackingStatus::kTracking) {
      EXPECT_TRUE(estimate.search.refilling) << estimate.t_ns;
      EXPECT_EQ(estimate.search.verified_steps, 0) << estimate.t_ns;
      ++waited;
    }
  }
  std::cout << "silence in the verification at " << silence_begin_ns * 1e-9 << " s: " << waited
            << " steps waited, TRACKING at " << first_tracking_ns * 1e-9 << " s\n";
  EXPECT_GT(waited, 10);
  // Found by the same round, without a new one.
  for (const PoseEstimate& estimate : estimates) {
    if (estimate.status == TrackingStatus::kTracking) {
      EXPECT_EQ(estimate.search.round, round_before);
      break;
    }
  }
}

TEST(TrackerSearch, RejectsABadPriorAndFrameTrackers) {
  Tracker tracker(SceneMap(), nullptr, kCamera, TrackerOptions());
  EXPECT_THROW(tracker.SetSearchPrior(Eigen::Vector3d::Zero(), 0.0), InvalidArgumentError);
  EXPECT_THROW(tracker.SetSearchPrior(Eigen::Vector3d::Constant(NAN), 1.0), InvalidArgumentError);
  TrackerOptions frames;
  frames.input = TrackerInput::kFrames;
  Tracker frame_tracker(SceneMap(), nullptr, kCamera, frames);
  EXPECT_THROW(frame_tracker.StartWithoutPose(0), InvalidArgumentError);
  const TruthImageSource source(Vector6d::Zero());
  EXPECT_THROW(frame_tracker.SetImageHypothesisSource(&source), InvalidArgumentError);
  TrackerOptions bad;
  bad.relocalization_verify_steps = 0;
  EXPECT_THROW(bad.Check(), InvalidArgumentError);
  for (const double value : {-0.1, 1.5, std::nan("")}) {
    TrackerOptions bad_alignment;
    bad_alignment.relocalization_verify_min_alignment = value;
    EXPECT_THROW(bad_alignment.Check(), InvalidArgumentError) << value;
  }
  TrackerOptions bad_tau;
  bad_tau.relocalization_image_tau_s = 0;
  EXPECT_THROW(bad_tau.Check(), InvalidArgumentError);
  TrackerOptions bad_interval;
  bad_interval.relocalization_image_interval_s = -1;
  EXPECT_THROW(bad_interval.Check(), InvalidArgumentError);
  for (const double value : {-0.5, 11.0, std::nan("")}) {
    TrackerOptions bad_blur;
    bad_blur.relocalization_image_blur_px = value;
    EXPECT_THROW(bad_blur.Check(), InvalidArgumentError) << value;
  }
  for (const double value : {-0.01, 0.6, std::nan("")}) {
    TrackerOptions bad_probe;
    bad_probe.relocalization_probe_depth_fraction = value;
    EXPECT_THROW(bad_probe.Check(), InvalidArgumentError) << value;
  }
  for (const double value : {-0.01, 1.5, std::nan("")}) {
    TrackerOptions bad_margin;
    bad_margin.relocalization_probe_margin = value;
    EXPECT_THROW(bad_margin.Check(), InvalidArgumentError) << value;
  }
}

TEST(StaticMapSource, GivesKeyframesAndViewpointsBetweenThemWithinThePrior) {
  const Map& map = SceneMap();
  const StaticMapSource source(map);
  std::vector<Rigid3d> viewpoints;
  ViewpointQuery query;
  query.samples_between_keyframes = 2;
  source.CandidateViewpoints(query, &viewpoints);
  const size_t keyframes = map.keyframes.size();
  ASSERT_EQ(viewpoints.size(), keyframes + 2 * (keyframes - 1));
  EXPECT_TRUE(
      viewpoints[0].translation.isApprox(map.keyframes[0].cam_from_world.Inverse().translation));
  EXPECT_TRUE(
      viewpoints[3].translation.isApprox(map.keyframes[1].cam_from_world.Inverse().translation));
  query.search_center = viewpoints[0].translation;
  query.search_radius_m = 1e-6;
  source.CandidateViewpoints(query, &viewpoints);
  EXPECT_EQ(viewpoints.size(), 1u);
}

// A search whose source changes while a round runs drops the round (its pre-score points index
// the old points) and asks the source for viewpoints again: swapped mid-round to the scene moved
// 5 m along x, it finds the camera 5 m along x. (Keeping the episode's viewpoints, it searched
// the old place in the new points and never found it.)
TEST(TrackerSearch, ASourceChangedMidRoundIsSearchedAfresh) {
  const EventBuffer events = SceneEvents(800'000'000);
  const Eigen::Vector3f shift(5, 0, 0);
  Map moved = SceneMap();
  for (Eigen::Vector3f& position : moved.positions) position += shift;
  for (Keyframe& keyframe : moved.keyframes) {
    keyframe.cam_from_world =
        keyframe.cam_from_world * Rigid3d(Eigen::Quaterniond::Identity(), -shift.cast<double>());
  }
  testing::SwappingMapSource source(&SceneMap());
  TrackerOptions options;
  Tracker tracker(source, kCamera, options);
  tracker.StartWithoutPose(0);
  const int64_t period_ns = std::llround(1e9 / options.step_rate_hz);
  bool swapped = false;
  int64_t swap_ns = -1;
  int tracking = 0;
  for (int64_t t_ns = 0; t_ns < 800'000'000; t_ns += period_ns) {
    for (const PoseEstimate& estimate :
         tracker.AddEvents(testing::EventsBetween(events, t_ns - period_ns, t_ns))) {
      if (!swapped) {
        ASSERT_NE(estimate.status, TrackingStatus::kTracking) << "found before the swap";
        if (estimate.search.prescored > 0) {
          source.Swap(&moved);
          swapped = true;
          swap_ns = estimate.t_ns;
        }
        continue;
      }
      if (estimate.status != TrackingStatus::kTracking) continue;
      ++tracking;
      Rigid3d truth = testing::SmoothMotion(estimate.t_ns);
      truth.translation += shift.cast<double>();
      EXPECT_LT((estimate.world_from_cam.translation - truth.translation).norm(), 0.05)
          << estimate.t_ns;
    }
  }
  ASSERT_TRUE(swapped);
  std::cout << "swapped at " << swap_ns * 1e-9 << " s; " << tracking
            << " TRACKING steps in the moved scene\n";
  EXPECT_GT(tracking, 50);
}

// A search prior that arrives while a round pre-scores (a GNSS receiver's fix every second)
// takes effect at the next round and does not stall the one in progress: the camera is found,
// every second's fix refreshing the prior. (Clearing the viewpoints under the round left it
// pre-scoring forever.)
TEST(TrackerSearch, APriorSetDuringARoundTakesEffectAtTheNextOne) {
  const EventBuffer events = SceneEvents(800'000'000);
  TrackerOptions options;
  // A few viewpoints per step, so that the round is still pre-scoring when the prior comes.
  options.relocalization_prescores_per_step = 1;
  Tracker tracker(SceneMap(), nullptr, kCamera, options);
  tracker.StartWithoutPose(0);
  const int64_t period_ns = std::llround(1e9 / options.step_rate_hz);
  int priors = 0;
  int64_t first_tracking_ns = -1;
  for (int64_t t_ns = 0; t_ns < 800'000'000; t_ns += period_ns) {
    for (const PoseEstimate& estimate :
         tracker.AddEvents(testing::EventsBetween(events, t_ns - period_ns, t_ns))) {
      if (estimate.status == TrackingStatus::kTracking) {
        if (first_tracking_ns < 0) first_tracking_ns = estimate.t_ns;
        EXPECT_LT(PositionError(estimate), 0.05) << estimate.t_ns;
      } else if (estimate.search.prescored > 0) {
        // Mid-round, around the true position (as a fix would be), once per pre-scoring step.
        tracker.SetSearchPrior(testing::SmoothMotion(estimate.t_ns).translation, 1.0);
        ++priors;
      }
    }
  }
  std::cout << priors << " priors set while pre-scoring; TRACKING from " << first_tracking_ns * 1e-9
            << " s\n";
  EXPECT_GT(priors, 1);
  ASSERT_GE(first_tracking_ns, 0) << "never TRACKING";
  EXPECT_LT(first_tracking_ns, 600'000'000);
}

}  // namespace
}  // namespace evloc::tracking
