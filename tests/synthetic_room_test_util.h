// Test helpers for the synthetic-room mapping checks (docs/mapper.md, "Synthetic room"): the
// simulator's default room rendered along its `mid` motion as ideal frames (the renderer without
// the frame sensor's noise and blur, and without events, to stay short), the exact reference map
// and the accuracy measure.
#pragma once

#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "mapper/map_builder.h"
#include "maps/map.h"
#include "tools/map_accuracy/map_accuracy.h"
#include "tools/sim/ground_truth_map.h"
#include "tools/sim/motion.h"
#include "tools/sim/renderer.h"
#include "tools/sim/scene.h"

namespace evloc::mapper::testing {

// The rendered sequence: images, poses and depth maps.
struct Sequence {
  // Folder of the 8-bit frames.
  std::filesystem::path image_dir;
  // `t_s name` lines.
  std::filesystem::path image_list;
  // `NAME tx ty tz qx qy qz qw` world_from_cam lines (--known-poses, --align-to).
  std::filesystem::path poses;
  // The pinhole camera (the simulator's default: 640 x 480, f = 500 px).
  Camera camera;
  // The rendered depth of every frame, with its time.
  std::vector<DepthView> depth_views;
};

// Renders 30 frames (15 Hz) of 2 s of the `mid` motion (seed 1, as `evloc-sim render --motion
// mid --duration 2`) into `directory`.
inline Sequence RenderSequence(const sim::Scene& scene, const std::filesystem::path& directory) {
  Sequence sequence;
  sequence.camera = Camera::Pinhole(640, 480, 500.0, 500.0, 319.5, 239.5);
  sim::SmoothMotionOptions motion_options;
  motion_options.profile = sim::MotionProfile::kMid;
  motion_options.duration_s = 2.0;
  motion_options.camera_region = scene.camera_region;
  // The simulator's base viewpoint: from the camera region's centre towards the room's centre.
  motion_options.viewpoint.position = scene.camera_region.center();
  motion_options.viewpoint.look_at = scene.bounds.center();
  const sim::SmoothMotion motion(motion_options);
  const sim::Renderer renderer(scene, sequence.camera);

  sequence.image_dir = directory / "images";
  sequence.image_list = directory / "images.txt";
  sequence.poses = directory / "poses.txt";
  std::filesystem::create_directories(sequence.image_dir);
  std::ofstream list(sequence.image_list);
  std::ofstream poses(sequence.poses);
  poses << std::setprecision(17);
  constexpr int kFrames = 30;  // 15 Hz
  for (int k = 0; k < kFrames; ++k) {
    const int64_t t_ns = motion.duration_ns() * k / (kFrames - 1);
    const Rigid3d world_from_cam = motion.WorldFromCam(t_ns);
    cv::Mat gray;
    DepthView view;
    renderer.Render(world_from_cam, &gray, nullptr, &view.depth_m);
    cv::Mat image;
    gray.convertTo(image, CV_8U, 255.0);
    std::ostringstream name;
    name << "frame_" << std::setw(3) << std::setfill('0') << k << ".png";
    EXPECT_TRUE(cv::imwrite((sequence.image_dir / name.str()).string(), image));
    list << std::fixed << std::setprecision(9) << t_ns * 1e-9 << " " << name.str() << "\n";
    const Eigen::Quaterniond& q = world_from_cam.rotation;
    const Eigen::Vector3d& t = world_from_cam.translation;
    poses << name.str() << " " << t.x() << " " << t.y() << " " << t.z() << " " << q.x() << " "
          << q.y() << " " << q.z() << " " << q.w() << "\n";
    view.camera = sequence.camera;
    view.cam_from_world = world_from_cam.Inverse();
    view.t_ns = t_ns;
    sequence.depth_views.push_back(std::move(view));
  }
  return sequence;
}

// The exact map of the scene and which of its points have an image-defined gradient.
struct Reference {
  // The exact map (evloc-sim's gt_map).
  Map map;
  // Per point: false for convex creases (ReferenceGradientDefined).
  std::vector<bool> gradient_defined;
};

// Build options for `sequence` (images, list, camera) writing the map to `output_dir`.
inline MapBuilderOptions SequenceBuildOptions(const Sequence& sequence,
                                              const std::filesystem::path& output_dir) {
  MapBuilderOptions options;
  options.image_dir = sequence.image_dir;
  options.image_list = sequence.image_list;
  options.camera = sequence.camera;
  options.output_dir = output_dir;
  return options;
}

// The exact map of `scene` with the simulator's options.
inline Reference ExactReference(const sim::Scene& scene, const Camera& camera) {
  Reference reference;
  const sim::GroundTruthMapOptions options;
  reference.map = sim::BuildGroundTruthMap(scene, camera, {}, options);
  for (const sim::GroundTruthEdgePoint& edge : sim::SampleGroundTruthEdges(scene, options)) {
    reference.gradient_defined.push_back(edge.kind != sim::EdgeKind::kConvexCrease);
  }
  return reference;
}

// Measures the map in `map_dir` and prints the figures after `label`.
inline MapAccuracy Measure(const std::filesystem::path& map_dir, const Sequence& sequence,
                           const Reference& reference, const std::string& label) {
  const Map map = LoadMap(map_dir / "map.evmap");
  const MapAccuracy accuracy =
      MeasureMapAccuracy(map, reference.map, sequence.depth_views, MapAccuracyOptions(), nullptr,
                         reference.gradient_defined);
  std::cout << label << ": " << accuracy.num_points << " points, median depth error "
            << accuracy.median_depth_error_m * 1000.0 << " mm ("
            << 100.0 * accuracy.depth_within_fraction << " % within 2 cm), median edge distance "
            << accuracy.median_edge_distance_m * 1000.0 << " mm, median gradient angle "
            << accuracy.median_gradient_angle_defined_deg << " deg without convex creases ("
            << accuracy.median_gradient_angle_deg << " deg with them)\n";
  return accuracy;
}

// Prints the CPU seconds of every stage after `label`.
inline void PrintCpuTimes(const MapBuildReport& report, const std::string& label) {
  std::cout << label << " CPU seconds:";
  for (const StageTiming& timing : report.timings) {
    std::cout << " " << timing.stage << " " << timing.cpu_seconds;
  }
  std::cout << "\n";
}

}  // namespace evloc::mapper::testing
