#include "localizer/tracking/pose_time.h"

#include <algorithm>
#include <random>

#include <gtest/gtest.h>

#include "core/camera/camera.h"
#include "core/camera/undistortion_table.h"

namespace evloc::tracking {
namespace {

TEST(WeightedMedian, EqualsTheCumulativeWeightDefinition) {
  std::mt19937 random(7);
  std::uniform_int_distribution<int64_t> value(0, 50);
  std::uniform_real_distribution<double> weight(0.01, 3.0);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<std::pair<int64_t, double>> samples(1 + trial % 37);
    for (auto& sample : samples) sample = {value(random), weight(random)};
    std::vector<std::pair<int64_t, double>> sorted = samples;
    std::sort(sorted.begin(), sorted.end());
    double total = 0;
    for (const auto& sample : sorted) total += sample.second;
    int64_t expected = sorted.back().first;
    double running = 0;
    for (const auto& sample : sorted) {
      running += sample.second;
      if (running >= 0.5 * total) {
        expected = sample.first;
        break;
      }
    }
    EXPECT_EQ(WeightedMedian(&samples), expected) << trial;
  }
  std::vector<std::pair<int64_t, double>> none;
  EXPECT_EQ(WeightedMedian(&none), 0);
  // A heavy sample outweighs many light ones.
  std::vector<std::pair<int64_t, double>> heavy = {{1, 1}, {2, 1}, {3, 1}, {9, 10}};
  EXPECT_EQ(WeightedMedian(&heavy), 9);
}

// A camera translating along x at 0.5 m/s past points on a plane 2 m ahead (f = 100 px: 25 px/s
// of image motion to the left). Each point's cell holds events of known ages.
TEST(MeasureSurfaceAge, BlendsTheAgesOfTheActivePixelsOfEachPointsCellWeightedBySpeed) {
  const Camera camera = Camera::Pinhole(64, 48, 100, 100, 31.5, 23.5);
  const UndistortionTable table(camera);
  TimeSurface surface(table);
  const PinholeIntrinsics intrinsics = PinholeIntrinsics::FromCamera(camera);
  const int64_t t_ns = 1'000'000'000;
  // Point A projects to (10.25, 20): pixel (10, 20) fired 4 ms ago, (11, 20) 8 ms ago, the row
  // below never: the blend is (0.75 * 4 + 0.25 * 8) / 1 = 5 ms.
  // Point B projects to (40.5, 30.5): only (40, 30) fired, 2 ms ago: weight 0.25, not more than
  // the least, so B does not count.
  const std::vector<Eigen::Vector3f> positions = {
      Eigen::Vector3f((10.25f - 31.5f) / 100 * 2, (20 - 23.5f) / 100 * 2, 2),
      Eigen::Vector3f((40.5f - 31.5f) / 100 * 2, (30.5f - 23.5f) / 100 * 2, 2)};
  EventBuffer events;
  events.push_back({t_ns - 8'000'000, 11, 20, 1});
  events.push_back({t_ns - 4'000'000, 10, 20, 1});
  events.push_back({t_ns - 2'000'000, 40, 30, -1});
  surface.Insert(events, 0, events.size());
  const SurfaceDecay decay{10e6, 0.1};  // Active up to 23 ms.
  Vector6d velocity = Vector6d::Zero();
  velocity(0) = 0.5;
  std::vector<std::pair<int64_t, double>> scratch;
  const std::vector<uint32_t> both = {0, 1};
  SurfaceAge age = MeasureSurfaceAge(surface, SurfaceChannel::kAll, decay, t_ns, intrinsics,
                                     Rigid3d(), velocity, positions, both, &scratch);
  EXPECT_EQ(age.points, 1);
  // The float positions project within 1e-5 px of the intended pixels.
  EXPECT_NEAR(age.age_ns, 5'000'000, 100);
  // The ON channel holds the same two events of A: same age. The OFF channel has none of A's.
  age = MeasureSurfaceAge(surface, SurfaceChannel::kOff, decay, t_ns, intrinsics, Rigid3d(),
                          velocity, positions, both, &scratch);
  EXPECT_EQ(age.points, 0);
  EXPECT_EQ(age.age_ns, 0);
  // With a shorter decay the 8 ms event is empty: only the 4 ms pixel counts.
  age = MeasureSurfaceAge(surface, SurfaceChannel::kAll, SurfaceDecay{2e6, 0.1}, t_ns, intrinsics,
                          Rigid3d(), velocity, positions, both, &scratch);
  EXPECT_EQ(age.points, 1);
  EXPECT_NEAR(age.age_ns, 4'000'000, 100);
  // A camera at rest: no point moves in the image, none says anything about time.
  age = MeasureSurfaceAge(surface, SurfaceChannel::kAll, decay, t_ns, intrinsics, Rigid3d(),
                          Vector6d::Zero(), positions, both, &scratch);
  EXPECT_EQ(age.points, 0);
}

}  // namespace
}  // namespace evloc::tracking
