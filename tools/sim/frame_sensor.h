// The simulated frame camera and the lighting of a simulated sequence: an illumination field
// scaling the rendered radiance (seen by both the event and the frame camera), exposure
// integration (motion blur), and a noisy 8-bit sensor (docs/simulator.md, "Frames and lighting").
#pragma once

#include <cstdint>
#include <random>
#include <string>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"

namespace evloc::sim {

// The `--lighting` presets.
enum class LightingCondition { kBright, kDim, kDark, kHdr };

// "bright", "dim", "dark" or "hdr".
std::string LightingConditionName(LightingCondition condition);
// Parses a lighting name; throws InvalidArgumentError naming the valid values otherwise.
LightingCondition ParseLightingCondition(const std::string& name);

// Illumination of the scene: a factor multiplying the rendered albedo-times-shading radiance.
// Uniform, or (hdr) a brightly lit half-space and a shadowed one with a smooth transition.
struct IlluminationOptions {
  // Factor in the lit part (the whole scene when not split), > 0.
  double lit_factor = 1.0;
  // Factor in the shadowed part, > 0; equal to lit_factor for uniform illumination.
  double shadow_factor = 1.0;
  // A point of the plane separating lit and shadowed parts, world metres.
  Eigen::Vector3d split_point = Eigen::Vector3d::Zero();
  // Normal of that plane, pointing into the lit part (normalised on use).
  Eigen::Vector3d split_normal = Eigen::Vector3d::UnitX();
  // Width of the transition, metres (a logistic ramp), > 0.
  double transition_m = 0.1;

  // True when the illumination is the same everywhere.
  bool IsUniform() const { return lit_factor == shadow_factor; }
  // The factor at a world point.
  double FactorAt(const Eigen::Vector3d& point_world) const;
  // Throws InvalidArgumentError for non-positive or non-finite factors or width, or a zero normal.
  void Check() const;
};

// The ray of every pixel in the camera frame with z = 1 (CV_32FC3); NaN where the pixel cannot be
// unprojected through the lens.
cv::Mat ComputeRayTable(const Camera& camera);

// Multiplies every channel of `image` (CV_32FC1 or CV_32FC3) by the illumination factor at the
// world point seen by each pixel (ray from `rays` (ComputeRayTable) times `depth`, z metres;
// pixels with depth 0 or no ray get the shadow factor). Uniform illumination is a plain scaling
// and ignores rays and depth.
void ApplyIllumination(const IlluminationOptions& illumination, const cv::Mat& rays,
                       const Rigid3d& world_from_cam, const cv::Mat& depth, cv::Mat* image);

// Parameters of the frame camera.
struct FrameSensorOptions {
  // Frames per second; the frame time stamp is the middle of its exposure.
  double fps = 30;
  // Exposure time, seconds; must be below 1 / fps.
  double exposure_s = 0.005;
  // Electrons collected per second by a pixel of radiance 1 (after illumination).
  double electrons_per_second = 2e6;
  // Full-well capacity, electrons: the pixel clips there.
  double full_well_electrons = 10000;
  // Digital numbers (8 bit) per electron.
  double gain_dn_per_electron = 255.0 / 10000;
  // Read noise standard deviation, electrons.
  double read_noise_electrons = 3;
  // Whether to add shot and read noise (false: the noise-free expectation, still quantised).
  bool noise = true;
  // Seed of the noise generator.
  uint64_t seed = 1;

  // Throws InvalidArgumentError for non-positive rates, an exposure not in (0, 1/fps), or
  // negative noise.
  void Check() const;
};

// A lighting preset: the illumination and the frame camera settings that go with it
// (table in docs/simulator.md).
struct LightingPreset {
  // The scene illumination.
  IlluminationOptions illumination;
  // The frame camera settings (fps and seed are left at their defaults).
  FrameSensorOptions frames;
};

// The preset of a lighting condition. `scene_bounds` places the hdr split plane.
LightingPreset MakeLightingPreset(LightingCondition condition,
                                  const Eigen::AlignedBox3d& scene_bounds);

// Integrates radiance images over one exposure window [start_ns, end_ns] with the trapezoidal
// rule over the images added in time order (the first at start_ns, the last at end_ns), giving
// the time-averaged radiance: motion blur.
class ExposureIntegrator {
 public:
  // Starts a window; throws InvalidArgumentError unless start_ns < end_ns.
  ExposureIntegrator(int64_t start_ns, int64_t end_ns);
  // Adds the radiance (CV_32FC3 or CV_32FC1) at t_ns, inside the window and after the previous.
  // Throws InvalidArgumentError otherwise.
  void Add(const cv::Mat& radiance, int64_t t_ns);
  // True when an image at end_ns was added.
  bool complete() const { return last_t_ns_ == end_ns_; }
  // Number of images added.
  int num_images() const { return num_images_; }
  // The time-averaged radiance; throws InvalidArgumentError unless complete().
  cv::Mat Mean() const;

 private:
  int64_t start_ns_;
  int64_t end_ns_;
  int64_t last_t_ns_ = 0;
  int num_images_ = 0;
  cv::Mat previous_;
  cv::Mat sum_;  // integral in radiance x seconds
};

// Turns mean radiance over an exposure into an 8-bit image: electrons = radiance x rate x
// exposure, Poisson shot noise, clipping at the full well, Gaussian read noise, gain, rounding
// and clipping to [0, 255].
class FrameSensor {
 public:
  // Throws InvalidArgumentError when options fail Check().
  explicit FrameSensor(const FrameSensorOptions& options);
  // CV_32FC3 (RGB) or CV_32FC1 mean radiance in, CV_8UC3 (BGR, for PNG) or CV_8UC1 out.
  cv::Mat Expose(const cv::Mat& mean_radiance);
  // The options.
  const FrameSensorOptions& options() const { return options_; }

 private:
  FrameSensorOptions options_;
  std::mt19937_64 rng_;
};

}  // namespace evloc::sim
