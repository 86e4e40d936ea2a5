#include "localizer/tracking/point_selection.h"

#include <algorithm>
#include <map>
#include <numeric>

#include <Eigen/Eigenvalues>

#include <gtest/gtest.h>

#include "core/common/error.h"
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

TEST(PointSelection, InformativeKeepsThePointsThatAloneFixADirection) {
  // 900 points on vertical edges (image gradient along x) spread over a 320x240 image, then 100 on
  // horizontal edges (gradient along y) and 20 whose gradient points along the viewing ray (no
  // edge normal in the image), at 1.5-3 m.
  const PinholeIntrinsics intrinsics{200.0, 200.0, 159.5, 119.5};
  Map map;
  auto add_at_pixel = [&](double u, double v, double z, const Eigen::Vector3f& gradient) {
    map.AddPoint(Eigen::Vector3f((u - 159.5) * z / 200.0, (v - 119.5) * z / 200.0, z), gradient);
  };
  for (int i = 0; i < 900; ++i) {
    add_at_pixel(10.0 + (i % 30) * 10.0, 10.0 + (i / 30) * 7.0, 1.5 + (i % 7) * 0.25,
                 Eigen::Vector3f::UnitX());
  }
  for (int i = 0; i < 100; ++i) {
    add_at_pixel(15.0 + (i % 10) * 29.0, 15.0 + (i / 10) * 21.0, 1.5 + (i % 5) * 0.3,
                 Eigen::Vector3f::UnitY());
  }
  for (int i = 0; i < 20; ++i) {
    const Eigen::Vector3f ray =
        Eigen::Vector3f(20.0f + 13.0f * i - 159.5f, 80.0f, 200.0f).normalized();
    add_at_pixel(20.0 + 13.0 * i, 199.5, 2.0, ray);
  }
  std::vector<uint32_t> all(map.size());
  std::iota(all.begin(), all.end(), 0u);
  const auto select = [&](const std::vector<uint32_t>& from, int count, double seed_fraction,
                          double probe_fraction = 0.01) {
    InformativeSelectionOptions options;
    options.count = count;
    options.seed_fraction = seed_fraction;
    options.gradient_probe_depth_fraction = probe_fraction;
    return SelectInformative(map.positions, map.gradients, from, intrinsics, Rigid3d(), options);
  };
  const std::vector<uint32_t> chosen = select(all, 200, 0.25);
  ASSERT_EQ(chosen.size(), 200u);
  EXPECT_TRUE(std::adjacent_find(chosen.begin(), chosen.end(),
                                 [](uint32_t a, uint32_t b) { return a >= b; }) == chosen.end())
      << "ascending, each index once";
  // The even pick of as many points (all seeds) for comparison.
  const std::vector<uint32_t> even = select(all, 200, 1.0);
  // The horizontal edges alone fix the vertical translation and the pitch: the choice keeps far
  // more of them than their share, and its information is better conditioned than the even
  // pick's. The information of a set: the sum of j j^T over its predicted rows (translation part
  // n^T dpi/dp with n the unit edge normal, rotation part p x that).
  const auto smallest_eigenvalue = [&](const std::vector<uint32_t>& set) {
    Matrix6d information = Matrix6d::Zero();
    for (const uint32_t i : set) {
      const Eigen::Vector3d p = map.positions[i].cast<double>();
      const Eigen::Vector3d g = map.gradients[i].cast<double>();
      Eigen::Vector2d normal(g.x(), g.y());
      if (normal.norm() < 0.5) continue;  // along the ray
      normal.normalize();
      Eigen::Matrix<double, 2, 3> d_pixel;
      d_pixel << 200.0 / p.z(), 0, -200.0 * p.x() / (p.z() * p.z()), 0, 200.0 / p.z(),
          -200.0 * p.y() / (p.z() * p.z());
      Vector6d row;
      row.head<3>() = d_pixel.transpose() * normal;
      row.tail<3>() = p.cross(Eigen::Vector3d(row.head<3>()));
      information += row * row.transpose();
    }
    return Eigen::SelfAdjointEigenSolver<Matrix6d>(information).eigenvalues()(0);
  };
  const auto horizontal = [](const std::vector<uint32_t>& set) {
    return std::count_if(set.begin(), set.end(), [](uint32_t i) { return i >= 900 && i < 1000; });
  };
  EXPECT_LE(horizontal(even), 25);
  EXPECT_GE(horizontal(chosen), 2 * horizontal(even) + 20);
  EXPECT_GT(smallest_eigenvalue(chosen), 2.0 * smallest_eigenvalue(even));
  // A point without an edge normal is taken only as a seed; the 50 seeds at even intervals over
  // the 1020 points (positions 0, 20.4, ..., 999.6) include none of them.
  const auto no_normal =
      std::count_if(chosen.begin(), chosen.end(), [](uint32_t i) { return i >= 1000; });
  EXPECT_EQ(no_normal, 0);
  // All seeds: the even intervals alone.
  const std::vector<uint32_t> seeds_only = select(all, 100, 1.0);
  ASSERT_EQ(seeds_only.size(), 100u);
  for (size_t k = 0; k < 100; ++k) EXPECT_EQ(seeds_only[k], k * 1020 / 100) << k;
  // Deterministic; everything when the budget covers it.
  EXPECT_EQ(select(all, 200, 0.25), chosen);
  EXPECT_EQ(select(all, 5000, 0.25), all);
  EXPECT_THROW(select(all, 0, 0.25), InvalidArgumentError);
  EXPECT_THROW(select(all, 10, 0.0), InvalidArgumentError);
  EXPECT_THROW(select(all, 10, 0.25, 0.0), InvalidArgumentError);
  std::vector<uint32_t> out_of_range = all;
  out_of_range.push_back(5000);
  EXPECT_THROW(select(out_of_range, 10, 0.25), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::tracking
