// The simulated depth camera of a dataset with depth (docs/simulator.md, "Depth camera"): its own
// intrinsics, frame rate and a known extrinsic to the event camera, and the errors of a real
// structured-light sensor: noise growing with the square of the depth, holes where the depth
// jumps (on the far side of the jump), on dark surfaces (too little of the projected light comes
// back) and on shiny ones seen near the mirror direction, and millimetre quantisation.
#pragma once

#include <cstdint>
#include <memory>
#include <random>
#include <string>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "tools/sim/renderer.h"
#include "tools/sim/scene.h"

namespace evloc::sim {

// Options of the depth camera model.
struct DepthSensorOptions {
  // The depth camera (any model; the default is a VGA structured-light camera, f = 525 px).
  Camera camera = Camera::Pinhole(640, 480, 525.0, 525.0, 319.5, 239.5);
  // p_event = event_from_depth * p_depth: the depth camera 5 cm to the right of the event camera,
  // turned by 1 degree about its y axis.
  Rigid3d event_from_depth = DefaultEventFromDepth();
  // Frames per second.
  double fps = 30;
  // Time of the first frame, nanoseconds (the render command starts it with the frame camera).
  int64_t first_frame_t_ns = 0;
  // Standard deviation of the depth noise at 1 m, metres; it grows with the square of the depth
  // (sigma = noise_at_1m_m * z^2; Khoshelham and Elberink 2012 measured 1.4 mm for the Kinect).
  double noise_at_1m_m = 0.0015;
  // Depth outside [min_range_m, max_range_m] is not measured (0).
  double min_range_m = 0.3;
  // Farthest depth measured, metres.
  double max_range_m = 8.0;
  // A pixel with a depth nearer than its own by more than this fraction of its own within
  // discontinuity_hole_px pixels (a square window) is on the far side of a depth discontinuity
  // (the projector's shadow): a hole.
  double discontinuity_fraction = 0.03;
  // Holes at discontinuities reach this many pixels into the far side (0: none).
  int discontinuity_hole_px = 1;
  // The light that comes back, albedo * cos(incidence), below this: a hole (dark surfaces, and
  // surfaces seen at grazing angles).
  double min_return = 0.06;
  // A surface with specular >= 0.5 seen within this angle of its normal (the mirror direction of
  // the projector beside the camera): a hole, degrees.
  double specular_hole_angle_deg = 20;
  // Depth is rounded to a multiple of this, metres (millimetres).
  double quantization_m = 0.001;
  // Seed of the noise.
  uint64_t seed = 1;

  // The default extrinsic (above).
  static Rigid3d DefaultEventFromDepth();
  // Throws InvalidArgumentError naming the first bad field.
  void Check() const;
};

// What the model did to one frame.
struct DepthModelCounts {
  // Pixels with an exact depth.
  int64_t exact = 0;
  // Holes from the range limits, the discontinuities, dark and shiny surfaces.
  int64_t out_of_range = 0;
  int64_t discontinuity = 0;
  int64_t dark = 0;
  int64_t specular = 0;
  // Pixels with a measured depth.
  int64_t measured = 0;
};

// Applies the sensor's errors to an exact depth map: `exact_depth_m` (CV_32FC1, z metres, 0 =
// nothing hit), `albedo` (CV_32FC1, the surface's albedo under the sensor's own light) and
// `specular` (CV_32FC1, Surface::specular) per pixel of `camera`; the noise from `rng`. Returns
// CV_32FC1 metres, 0 = no depth; adds to `counts` when not null. Throws InvalidArgumentError
// for sizes or types that do not match the camera.
cv::Mat ApplyDepthSensorModel(const cv::Mat& exact_depth_m, const cv::Mat& albedo,
                              const cv::Mat& specular, const Camera& camera,
                              const DepthSensorOptions& options, std::mt19937_64* rng,
                              DepthModelCounts* counts = nullptr);

// The depth camera looking at a scene: renders the exact depth, the albedo and the specularity
// from its own pose (the event camera's pose times the extrinsic) and applies the model.
class DepthSensor {
 public:
  // Throws InvalidArgumentError for bad options or a bad scene.
  DepthSensor(const Scene& scene, const DepthSensorOptions& options);
  ~DepthSensor();

  // The frame `index` (its time: first_frame_t_ns + index / fps) with the event camera at
  // `world_from_event`: CV_32FC1 metres, 0 = no depth. The noise depends on the seed and the
  // index only.
  cv::Mat Capture(const Rigid3d& world_from_event, int64_t index,
                  DepthModelCounts* counts = nullptr) const;
  // The time of frame `index`, nanoseconds.
  int64_t FrameTimeNs(int64_t index) const;
  // The options.
  const DepthSensorOptions& options() const { return options_; }

 private:
  DepthSensorOptions options_;
  // The scene under the sensor's own light (albedo only) and with every surface painted its
  // specularity.
  std::unique_ptr<Renderer> albedo_renderer_;
  std::unique_ptr<Renderer> specular_renderer_;
};

}  // namespace evloc::sim
