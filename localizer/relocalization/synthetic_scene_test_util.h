// Synthetic 2D-3D correspondences for the absolute pose tests and benchmark: points in front of
// a distorted camera, pixel noise, and a fraction of outliers, reproducible from a seed.
#pragma once

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include <Eigen/Core>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"

namespace evloc::relocalization::testing {

// A 640 x 480 camera with clear barrel distortion and a little tangential distortion.
inline Camera DistortedCamera() {
  Camera camera = Camera::Pinhole(640, 480, 500.0, 505.0, 318.7, 241.2);
  camera.model = CameraModel::kRadialTangential;
  camera.distortion = {-0.25, 0.07, 0.0008, -0.0005, 0.0};
  camera.Check();
  return camera;
}

// 2D-3D correspondences of a synthetic scene seen from `world_from_cam`.
struct Scene {
  // The true pose.
  Rigid3d world_from_cam;
  // Observed pixels (distorted).
  std::vector<Eigen::Vector2d> pixels;
  // The corresponding points, world coordinates.
  std::vector<Eigen::Vector3d> points_in_world;
  // True for correspondences replaced by outliers.
  std::vector<bool> is_outlier;
};

// `count` points at depths 1.5-6 m spread over the image, observed with Gaussian pixel noise;
// a fraction of the pixels is replaced by uniformly random pixels (outliers).
inline Scene MakeScene(const Camera& camera, int count, double noise_px, double outlier_fraction,
                       unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_real_distribution<double> u_pixel(5.0, camera.width - 6.0);
  std::uniform_real_distribution<double> v_pixel(5.0, camera.height - 6.0);
  std::uniform_real_distribution<double> depth(1.5, 6.0);
  std::normal_distribution<double> noise(0.0, noise_px);
  Scene scene;
  scene.world_from_cam =
      Rigid3d(ExpSO3(Eigen::Vector3d(0.3 * unit(rng), 0.3 * unit(rng), M_PI * unit(rng))),
              Eigen::Vector3d(2 * unit(rng), 2 * unit(rng), 1 + 0.5 * unit(rng)));
  const int outliers = static_cast<int>(std::lround(outlier_fraction * count));
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3d ray;
    const Eigen::Vector2d sampled(u_pixel(rng), v_pixel(rng));
    Eigen::Vector2d pixel;
    const bool unprojected = camera.Unproject(sampled, &ray);
    const Eigen::Vector3d point_in_cam = depth(rng) * ray;
    if (!unprojected || !camera.Project(point_in_cam, &pixel)) {
      throw std::logic_error("MakeScene: the camera cannot see its own pixels");
    }
    const bool outlier = i < outliers;
    pixel = outlier ? Eigen::Vector2d(u_pixel(rng), v_pixel(rng))
                    : Eigen::Vector2d(pixel + Eigen::Vector2d(noise(rng), noise(rng)));
    scene.pixels.push_back(pixel);
    scene.points_in_world.push_back(scene.world_from_cam * point_in_cam);
    scene.is_outlier.push_back(outlier);
  }
  // Shuffle so that outliers are not grouped at the front.
  std::vector<int> order(count);
  for (int i = 0; i < count; ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);
  Scene shuffled = scene;
  for (int i = 0; i < count; ++i) {
    shuffled.pixels[i] = scene.pixels[order[i]];
    shuffled.points_in_world[i] = scene.points_in_world[order[i]];
    shuffled.is_outlier[i] = scene.is_outlier[order[i]];
  }
  return shuffled;
}

}  // namespace evloc::relocalization::testing
