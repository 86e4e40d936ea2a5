// Accuracy of `evloc-mapper build` on real photos (docs/mapper.md, "Measured figures"): the
// Middlebury templeSparseRing images with calibrated intrinsics and poses. Label `long`.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>

#include "core/common/test_data.h"
#include "core/dataset/testing/middlebury.h"
#include "mapper/map_builder.h"
#include "maps/map.h"
#include "tools/map_accuracy/map_accuracy.h"

namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;

void PrintTimings(const MapBuildReport& report) {
  for (const StageTiming& timing : report.timings) {
    std::cout << "  " << timing.stage << ": " << timing.seconds << " s wall, " << timing.cpu_seconds
              << " s CPU" << (timing.reused ? " (reused)" : "") << "\n";
  }
  std::cout << "  COLMAP total " << report.TotalSeconds("colmap") << " s wall, "
            << report.TotalCpuSeconds("colmap") << " s CPU; semi-dense total "
            << report.TotalSeconds("semidense") << " s wall, "
            << report.TotalCpuSeconds("semidense") << " s CPU\n";
}

struct TempleFixture {
  fs::path image_dir;
  std::vector<testing::MiddleburyView> views;
  Camera camera;
};

TempleFixture LoadTemple(const fs::path& parameters) {
  TempleFixture temple;
  temple.image_dir = parameters.parent_path();
  temple.views = testing::ReadMiddleburyParameters(parameters);
  temple.camera = testing::MiddleburyCamera(temple.views.at(0), 640, 480);
  return temple;
}

TEST(MapBuilderAccuracy, TempleKnownPosesMapLiesOnImageEdges) {
  EVLOC_REQUIRE_SHARED_DATA(parameters, "middlebury/templeSparseRing/templeSR_par.txt");
  const TempleFixture temple = LoadTemple(parameters);
  const fs::path directory = evloc::testing::MakeTempDir("accuracy_temple_known");
  testing::WriteNamedPoses(directory / "poses.txt", temple.views);
  MapBuilderOptions options;
  options.image_dir = temple.image_dir;
  options.output_dir = directory / "map";
  options.camera = temple.camera;
  options.known_poses = directory / "poses.txt";
  const MapBuildReport report = BuildMap(options);
  const Map map = LoadMap(options.output_dir / "map.evmap");
  const std::vector<double> distances = KeyframeEdgeDistances(map, temple.image_dir);
  ASSERT_GT(distances.size(), 1000u);
  const double median = distances[distances.size() / 2];
  std::cout << "templeSparseRing, known poses: " << report.num_registered << "/"
            << report.num_images << " images, " << report.num_keyframes << " keyframes, "
            << report.num_sparse_points << " sparse points (mean reprojection error "
            << report.colmap_mean_reprojection_error_px << " px), " << report.num_keyframe_points
            << " keyframe points, " << map.size() << " map points\n"
            << "  edge distance of visible points: median " << median << " px, 75th "
            << distances[distances.size() * 3 / 4] << " px, 90th "
            << distances[distances.size() * 9 / 10] << " px over " << distances.size()
            << " projections\n";
  PrintTimings(report);
  EXPECT_LE(median, 1.0);
  // CPU time: wall time on a shared machine depends on the others' load. The bound is the COLMAP
  // CPU of this build with COLMAP's matcher (24.7 s, docs/mapper.md "Timings"), which it used to
  // be compared with: evloc's matcher brought COLMAP's stages down to about 9 s (semi-dense 15 s).
  constexpr double kSemidenseCpuBudgetSeconds = 24.7;
  EXPECT_LE(report.TotalCpuSeconds("semidense"), kSemidenseCpuBudgetSeconds);
  fs::remove_all(directory);
}

TEST(MapBuilderAccuracy, TempleEstimatedPosesAgreeWithCalibration) {
  EVLOC_REQUIRE_SHARED_DATA(parameters, "middlebury/templeSparseRing/templeSR_par.txt");
  const TempleFixture temple = LoadTemple(parameters);
  const fs::path directory = evloc::testing::MakeTempDir("accuracy_temple_estimated");
  testing::WriteNamedPoses(directory / "poses.txt", temple.views);
  MapBuilderOptions options;
  options.image_dir = temple.image_dir;
  options.output_dir = directory / "map";
  options.camera = temple.camera;
  options.align_to = directory / "poses.txt";
  const MapBuildReport report = BuildMap(options);
  EXPECT_EQ(report.num_registered, 16u);
  ASSERT_TRUE(report.alignment_rms_m.has_value());
  const Map map = LoadMap(options.output_dir / "map.evmap");
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3f& position : map.positions) centroid += position.cast<double>();
  centroid /= static_cast<double>(map.size());
  // The poses as the mapper aligned them (centres and orientations, AlignPoses), and re-aligned
  // by the camera centres alone (Umeyama: the usual evaluation, minimising the position errors).
  std::vector<Rigid3d> aligned;
  std::vector<Rigid3d> truths;
  for (const testing::MiddleburyView& view : temple.views) {
    const auto estimated = report.world_from_cams.find(view.name);
    ASSERT_NE(estimated, report.world_from_cams.end()) << view.name;
    aligned.push_back(estimated->second);
    truths.push_back(view.cam_from_world.Inverse());
  }
  Eigen::Matrix3Xd source(3, aligned.size());
  Eigen::Matrix3Xd target(3, aligned.size());
  for (size_t i = 0; i < aligned.size(); ++i) {
    source.col(static_cast<Eigen::Index>(i)) = aligned[i].translation;
    target.col(static_cast<Eigen::Index>(i)) = truths[i].translation;
  }
  const Sim3d centres_only = AlignUmeyama(source, target, true);
  struct Worst {
    double rotation_deg = 0.0;
    double relative_position = 0.0;
    std::string view;
  };
  const auto worst_of = [&](const Sim3d& realignment) {
    Worst worst;
    for (size_t i = 0; i < aligned.size(); ++i) {
      const Rigid3d pose = realignment.TransformPose(aligned[i]);
      const double rotation_deg =
          AngleBetween(pose.rotation, truths[i].rotation) * 180.0 / std::numbers::pi;
      const double relative = (pose.translation - truths[i].translation).norm() /
                              (truths[i].translation - centroid).norm();
      worst.rotation_deg = std::max(worst.rotation_deg, rotation_deg);
      if (relative > worst.relative_position) {
        worst.relative_position = relative;
        worst.view = temple.views[i].name;
      }
    }
    return worst;
  };
  const Worst as_mapped = worst_of(Sim3d());
  const Worst by_centres = worst_of(centres_only);
  std::cout << "templeSparseRing, estimated poses against the calibration: as aligned by the "
               "mapper (centres and orientations): max rotation error "
            << as_mapped.rotation_deg << " deg, max position error "
            << 100.0 * as_mapped.relative_position << " % of the object distance ("
            << as_mapped.view << "); re-aligned by the centres alone: " << by_centres.rotation_deg
            << " deg, " << 100.0 * by_centres.relative_position << " % (" << by_centres.view
            << ")\n";
  // The requirement is checked with the centre alignment (the usual one).
  const double max_rotation_deg = by_centres.rotation_deg;
  const double max_relative_position = by_centres.relative_position;
  const std::vector<double> distances = KeyframeEdgeDistances(map, temple.image_dir);
  std::cout << "templeSparseRing, estimated poses (fixed intrinsics, Sim(3) to calibration): "
            << report.num_registered << "/16 registered, alignment RMS "
            << *report.alignment_rms_m * 1000.0 << " mm (scale " << *report.alignment_scale << "); "
            << map.size() << " points, median edge distance " << distances[distances.size() / 2]
            << " px\n";
  PrintTimings(report);
  EXPECT_LT(max_rotation_deg, 1.0);
  EXPECT_LT(max_relative_position, 0.01);
  fs::remove_all(directory);
}

}  // namespace
}  // namespace evloc::mapper
