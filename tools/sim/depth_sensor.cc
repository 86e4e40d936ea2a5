#include "tools/sim/depth_sensor.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/common/error.h"

namespace evloc::sim {

Rigid3d DepthSensorOptions::DefaultEventFromDepth() {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 180.0, Eigen::Vector3d::UnitY())),
                 Eigen::Vector3d(0.05, 0.0, 0.0));
}

void DepthSensorOptions::Check() const {
  camera.Check();
  auto fail = [](const std::string& what) { throw InvalidArgumentError("depth camera: " + what); };
  if (!event_from_depth.IsFinite()) fail("the extrinsic event_from_depth is not finite");
  if (!(fps > 0) || !std::isfinite(fps)) fail("the frame rate must be positive");
  if (first_frame_t_ns < 0) fail("the first frame time must be >= 0");
  if (!(noise_at_1m_m >= 0) || !std::isfinite(noise_at_1m_m)) fail("noise_at_1m_m must be >= 0");
  if (!(min_range_m > 0) || !(max_range_m > min_range_m) || !std::isfinite(max_range_m)) {
    fail("need 0 < min_range_m < max_range_m");
  }
  if (!(discontinuity_fraction > 0) || !(discontinuity_fraction < 1)) {
    fail("discontinuity_fraction must lie in (0, 1)");
  }
  if (discontinuity_hole_px < 0 || discontinuity_hole_px > 8) {
    fail("discontinuity_hole_px must lie in [0, 8]");
  }
  if (!(min_return >= 0) || !(min_return < 1)) fail("min_return must lie in [0, 1)");
  if (!(specular_hole_angle_deg >= 0) || !(specular_hole_angle_deg < 90)) {
    fail("specular_hole_angle_deg must lie in [0, 90)");
  }
  if (!(quantization_m >= 0) || !(quantization_m < 0.1)) {
    fail("quantization_m must lie in [0, 0.1) metres");
  }
}

cv::Mat ApplyDepthSensorModel(const cv::Mat& exact_depth_m, const cv::Mat& albedo,
                              const cv::Mat& specular, const Camera& camera,
                              const DepthSensorOptions& options, std::mt19937_64* rng,
                              DepthModelCounts* counts) {
  const cv::Size size(camera.width, camera.height);
  for (const cv::Mat* image : {&exact_depth_m, &albedo, &specular}) {
    if (image->type() != CV_32FC1 || image->size() != size) {
      throw InvalidArgumentError(
          "ApplyDepthSensorModel: depth, albedo and specular must be CV_32FC1 of the camera's " +
          std::to_string(camera.width) + "x" + std::to_string(camera.height) + " size");
    }
  }
  const int width = camera.width;
  const int height = camera.height;
  // The ray (z = 1) of every pixel, to lift neighbours into 3D for the surface normal.
  std::vector<Eigen::Vector3d> rays(static_cast<size_t>(width) * height,
                                    Eigen::Vector3d::Constant(std::nan("")));
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      Eigen::Vector3d ray;
      if (camera.Unproject(Eigen::Vector2d(x, y), &ray) && ray.z() > 1e-9) {
        rays[static_cast<size_t>(y) * width + x] = ray / ray.z();
      }
    }
  }
  auto depth_at = [&](int x, int y) { return exact_depth_m.at<float>(y, x); };
  auto point_at = [&](int x, int y) {
    return Eigen::Vector3d(rays[static_cast<size_t>(y) * width + x] * depth_at(x, y));
  };
  auto valid = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < width && y < height && depth_at(x, y) > 0 &&
           !std::isnan(rays[static_cast<size_t>(y) * width + x].x());
  };
  const double cos_specular = std::cos(options.specular_hole_angle_deg * M_PI / 180.0);
  const int r = options.discontinuity_hole_px;
  std::normal_distribution<double> unit_normal(0.0, 1.0);
  DepthModelCounts local;
  cv::Mat measured(size, CV_32FC1, cv::Scalar(0));
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      // One draw per pixel whatever happens to it: the noise of a pixel does not depend on the
      // holes elsewhere.
      const double noise = unit_normal(*rng);
      if (!valid(x, y)) continue;
      ++local.exact;
      const double z = depth_at(x, y);
      if (z < options.min_range_m || z > options.max_range_m) {
        ++local.out_of_range;
        continue;
      }
      bool shadowed = false;
      for (int dy = -r; dy <= r && !shadowed; ++dy) {
        for (int dx = -r; dx <= r && !shadowed; ++dx) {
          if (!valid(x + dx, y + dy)) continue;
          shadowed = depth_at(x + dx, y + dy) < z * (1.0 - options.discontinuity_fraction);
        }
      }
      if (shadowed) {
        ++local.discontinuity;
        continue;
      }
      // The surface normal from the neighbours on the same surface (within the discontinuity
      // fraction of this depth; central differences where both are).
      auto same_surface = [&](int nx, int ny) {
        return valid(nx, ny) &&
               std::abs(depth_at(nx, ny) - z) <= z * options.discontinuity_fraction;
      };
      const int x0 = same_surface(x - 1, y) ? x - 1 : x;
      const int x1 = same_surface(x + 1, y) ? x + 1 : x;
      const int y0 = same_surface(x, y - 1) ? y - 1 : y;
      const int y1 = same_surface(x, y + 1) ? y + 1 : y;
      double cos_incidence = 1.0;
      if (x1 != x0 && y1 != y0) {
        const Eigen::Vector3d normal =
            (point_at(x1, y) - point_at(x0, y)).cross(point_at(x, y1) - point_at(x, y0));
        const Eigen::Vector3d point = point_at(x, y);
        if (normal.norm() > 0) {
          cos_incidence = std::abs(normal.dot(point)) / (normal.norm() * point.norm());
        }
      }
      if (albedo.at<float>(y, x) * cos_incidence < options.min_return) {
        ++local.dark;
        continue;
      }
      if (specular.at<float>(y, x) >= 0.5f && cos_incidence > cos_specular) {
        ++local.specular;
        continue;
      }
      double value = z + noise * options.noise_at_1m_m * z * z;
      if (options.quantization_m > 0) {
        value = std::round(value / options.quantization_m) * options.quantization_m;
      }
      if (!(value > 0)) continue;
      measured.at<float>(y, x) = static_cast<float>(value);
      ++local.measured;
    }
  }
  if (counts != nullptr) {
    counts->exact += local.exact;
    counts->out_of_range += local.out_of_range;
    counts->discontinuity += local.discontinuity;
    counts->dark += local.dark;
    counts->specular += local.specular;
    counts->measured += local.measured;
  }
  return measured;
}

namespace {

// The scene as the depth camera's own light sees it: albedo only (no daylight, lamps or
// shading), or every surface painted its specularity.
Scene SensorScene(const Scene& scene, bool paint_specular) {
  Scene sensor = scene;
  sensor.daylight = 1.0;
  sensor.sky = 0.0;
  sensor.point_lights.clear();
  for (Surface& surface : sensor.surfaces) {
    surface.shading = 1.0f;
    if (paint_specular) {
      surface.texture = Texture();
      surface.texture.base = Gray(surface.specular);
    }
  }
  return sensor;
}

}  // namespace

DepthSensor::DepthSensor(const Scene& scene, const DepthSensorOptions& options)
    : options_(options) {
  options_.Check();
  scene.Check();
  RenderOptions render;
  render.supersampling = 1;  // depth and albedo at the pixel centre
  albedo_renderer_ = std::make_unique<Renderer>(SensorScene(scene, false), options_.camera, render);
  specular_renderer_ =
      std::make_unique<Renderer>(SensorScene(scene, true), options_.camera, render);
}

DepthSensor::~DepthSensor() = default;

int64_t DepthSensor::FrameTimeNs(int64_t index) const {
  return options_.first_frame_t_ns +
         static_cast<int64_t>(std::llround(static_cast<double>(index) * 1e9 / options_.fps));
}

cv::Mat DepthSensor::Capture(const Rigid3d& world_from_event, int64_t index,
                             DepthModelCounts* counts) const {
  const Rigid3d world_from_depth = world_from_event * options_.event_from_depth;
  cv::Mat albedo;
  cv::Mat depth;
  albedo_renderer_->Render(world_from_depth, &albedo, nullptr, &depth);
  cv::Mat specular;
  specular_renderer_->Render(world_from_depth, &specular);
  // A generator per frame: the same frame gets the same noise in any order.
  std::seed_seq seed{static_cast<uint32_t>(options_.seed),
                     static_cast<uint32_t>(options_.seed >> 32), static_cast<uint32_t>(index),
                     static_cast<uint32_t>(index >> 32), 0xde97u};
  std::mt19937_64 rng(seed);
  return ApplyDepthSensorModel(depth, albedo, specular, options_.camera, options_, &rng, counts);
}

}  // namespace evloc::sim
