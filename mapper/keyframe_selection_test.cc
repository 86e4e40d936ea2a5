#include "mapper/keyframe_selection.h"

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::mapper {
namespace {

// Cameras along x looking at +z, at depth 2 m from a row of points; view i sees points within
// +-0.6 m of its x position.
struct Scene {
  std::vector<RegisteredView> views;
  std::unordered_map<uint64_t, Eigen::Vector3d> points;
};

Scene MakeScene(int num_views, double spacing) {
  Scene scene;
  for (uint64_t id = 0; id < 400; ++id) {
    scene.points[id] = Eigen::Vector3d(-1.0 + 0.01 * static_cast<double>(id), 0.0, 2.0);
  }
  for (int i = 0; i < num_views; ++i) {
    RegisteredView view;
    view.image_name = "view" + std::to_string(i);
    const Eigen::Vector3d center(spacing * i, 0.0, 0.0);
    view.cam_from_world = Rigid3d(Eigen::Quaterniond::Identity(), -center);
    for (const auto& [id, point] : scene.points) {
      if (std::abs(point.x() - center.x()) < 0.6) view.observed_points.push_back(id);
    }
    scene.views.push_back(view);
  }
  return scene;
}

TEST(KeyframeSelection, NewKeyframeAfterEnoughBaseline) {
  const Scene scene = MakeScene(20, 0.02);
  KeyframeSelectionOptions options;
  options.max_baseline_ratio = 0.045;  // 0.09 m at 2 m depth: every 5th view (0.1 m).
  options.max_shared_fraction = 0.01;
  options.min_keyframes = 1;
  const KeyframeSelection selection = SelectKeyframes(scene.views, scene.points, options);
  EXPECT_EQ(selection.keyframes, (std::vector<size_t>{0, 5, 10, 15}));
  ASSERT_EQ(selection.median_depths.size(), 4u);
  EXPECT_NEAR(selection.median_depths[0], 2.0, 1e-9);
}

TEST(KeyframeSelection, MaxKeyframesThinsEvenly) {
  const Scene scene = MakeScene(20, 0.05);
  KeyframeSelectionOptions options;
  options.max_keyframes = 3;
  const KeyframeSelection selection = SelectKeyframes(scene.views, scene.points, options);
  ASSERT_EQ(selection.keyframes.size(), 3u);
  EXPECT_EQ(selection.keyframes.front(), 0u);
  EXPECT_GT(selection.keyframes.back(), 15u);
}

TEST(KeyframeSelection, NeighboursShareMostPointsAndHaveBaseline) {
  Scene scene = MakeScene(10, 0.1);
  // A duplicate of view 0 (no baseline) must not be a neighbour.
  scene.views.push_back(scene.views[0]);
  KeyframeSelectionOptions options;
  options.num_neighbours = 3;
  options.preferred_neighbour_baseline_ratio = 0.01;  // Every baseline here is wide enough.
  const KeyframeSelection selection = SelectKeyframes(scene.views, scene.points, options);
  ASSERT_EQ(selection.keyframes.front(), 0u);
  const std::vector<size_t>& neighbours = selection.neighbours.front();
  EXPECT_EQ(neighbours, (std::vector<size_t>{1, 2, 3}));
}

TEST(KeyframeSelection, NeighboursPreferBaselineUpToThePreferredRatio) {
  const Scene scene = MakeScene(10, 0.1);
  KeyframeSelectionOptions options;
  options.num_neighbours = 3;
  options.preferred_neighbour_baseline_ratio = 0.08;  // 0.16 m at 2 m depth.
  const KeyframeSelection selection = SelectKeyframes(scene.views, scene.points, options);
  ASSERT_EQ(selection.keyframes.front(), 0u);
  // View 1 (0.1 m) shares the most points but is weighted by 0.1 / 0.16; views 2-4 are not.
  EXPECT_EQ(selection.neighbours.front(), (std::vector<size_t>{2, 3, 4}));
}

TEST(KeyframeSelection, ShortSequenceGetsMinKeyframes) {
  // 60 views over 0.6 m at 2 m depth: the default 0.1 * depth baseline gives 3 keyframes.
  const Scene scene = MakeScene(60, 0.01);
  KeyframeSelectionOptions options;
  options.max_shared_fraction = 0.01;
  options.min_keyframes = 12;
  const KeyframeSelection selection = SelectKeyframes(scene.views, scene.points, options);
  EXPECT_GE(selection.keyframes.size(), 12u);
  EXPECT_LE(selection.keyframes.size(), 30u);
  EXPECT_EQ(selection.keyframes.front(), 0u);
  EXPECT_GE(selection.keyframes.back(), 50u);
  for (const std::vector<size_t>& neighbours : selection.neighbours) {
    EXPECT_EQ(neighbours.size(), static_cast<size_t>(options.num_neighbours));
  }
  // More keyframes than views cannot be had: every view is one.
  options.min_keyframes = 100;
  const Scene tiny = MakeScene(4, 0.001);
  EXPECT_EQ(SelectKeyframes(tiny.views, tiny.points, options).keyframes,
            (std::vector<size_t>{0, 1, 2, 3}));
}

TEST(KeyframeSelection, RejectsBadInput) {
  const Scene scene = MakeScene(3, 0.1);
  KeyframeSelectionOptions options;
  EXPECT_THROW(SelectKeyframes({}, scene.points, options), InvalidArgumentError);
  options.num_neighbours = 0;
  EXPECT_THROW(SelectKeyframes(scene.views, scene.points, options), InvalidArgumentError);
  options = KeyframeSelectionOptions();
  options.min_keyframes = 0;
  EXPECT_THROW(SelectKeyframes(scene.views, scene.points, options), InvalidArgumentError);
  options = KeyframeSelectionOptions();
  options.preferred_neighbour_baseline_ratio = 0.0;
  EXPECT_THROW(SelectKeyframes(scene.views, scene.points, options), InvalidArgumentError);
  options = KeyframeSelectionOptions();
  std::vector<RegisteredView> views = scene.views;
  views[0].observed_points.push_back(123456);
  EXPECT_THROW(SelectKeyframes(views, scene.points, options), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::mapper
