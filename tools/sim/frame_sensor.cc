#include "tools/sim/frame_sensor.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/common/error.h"

namespace evloc::sim {

std::string LightingConditionName(LightingCondition condition) {
  switch (condition) {
    case LightingCondition::kBright:
      return "bright";
    case LightingCondition::kDim:
      return "dim";
    case LightingCondition::kDark:
      return "dark";
    case LightingCondition::kHdr:
      return "hdr";
  }
  return "unknown";
}

LightingCondition ParseLightingCondition(const std::string& name) {
  for (LightingCondition condition : {LightingCondition::kBright, LightingCondition::kDim,
                                      LightingCondition::kDark, LightingCondition::kHdr}) {
    if (name == LightingConditionName(condition)) return condition;
  }
  throw InvalidArgumentError("Unknown lighting '" + name + "'; expected bright, dim, dark or hdr.");
}

double IlluminationOptions::FactorAt(const Eigen::Vector3d& point_world) const {
  if (IsUniform()) return lit_factor;
  const double signed_distance = split_normal.normalized().dot(point_world - split_point);
  const double lit_weight = 1.0 / (1.0 + std::exp(-4.0 * signed_distance / transition_m));
  return shadow_factor + (lit_factor - shadow_factor) * lit_weight;
}

void IlluminationOptions::Check() const {
  for (double value : {lit_factor, shadow_factor, transition_m}) {
    if (!std::isfinite(value) || value <= 0) {
      throw InvalidArgumentError(
          "Illumination factors and transition width must be positive and finite.");
    }
  }
  if (!split_normal.allFinite() || split_normal.norm() < 1e-12 || !split_point.allFinite()) {
    throw InvalidArgumentError("Illumination split plane is degenerate.");
  }
}

cv::Mat ComputeRayTable(const Camera& camera) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cv::Mat rays(camera.height, camera.width, CV_32FC3);
  for (int row = 0; row < camera.height; ++row) {
    auto* out = rays.ptr<cv::Vec3f>(row);
    for (int col = 0; col < camera.width; ++col) {
      Eigen::Vector3d ray;
      if (camera.Unproject(Eigen::Vector2d(col, row), &ray)) {
        out[col] = cv::Vec3f(static_cast<float>(ray.x()), static_cast<float>(ray.y()),
                             static_cast<float>(ray.z()));
      } else {
        out[col] = cv::Vec3f(nan, nan, nan);
      }
    }
  }
  return rays;
}

void ApplyIllumination(const IlluminationOptions& illumination, const cv::Mat& rays,
                       const Rigid3d& world_from_cam, const cv::Mat& depth, cv::Mat* image) {
  if (illumination.IsUniform()) {
    if (illumination.lit_factor != 1.0) *image *= illumination.lit_factor;
    return;
  }
  if (depth.type() != CV_32FC1 || depth.size() != image->size() || rays.type() != CV_32FC3 ||
      rays.size() != image->size()) {
    throw InvalidArgumentError(
        "ApplyIllumination: CV_32FC1 depth and CV_32FC3 rays of the image "
        "size are needed for non-uniform illumination.");
  }
  const int channels = image->channels();
  const Eigen::Matrix3d rotation = world_from_cam.RotationMatrix();
  for (int row = 0; row < image->rows; ++row) {
    const float* depth_row = depth.ptr<float>(row);
    const auto* ray_row = rays.ptr<cv::Vec3f>(row);
    float* pixel = image->ptr<float>(row);
    for (int col = 0; col < image->cols; ++col, pixel += channels) {
      double factor = illumination.shadow_factor;
      const cv::Vec3f& ray = ray_row[col];
      if (depth_row[col] > 0 && std::isfinite(ray[0])) {
        const Eigen::Vector3d point_cam =
            Eigen::Vector3d(ray[0], ray[1], ray[2]) * static_cast<double>(depth_row[col]);
        factor = illumination.FactorAt(rotation * point_cam + world_from_cam.translation);
      }
      for (int c = 0; c < channels; ++c) pixel[c] = static_cast<float>(pixel[c] * factor);
    }
  }
}

void FrameSensorOptions::Check() const {
  if (!std::isfinite(fps) || fps <= 0) {
    throw InvalidArgumentError("Frame rate must be positive, got " + std::to_string(fps) + ".");
  }
  if (!std::isfinite(exposure_s) || exposure_s <= 0 || exposure_s >= 1.0 / fps) {
    throw InvalidArgumentError("Exposure " + std::to_string(exposure_s) +
                               " s must be positive and shorter than the frame period " +
                               std::to_string(1.0 / fps) + " s.");
  }
  for (double value : {electrons_per_second, full_well_electrons, gain_dn_per_electron}) {
    if (!std::isfinite(value) || value <= 0) {
      throw InvalidArgumentError("Frame sensor rates, full well and gain must be positive.");
    }
  }
  if (!std::isfinite(read_noise_electrons) || read_noise_electrons < 0) {
    throw InvalidArgumentError("Frame sensor read noise must be >= 0.");
  }
}

LightingPreset MakeLightingPreset(LightingCondition condition,
                                  const Eigen::AlignedBox3d& scene_bounds) {
  LightingPreset preset;
  FrameSensorOptions& frames = preset.frames;
  IlluminationOptions& light = preset.illumination;
  frames.electrons_per_second = 1e6;
  frames.full_well_electrons = 10000;
  switch (condition) {
    case LightingCondition::kBright:
      frames.exposure_s = 0.010;
      frames.read_noise_electrons = 3;
      break;
    case LightingCondition::kDim:
      light.lit_factor = light.shadow_factor = 0.1;
      frames.exposure_s = 0.020;
      frames.read_noise_electrons = 4;
      break;
    case LightingCondition::kDark:
      light.lit_factor = light.shadow_factor = 0.02;
      frames.exposure_s = 0.030;
      frames.read_noise_electrons = 5;
      break;
    case LightingCondition::kHdr:
      light.lit_factor = 4.0;
      light.shadow_factor = 0.04;
      light.split_point = scene_bounds.isEmpty() ? Eigen::Vector3d(Eigen::Vector3d::Zero())
                                                 : Eigen::Vector3d(scene_bounds.center());
      light.split_normal = Eigen::Vector3d::UnitX();
      light.transition_m = 0.1;
      frames.exposure_s = 0.010;
      frames.read_noise_electrons = 3;
      break;
  }
  // Gain: radiance 1 under the lit illumination maps to 255 (a fixed auto-exposure outcome);
  // in hdr the gain is set for unit illumination, so the lit part saturates.
  const double reference_illumination =
      condition == LightingCondition::kHdr ? 1.0 : light.lit_factor;
  frames.gain_dn_per_electron =
      255.0 / (reference_illumination * frames.electrons_per_second * frames.exposure_s);
  return preset;
}

ExposureIntegrator::ExposureIntegrator(int64_t start_ns, int64_t end_ns)
    : start_ns_(start_ns), end_ns_(end_ns), last_t_ns_(start_ns) {
  if (end_ns <= start_ns) {
    throw InvalidArgumentError("ExposureIntegrator: the window must have a positive length.");
  }
}

void ExposureIntegrator::Add(const cv::Mat& radiance, int64_t t_ns) {
  if (num_images_ == 0) {
    if (t_ns != start_ns_) {
      throw InvalidArgumentError(
          "ExposureIntegrator: the first image must be at the window start.");
    }
    sum_ = cv::Mat::zeros(radiance.size(), radiance.type());
  } else {
    if (t_ns <= last_t_ns_ || t_ns > end_ns_) {
      throw InvalidArgumentError(
          "ExposureIntegrator: image time outside the window or not after "
          "the previous one.");
    }
    const double half_step_s = 0.5 * static_cast<double>(t_ns - last_t_ns_) * 1e-9;
    cv::scaleAdd(previous_, half_step_s, sum_, sum_);
    cv::scaleAdd(radiance, half_step_s, sum_, sum_);
  }
  radiance.copyTo(previous_);
  last_t_ns_ = t_ns;
  ++num_images_;
}

cv::Mat ExposureIntegrator::Mean() const {
  if (!complete()) {
    throw InvalidArgumentError("ExposureIntegrator: the exposure window is not complete.");
  }
  return sum_ * (1e9 / static_cast<double>(end_ns_ - start_ns_));
}

FrameSensor::FrameSensor(const FrameSensorOptions& options)
    : options_(options), rng_(options.seed ^ 0x5851f42d4c957f2dULL) {
  options_.Check();
}

cv::Mat FrameSensor::Expose(const cv::Mat& mean_radiance) {
  const int channels = mean_radiance.channels();
  if (mean_radiance.depth() != CV_32F || (channels != 1 && channels != 3)) {
    throw InvalidArgumentError("FrameSensor::Expose expects CV_32FC1 or CV_32FC3 radiance.");
  }
  const double electrons_per_unit = options_.electrons_per_second * options_.exposure_s;
  std::normal_distribution<double> normal(0.0, 1.0);
  cv::Mat out(mean_radiance.size(), CV_8UC(channels));
  for (int row = 0; row < mean_radiance.rows; ++row) {
    const float* in = mean_radiance.ptr<float>(row);
    uint8_t* dn = out.ptr<uint8_t>(row);
    for (int col = 0; col < mean_radiance.cols; ++col) {
      for (int c = 0; c < channels; ++c) {
        // RGB in, BGR out (the PNG writer's order).
        const int in_channel = channels == 3 ? 2 - c : 0;
        double electrons = std::max(0.0, static_cast<double>(in[col * channels + in_channel])) *
                           electrons_per_unit;
        if (options_.noise) {
          if (electrons < 1000) {
            electrons = static_cast<double>(std::poisson_distribution<int64_t>(electrons)(rng_));
          } else {  // Gaussian approximation of Poisson, accurate at these counts
            electrons += std::sqrt(electrons) * normal(rng_);
          }
        }
        electrons = std::min(electrons, options_.full_well_electrons);
        if (options_.noise) electrons += options_.read_noise_electrons * normal(rng_);
        const double value = std::round(electrons * options_.gain_dn_per_electron);
        dn[col * channels + c] = static_cast<uint8_t>(std::clamp(value, 0.0, 255.0));
      }
    }
  }
  return out;
}

}  // namespace evloc::sim
