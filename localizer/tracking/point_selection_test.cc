#include "localizer/tracking/point_selection.h"

#include <algorithm>
#include <map>
#include <numeric>

#include <gtest/gtest.h>

#include "maps/map.h"

namespace evloc::tracking {
namespace {

TEST(PointSelection, CoversTheImageEvenlyWithinTheBudget) {
  // 2000 points crowded into one 16x16 bucket and 30 points spread over other buckets, at 2 m.
  const PinholeIntrinsics intrinsics{200.0, 200.0, 159.5, 119.5};
  Map map;
  auto add_at_pixel = [&](double u, double v) {
    const double z = 2.0;
    map.AddPoint(Eigen::Vector3f((u - 159.5) * z / 200.0, (v - 119.5) * z / 200.0, z),
                 Eigen::Vector3f::UnitX());
  };
  for (int i = 0; i < 2000; ++i) add_at_pixel(20.0 + (i % 40) * 0.3, 20.0 + (i / 40) * 0.2);
  for (int i = 0; i < 30; ++i) add_at_pixel(40.0 + 17.0 * (i % 10), 60.0 + 40.0 * (i / 10));
  // Behind the camera and out of the image: never selected.
  map.AddPoint(Eigen::Vector3f(0, 0, -2), Eigen::Vector3f::UnitX());
  map.AddPoint(Eigen::Vector3f(10, 0, 2), Eigen::Vector3f::UnitX());
  std::vector<uint32_t> candidates(map.size());
  std::iota(candidates.begin(), candidates.end(), 0u);
  PointSelectionOptions options;
  options.max_points = 100;
  const std::vector<uint32_t> selected =
      SelectEvenly(map.positions, candidates, intrinsics, 320, 240, Rigid3d(), options);
  ASSERT_EQ(selected.size(), 100u);
  EXPECT_TRUE(std::is_sorted(selected.begin(), selected.end()));
  // Every sparse point is kept; the crowded bucket gets the rest.
  for (uint32_t i = 2000; i < 2030; ++i) {
    EXPECT_TRUE(std::binary_search(selected.begin(), selected.end(), i)) << i;
  }
  EXPECT_FALSE(std::binary_search(selected.begin(), selected.end(), 2030u));
  EXPECT_FALSE(std::binary_search(selected.begin(), selected.end(), 2031u));
  // Deterministic and independent of the candidate order.
  std::vector<uint32_t> reversed(candidates.rbegin(), candidates.rend());
  EXPECT_EQ(SelectEvenly(map.positions, reversed, intrinsics, 320, 240, Rigid3d(), options),
            selected);
  // Within budget everything visible is returned.
  options.max_points = 5000;
  EXPECT_EQ(
      SelectEvenly(map.positions, candidates, intrinsics, 320, 240, Rigid3d(), options).size(),
      2030u);
}

TEST(PointSelection, KeepsMostOfTheCandidatesSortedAndRepeatedCandidatesTwice) {
  // 3000 points spread over a 320x240 image at 2 m; most of them kept (the result is then
  // ordered by marking the kept indices, not by a comparison sort).
  const PinholeIntrinsics intrinsics{200.0, 200.0, 159.5, 119.5};
  Map map;
  for (int i = 0; i < 3000; ++i) {
    const double u = 5.0 + (i % 60) * 5.1;
    const double v = 5.0 + (i / 60) * 4.6;
    map.AddPoint(Eigen::Vector3f((u - 159.5) * 2.0 / 200.0, (v - 119.5) * 2.0 / 200.0, 2.0f),
                 Eigen::Vector3f::UnitX());
  }
  std::vector<uint32_t> candidates(map.size());
  std::iota(candidates.begin(), candidates.end(), 0u);
  PointSelectionOptions options;
  options.max_points = 2500;
  const std::vector<uint32_t> selected =
      SelectEvenly(map.positions, candidates, intrinsics, 320, 240, Rigid3d(), options);
  ASSERT_EQ(selected.size(), 2500u);
  EXPECT_TRUE(std::adjacent_find(selected.begin(), selected.end(),
                                 [](uint32_t a, uint32_t b) { return a >= b; }) == selected.end())
      << "ascending, each index once";
  std::vector<uint32_t> reversed(candidates.rbegin(), candidates.rend());
  EXPECT_EQ(SelectEvenly(map.positions, reversed, intrinsics, 320, 240, Rigid3d(), options),
            selected);
  // A candidate given twice is a point given twice: within the budget both copies come back.
  std::vector<uint32_t> twice(candidates);
  twice.insert(twice.end(), candidates.begin(), candidates.begin() + 100);
  options.max_points = 5000;
  const std::vector<uint32_t> all =
      SelectEvenly(map.positions, twice, intrinsics, 320, 240, Rigid3d(), options);
  ASSERT_EQ(all.size(), 3100u);
  EXPECT_TRUE(std::is_sorted(all.begin(), all.end()));
  EXPECT_EQ(std::count(all.begin(), all.end(), 7u), 2);
  EXPECT_EQ(std::count(all.begin(), all.end(), 2000u), 1);
}

}  // namespace
}  // namespace evloc::tracking
