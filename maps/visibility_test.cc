#include "maps/visibility.h"

#include <gtest/gtest.h>

#include <random>
#include <thread>

#include "core/common/error.h"
#include "maps/synthetic_map.h"

namespace evloc {
namespace {

const Camera kCamera = Camera::Pinhole(640, 480, 320.0, 320.0, 319.5, 239.5);

// Points visible by brute force: every point through the per-point test.
std::vector<uint32_t> BruteForceVisible(const Map& map, const Camera& camera,
                                        const Rigid3d& world_from_cam,
                                        const VisibilityQueryOptions& options) {
  const Rigid3d cam_from_world = world_from_cam.Inverse();
  std::vector<uint32_t> visible;
  for (size_t i = 0; i < map.size(); ++i) {
    const Eigen::Vector3d point = cam_from_world * map.positions[i].cast<double>();
    Eigen::Vector2d pixel;
    if (point.z() >= options.min_depth_m && point.z() <= options.max_depth_m &&
        camera.Project(point, &pixel) && camera.IsInside(pixel, options.image_margin_px)) {
      visible.push_back(static_cast<uint32_t>(i));
    }
  }
  return visible;
}

TEST(VisibilityIndex, MapWithoutKeyframesKeepsPointsInTheFrustum) {
  // Camera at the origin looking down +z (identity pose).
  Map map;
  const Eigen::Vector3f gradient(1, 0, 0);
  map.AddPoint({0, 0, 2}, gradient);          // 0: in front, centre
  map.AddPoint({0, 0, -2}, gradient);         // 1: behind
  map.AddPoint({10, 0, 2}, gradient);         // 2: far outside to the right (x/z = 5)
  map.AddPoint({0.9f, 0.7f, 2}, gradient);    // 3: near the bottom-right corner, inside
  map.AddPoint({0, 0, 60}, gradient);         // 4: beyond max depth
  map.AddPoint({0, 0, 0.01f}, gradient);      // 5: nearer than min depth
  map.AddPoint({0.99f, 0, 2}, gradient);      // 6: u = 319.5 + 158.4 = 477.9: inside
  map.AddPoint({-0.2f, -0.1f, 1}, gradient);  // 7: in front
  const VisibilityIndex index(map);
  EXPECT_FALSE(index.uses_keyframes());
  EXPECT_GT(index.num_voxels(), 0u);
  EXPECT_EQ(index.Query(kCamera, Rigid3d::Identity()), (std::vector<uint32_t>{0, 3, 6, 7}));

  // Turned around (180 degrees about y), the camera sees point 1 only.
  const Rigid3d turned(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY())),
                       Eigen::Vector3d::Zero());
  EXPECT_EQ(index.Query(kCamera, turned), (std::vector<uint32_t>{1}));

  // A 150-pixel margin (u <= 489, v <= 329) drops the point near the corner (v = 239.5 + 112 =
  // 351.5) but keeps point 6 (u = 477.9, v = 239.5).
  VisibilityQueryOptions margin;
  margin.image_margin_px = 150;
  EXPECT_EQ(index.Query(kCamera, Rigid3d::Identity(), margin), (std::vector<uint32_t>{0, 6, 7}));

  VisibilityQueryOptions deep;
  deep.max_depth_m = 100;
  deep.min_depth_m = 0.005;
  EXPECT_EQ(index.Query(kCamera, Rigid3d::Identity(), deep),
            (std::vector<uint32_t>{0, 3, 4, 5, 6, 7}));
}

TEST(VisibilityIndex, VoxelQueryEqualsBruteForce) {
  CorridorMapOptions corridor;
  corridor.num_points = 20000;
  corridor.num_keyframes = 0;
  const Map map = MakeCorridorMap(corridor);
  Camera fisheye = kCamera;
  fisheye.model = CameraModel::kRadialTangential;
  fisheye.distortion = {-0.25, 0.07, 0.001, 0.0005, 0.0};
  std::mt19937 random(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (const double voxel_size : {0.1, 0.25, 1.0}) {
    VisibilityIndexOptions index_options;
    index_options.voxel_size_m = voxel_size;
    const VisibilityIndex index(map, index_options);
    for (int trial = 0; trial < 10; ++trial) {
      const Rigid3d pose =
          CorridorCameraPose(10.0 + 8.0 * uniform(random)) *
          Rigid3d(ExpSO3(Eigen::Vector3d(uniform(random), uniform(random), uniform(random))),
                  Eigen::Vector3d(0.3 * uniform(random), 0.3 * uniform(random), 0.0));
      VisibilityQueryOptions options;
      options.max_depth_m = 2.0 + 4.0 * (trial % 3);
      options.image_margin_px = 5.0 * (trial % 2);
      for (const Camera& camera : {kCamera, fisheye}) {
        const std::vector<uint32_t> expected = BruteForceVisible(map, camera, pose, options);
        EXPECT_EQ(index.Query(camera, pose, options), expected)
            << "voxel " << voxel_size << " trial " << trial;
        if (trial == 0) {
          EXPECT_GT(expected.size(), 100u);
        }
      }
    }
  }
}

// Four keyframes on the x axis at x = 0, 1, 2, 3, all looking down +z except keyframe 3, which
// looks down -z; each sees its own 10 points (and keyframes 1 and 2 share points 15..19).
Map MakeKeyframeMap() {
  Map map;
  map.cameras.push_back(kCamera);
  for (int k = 0; k < 4; ++k) {
    const double direction = k == 3 ? -1.0 : 1.0;
    for (int i = 0; i < 10; ++i) {
      map.AddPoint(Eigen::Vector3f(k + 0.05f * i, 0.0f, static_cast<float>(2.0 * direction)),
                   {0, 1, 0}, 0.0f, 0.0f, static_cast<uint32_t>(k));
    }
    Rigid3d world_from_cam(Eigen::Quaterniond::Identity(), Eigen::Vector3d(k, 0, 0));
    if (k == 3) {
      world_from_cam.rotation = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY());
    }
    Keyframe keyframe;
    keyframe.cam_from_world = world_from_cam.Inverse();
    for (uint32_t i = 0; i < 10; ++i) keyframe.visible_points.push_back(10 * k + i);
    map.keyframes.push_back(keyframe);
  }
  map.keyframes[2].visible_points.insert(map.keyframes[2].visible_points.begin(),
                                         {15, 16, 17, 18, 19});
  map.Check();
  return map;
}

TEST(VisibilityIndex, NearestKeyframesByPositionAndViewingDirection) {
  const Map map = MakeKeyframeMap();
  const VisibilityIndex index(map);
  EXPECT_TRUE(index.uses_keyframes());
  EXPECT_EQ(index.num_voxels(), 0u);
  VisibilityQueryOptions options;
  options.num_nearest_keyframes = 2;
  const Rigid3d near_two(Eigen::Quaterniond::Identity(), Eigen::Vector3d(2.1, 0, 0));
  EXPECT_EQ(index.NearestKeyframes(near_two, options), (std::vector<uint32_t>{2, 1}));
  // Keyframe 3 is nearer to x = 2.9 than keyframe 2, but looks the other way.
  const Rigid3d near_three(Eigen::Quaterniond::Identity(), Eigen::Vector3d(2.9, 0, 0));
  options.num_nearest_keyframes = 1;
  EXPECT_EQ(index.NearestKeyframes(near_three, options), (std::vector<uint32_t>{2}));
  // With a small angle weight and no angle limit, position wins.
  options.viewing_angle_weight_m_per_rad = 0.01;
  options.max_viewing_angle_rad = M_PI;
  EXPECT_EQ(index.NearestKeyframes(near_three, options), (std::vector<uint32_t>{3}));
}

TEST(VisibilityIndex, KeyframeQueryTakesCandidatesOfTheNearestKeyframesInTheFrustum) {
  const Map map = MakeKeyframeMap();
  const VisibilityIndex index(map);
  VisibilityQueryOptions options;
  options.num_nearest_keyframes = 2;
  // At x = 2.1 looking down +z: keyframes 2 and 1. All of their points (10..29) are in front at
  // depth 2; keyframe 1's points at x in [1, 1.45] lie at x/z down to -0.55, inside the half
  // field of view of 319.5/320 ~ 1.0.
  const Rigid3d pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(2.1, 0, 0));
  std::vector<uint32_t> expected;
  for (uint32_t i = 10; i < 30; ++i) expected.push_back(i);
  EXPECT_EQ(index.Query(kCamera, pose, options), expected);
  // Only the nearest keyframe: its own points and the 5 it shares with keyframe 1, once each.
  options.num_nearest_keyframes = 1;
  expected = {15, 16, 17, 18, 19};
  for (uint32_t i = 20; i < 30; ++i) expected.push_back(i);
  EXPECT_EQ(index.Query(kCamera, pose, options), expected);
  // Moved 2 m forward, the points are behind the camera.
  const Rigid3d forward(Eigen::Quaterniond::Identity(), Eigen::Vector3d(2.1, 0, 2.5));
  EXPECT_TRUE(index.Query(kCamera, forward, options).empty());
}

TEST(VisibilityIndex, KeyframesWithoutVisibleListsUseTheirSourcePoints) {
  Map map = MakeKeyframeMap();
  for (Keyframe& keyframe : map.keyframes) keyframe.visible_points.clear();
  const VisibilityIndex index(map);
  EXPECT_TRUE(index.uses_keyframes());
  VisibilityQueryOptions options;
  options.num_nearest_keyframes = 1;
  const Rigid3d pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1.0, 0, 0));
  std::vector<uint32_t> expected;
  for (uint32_t i = 10; i < 20; ++i) expected.push_back(i);
  EXPECT_EQ(index.Query(kCamera, pose, options), expected);
}

TEST(VisibilityIndex, ConcurrentQueriesAgreeWithSequentialOnes) {
  CorridorMapOptions corridor;
  corridor.num_points = 20000;
  corridor.num_keyframes = 20;
  const Map map = MakeCorridorMap(corridor);
  const VisibilityIndex index(map);
  std::vector<Rigid3d> poses;
  std::vector<std::vector<uint32_t>> expected;
  for (int i = 0; i < 16; ++i) {
    poses.push_back(CorridorCameraPose(1.0 + i));
    expected.push_back(index.Query(kCamera, poses.back()));
    EXPECT_FALSE(expected.back().empty());
  }
  std::vector<std::vector<std::vector<uint32_t>>> results(4);
  std::vector<std::thread> threads;
  for (size_t t = 0; t < results.size(); ++t) {
    threads.emplace_back([&, t] {
      for (int repeat = 0; repeat < 5; ++repeat) {
        for (const Rigid3d& pose : poses) results[t].push_back(index.Query(kCamera, pose));
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  for (const auto& thread_results : results) {
    ASSERT_EQ(thread_results.size(), 5 * poses.size());
    for (size_t i = 0; i < thread_results.size(); ++i) {
      EXPECT_EQ(thread_results[i], expected[i % poses.size()]);
    }
  }
}

TEST(VisibilityIndex, OptionsAreChecked) {
  const Map map = MakeKeyframeMap();
  const VisibilityIndex index(map);
  VisibilityQueryOptions options;
  options.num_nearest_keyframes = 0;
  EXPECT_THROW(index.Query(kCamera, Rigid3d::Identity(), options), InvalidArgumentError);
  options = {};
  options.min_depth_m = 5;
  options.max_depth_m = 1;
  EXPECT_THROW(index.Query(kCamera, Rigid3d::Identity(), options), InvalidArgumentError);
  options = {};
  options.image_margin_px = -1;
  EXPECT_THROW(index.Query(kCamera, Rigid3d::Identity(), options), InvalidArgumentError);
  VisibilityIndexOptions index_options;
  index_options.voxel_size_m = 0;
  EXPECT_THROW(VisibilityIndex(map, index_options), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc
