#include "tools/sim/motion.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;
// Components per axis of the sinusoid sums.
constexpr int kComponentsPerAxis = 3;
// Sampling step used to measure the peak speeds while calibrating the time scale, seconds.
constexpr double kCalibrationStepS = 1e-3;

// The largest finite-difference speed of f over [0, duration_s].
template <typename Distance>
double PeakRate(double duration_s, const Distance& distance_between) {
  const int steps = std::max(1, static_cast<int>(std::ceil(duration_s / kCalibrationStepS)));
  const double step = duration_s / steps;
  double peak = 0;
  for (int i = 0; i < steps; ++i) {
    peak = std::max(peak, distance_between(i * step, (i + 1) * step) / step);
  }
  return peak;
}

// Finds the time scale s such that the peak rate of f(s * t) over [0, duration] equals `target`.
// That peak is s times the peak rate of f over [0, s * duration], which grows with s, so the
// solution is unique: bracket it, then bisect on log s.
template <typename DistanceForScale>
double CalibrateTimeScale(double duration_s, double target, const DistanceForScale& distance) {
  const auto peak_for = [&](double scale) {
    return PeakRate(duration_s, [&](double a, double b) { return distance(scale, a, b); });
  };
  double low = 1.0;
  double high = 1.0;
  while (peak_for(low) > target && low > 1e-9) low *= 0.5;
  while (peak_for(high) < target && high < 1e9) high *= 2.0;
  for (int iteration = 0; iteration < 40 && high / low > 1.0 + 1e-6; ++iteration) {
    const double middle = std::sqrt(low * high);
    (peak_for(middle) < target ? low : high) = middle;
  }
  return std::sqrt(low * high);
}

}  // namespace

std::string MotionProfileName(MotionProfile profile) {
  switch (profile) {
    case MotionProfile::kSlow:
      return "slow";
    case MotionProfile::kMid:
      return "mid";
    case MotionProfile::kFast:
      return "fast";
    case MotionProfile::kAggressive:
      return "aggressive";
  }
  return "unknown";
}

MotionProfile ParseMotionProfile(const std::string& name) {
  for (MotionProfile profile : {MotionProfile::kSlow, MotionProfile::kMid, MotionProfile::kFast,
                                MotionProfile::kAggressive}) {
    if (name == MotionProfileName(profile)) return profile;
  }
  throw InvalidArgumentError("Unknown motion profile '" + name +
                             "'; expected slow, mid, fast or aggressive.");
}

PeakSpeeds PeakSpeedsOf(MotionProfile profile) {
  switch (profile) {
    case MotionProfile::kSlow:
      return {0.15, 20 * kDegree};
    case MotionProfile::kMid:
      return {0.4, 50 * kDegree};
    case MotionProfile::kFast:
      return {0.8, 120 * kDegree};
    case MotionProfile::kAggressive:
      return {1.5, 300 * kDegree};
  }
  return {};
}

Eigen::Quaterniond LookAtRotation(const Eigen::Vector3d& position, const Eigen::Vector3d& look_at,
                                  const Eigen::Vector3d& up) {
  const Eigen::Vector3d forward = look_at - position;
  if (forward.norm() < 1e-9 || up.norm() < 1e-9) {
    throw InvalidArgumentError("LookAtRotation: the camera position equals the look-at point.");
  }
  const Eigen::Vector3d z = forward.normalized();
  Eigen::Vector3d x = (-up).cross(z);  // image right = down x forward
  if (x.norm() < 1e-6) {
    throw InvalidArgumentError("LookAtRotation: the viewing direction is parallel to up.");
  }
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d rotation;
  rotation.col(0) = x;
  rotation.col(1) = y;
  rotation.col(2) = z;
  return Eigen::Quaterniond(rotation).normalized();
}

namespace {

double SumOfVibrations(const std::vector<Vibration>& vibrations, double t_s) {
  double sum = 0;
  for (const Vibration& v : vibrations) {
    sum += v.amplitude * std::sin(2 * std::numbers::pi * v.frequency_hz * t_s + v.phase);
  }
  return sum;
}

// `count` sinusoids with seeded frequencies in [low_hz, high_hz] and phases, amplitudes summing to
// `total`.
std::vector<Vibration> SeededVibration(std::mt19937_64* rng, int count, double total, double low_hz,
                                       double high_hz) {
  std::uniform_real_distribution<double> frequency(low_hz, high_hz), phase(0, 2 * std::numbers::pi),
      share(0.5, 1.0);
  std::vector<Vibration> vibrations(count);
  double shares = 0;
  for (Vibration& v : vibrations) {
    v.frequency_hz = frequency(*rng);
    v.phase = phase(*rng);
    v.amplitude = share(*rng);
    shares += v.amplitude;
  }
  for (Vibration& v : vibrations) v.amplitude *= total / shares;
  return vibrations;
}

std::vector<Vibration> Concatenate(std::vector<Vibration> a, const std::vector<Vibration>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

}  // namespace

void PathMotionOptions::Check() const {
  if (route.size() < 2)
    throw InvalidArgumentError("PathMotion: the route needs at least 2 points.");
  for (const Eigen::Vector2d& point : route) {
    if (!point.allFinite())
      throw InvalidArgumentError("PathMotion: the route has a non-finite point.");
  }
  if (!(speed_m_per_s > 0) || !std::isfinite(speed_m_per_s)) {
    throw InvalidArgumentError("PathMotion: the speed must be positive.");
  }
  if (!(height_m > 0) || !std::isfinite(height_m) || !(heading_window_m > 0)) {
    throw InvalidArgumentError("PathMotion: height and heading window must be positive.");
  }
  if (duration_s && !(*duration_s > 0 && std::isfinite(*duration_s))) {
    throw InvalidArgumentError("PathMotion: the duration must be positive.");
  }
  if (!(start_m >= 0) || !std::isfinite(start_m) || !std::isfinite(pitch_down_deg) ||
      !std::isfinite(yaw_offset_deg)) {
    throw InvalidArgumentError(
        "PathMotion: start, pitch and yaw offset must be finite, start >= 0.");
  }
  for (const auto* list : {&pitch_vibration, &roll_vibration, &yaw_vibration, &height_vibration}) {
    for (const Vibration& v : *list) {
      if (!std::isfinite(v.amplitude) || !std::isfinite(v.frequency_hz) ||
          !std::isfinite(v.phase)) {
        throw InvalidArgumentError("PathMotion: vibrations must be finite.");
      }
    }
  }
}

PathMotionOptions VehiclePathOptions(std::vector<Eigen::Vector2d> route, double speed_m_per_s,
                                     uint64_t seed) {
  PathMotionOptions options;
  options.route = std::move(route);
  options.speed_m_per_s = speed_m_per_s;
  options.height_m = 1.5;
  options.pitch_down_deg = 5;
  std::mt19937_64 rng(seed * 104729 + 3);
  options.pitch_vibration = Concatenate(SeededVibration(&rng, 3, 0.3, 1.0, 3.0),
                                        SeededVibration(&rng, 2, 0.03, 11.0, 15.0));
  options.roll_vibration = Concatenate(SeededVibration(&rng, 3, 0.3, 1.0, 3.0),
                                       SeededVibration(&rng, 2, 0.03, 11.0, 15.0));
  options.yaw_vibration = SeededVibration(&rng, 2, 0.1, 0.5, 2.0);
  options.height_vibration = Concatenate(SeededVibration(&rng, 3, 0.005, 1.0, 3.0),
                                         SeededVibration(&rng, 2, 0.002, 11.0, 15.0));
  return options;
}

PathMotionOptions PedestrianPathOptions(std::vector<Eigen::Vector2d> route, uint64_t seed) {
  PathMotionOptions options;
  options.route = std::move(route);
  options.speed_m_per_s = 1.4;
  options.height_m = 1.4;
  options.pitch_down_deg = 8;
  std::mt19937_64 rng(seed * 7727 + 11);
  std::uniform_real_distribution<double> phase(0, 2 * std::numbers::pi);
  const double stride_hz = 0.95;
  options.height_vibration = {Vibration{0.025, 2 * stride_hz, phase(rng)}};
  options.roll_vibration =
      Concatenate({Vibration{1.5, stride_hz, phase(rng)}}, SeededVibration(&rng, 3, 0.5, 2.0, 6.0));
  options.yaw_vibration =
      Concatenate({Vibration{2.5, stride_hz, phase(rng)}}, SeededVibration(&rng, 3, 1.0, 0.2, 3.0));
  options.pitch_vibration = Concatenate({Vibration{1.0, 2 * stride_hz, phase(rng)}},
                                        SeededVibration(&rng, 3, 1.0, 0.2, 3.0));
  return options;
}

PathMotion::PathMotion(PathMotionOptions options) : options_(std::move(options)) {
  options_.Check();
  cumulative_.reserve(options_.route.size());
  cumulative_.push_back(0);
  for (size_t i = 1; i < options_.route.size(); ++i) {
    cumulative_.push_back(cumulative_.back() + (options_.route[i] - options_.route[i - 1]).norm());
  }
  const double available = length_m() - options_.start_m;
  if (!(available > 0)) {
    throw InvalidArgumentError("PathMotion: the start (" + std::to_string(options_.start_m) +
                               " m) lies beyond the route's end (" + std::to_string(length_m()) +
                               " m).");
  }
  const double duration_s = options_.duration_s.value_or(available / options_.speed_m_per_s);
  if (duration_s * options_.speed_m_per_s > available + 1e-9) {
    throw InvalidArgumentError("PathMotion: " + std::to_string(duration_s) + " s at " +
                               std::to_string(options_.speed_m_per_s) + " m/s needs " +
                               std::to_string(duration_s * options_.speed_m_per_s) +
                               " m of route, but only " + std::to_string(available) +
                               " m remain after the start; shorten the duration.");
  }
  duration_ns_ = static_cast<int64_t>(std::llround(duration_s * 1e9));
}

Eigen::Vector2d PathMotion::PointAt(double s) const {
  s = std::clamp(s, 0.0, length_m());
  const auto upper = std::upper_bound(cumulative_.begin(), cumulative_.end(), s);
  if (upper == cumulative_.end()) return options_.route.back();
  const size_t i = static_cast<size_t>(upper - cumulative_.begin());
  const double piece = cumulative_[i] - cumulative_[i - 1];
  const double alpha = piece > 0 ? (s - cumulative_[i - 1]) / piece : 0;
  return options_.route[i - 1] + alpha * (options_.route[i] - options_.route[i - 1]);
}

Rigid3d PathMotion::WorldFromCam(int64_t t_ns) const {
  const double t_s = std::clamp<int64_t>(t_ns, 0, duration_ns_) * 1e-9;
  const double s = options_.start_m + options_.speed_m_per_s * t_s;
  const Eigen::Vector2d at = PointAt(s);
  const double half = options_.heading_window_m / 2;
  Eigen::Vector2d along = PointAt(s + half) - PointAt(s - half);
  if (along.norm() < 1e-9) along = options_.route.back() - options_.route.front();
  const double deg = std::numbers::pi / 180;
  const double heading =
      std::atan2(along.y(), along.x()) +
      (options_.yaw_offset_deg + SumOfVibrations(options_.yaw_vibration, t_s)) * deg;
  const double pitch =
      (options_.pitch_down_deg + SumOfVibrations(options_.pitch_vibration, t_s)) * deg;
  const Eigen::Vector3d position(
      at.x(), at.y(), options_.height_m + SumOfVibrations(options_.height_vibration, t_s));
  const Eigen::Vector3d forward(std::cos(heading) * std::cos(pitch),
                                std::sin(heading) * std::cos(pitch), -std::sin(pitch));
  const Eigen::Quaterniond base =
      LookAtRotation(position, position + forward, Eigen::Vector3d::UnitZ());
  // Roll about the optical axis.
  const double roll = SumOfVibrations(options_.roll_vibration, t_s) * deg;
  const Eigen::Quaterniond rotation =
      base * Eigen::Quaterniond(Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()));
  return Rigid3d(rotation.normalized(), position);
}

void SmoothMotionOptions::Check() const {
  if (!std::isfinite(duration_s) || duration_s <= 0) {
    throw InvalidArgumentError("Motion duration must be positive, got " +
                               std::to_string(duration_s) + " s.");
  }
  if (camera_region.isEmpty() || !camera_region.min().allFinite() ||
      !camera_region.max().allFinite()) {
    throw InvalidArgumentError("Motion camera_region is empty or not finite.");
  }
  if (!(region_fill > 0 && region_fill <= 1)) {
    throw InvalidArgumentError("Motion region_fill must be in (0, 1].");
  }
  for (double angle : {max_yaw_deg, max_pitch_deg, max_roll_deg}) {
    if (!std::isfinite(angle) || angle < 0) {
      throw InvalidArgumentError("Motion angle limits must be finite and >= 0.");
    }
  }
}

SmoothMotion::SmoothMotion(const SmoothMotionOptions& options) {
  options.Check();
  duration_ns_ = static_cast<int64_t>(std::llround(options.duration_s * 1e9));
  centre_ = options.camera_region.center();
  base_rotation_ = LookAtRotation(centre_, options.viewpoint.look_at, options.viewpoint.up);

  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> frequency(0.05, 0.3);
  std::uniform_real_distribution<double> phase(0, 2 * std::numbers::pi);
  std::uniform_real_distribution<double> weight(0.5, 1.0);
  const Eigen::Vector3d half_extent = 0.5 * options.camera_region.sizes() * options.region_fill;
  const Eigen::Vector3d max_angle =
      Eigen::Vector3d(options.max_pitch_deg, options.max_yaw_deg, options.max_roll_deg) * kDegree;
  // Amplitudes of each axis sum to the allowed excursion, so the sum never leaves it.
  auto make_axis = [&](double excursion) {
    std::vector<Component> components(kComponentsPerAxis);
    double weight_sum = 0;
    for (Component& component : components) {
      component.amplitude = weight(rng);
      component.frequency_hz = frequency(rng);
      component.phase = phase(rng);
      weight_sum += component.amplitude;
    }
    for (Component& component : components) component.amplitude *= excursion / weight_sum;
    return components;
  };
  for (int axis = 0; axis < 3; ++axis) position_components_[axis] = make_axis(half_extent[axis]);
  // Rotation axes in the camera frame: x = pitch, y = yaw (image y is down), z = roll.
  for (int axis = 0; axis < 3; ++axis) rotation_components_[axis] = make_axis(max_angle[axis]);

  const PeakSpeeds target = PeakSpeedsOf(options.profile);
  const double duration_s = options.duration_s;
  position_time_scale_ =
      CalibrateTimeScale(duration_s, target.linear_m_per_s, [&](double scale, double a, double b) {
        return (Evaluate(position_components_, scale, b) - Evaluate(position_components_, scale, a))
            .norm();
      });
  rotation_time_scale_ = CalibrateTimeScale(
      duration_s, target.angular_rad_per_s, [&](double scale, double a, double b) {
        return AngleBetween(ExpSO3(Evaluate(rotation_components_, scale, a)),
                            ExpSO3(Evaluate(rotation_components_, scale, b)));
      });
}

Eigen::Vector3d SmoothMotion::Evaluate(const std::array<std::vector<Component>, 3>& components,
                                       double scale, double t_s) {
  Eigen::Vector3d value = Eigen::Vector3d::Zero();
  for (int axis = 0; axis < 3; ++axis) {
    for (const Component& component : components[axis]) {
      value[axis] +=
          component.amplitude *
          std::sin(2 * std::numbers::pi * component.frequency_hz * scale * t_s + component.phase);
    }
  }
  return value;
}

Rigid3d SmoothMotion::WorldFromCam(int64_t t_ns) const {
  const double t_s = static_cast<double>(std::clamp<int64_t>(t_ns, 0, duration_ns_)) * 1e-9;
  const Eigen::Vector3d position =
      centre_ + Evaluate(position_components_, position_time_scale_, t_s);
  const Eigen::Quaterniond rotation =
      base_rotation_ * ExpSO3(Evaluate(rotation_components_, rotation_time_scale_, t_s));
  return Rigid3d(rotation, position);
}

RecordedMotion::RecordedMotion(const Trajectory& recorded, const Rigid3d& anchor_world_from_cam,
                               std::optional<int64_t> duration_ns)
    : recorded_(recorded) {
  if (recorded.size() < 2) {
    throw InvalidArgumentError("A recorded trajectory needs at least 2 poses, got " +
                               std::to_string(recorded.size()) + ".");
  }
  const int64_t available_ns = recorded.duration_ns();
  duration_ns_ = duration_ns.value_or(available_ns);
  if (duration_ns_ <= 0 || duration_ns_ > available_ns) {
    throw InvalidArgumentError("The recorded trajectory lasts " +
                               std::to_string(available_ns * 1e-9) + " s; a duration of " +
                               std::to_string(duration_ns_ * 1e-9) +
                               " s cannot be replayed. Pass a --duration of at most that.");
  }
  world_from_first_ = anchor_world_from_cam * recorded.poses().front().world_from_cam.Inverse();
}

Rigid3d RecordedMotion::WorldFromCam(int64_t t_ns) const {
  const int64_t clamped = std::clamp<int64_t>(t_ns, 0, duration_ns_);
  return world_from_first_ * *recorded_.Lookup(recorded_.start_ns() + clamped);
}

PeakSpeeds MeasurePeakSpeeds(const CameraMotion& motion, int64_t step_ns) {
  PeakSpeeds peak;
  Rigid3d previous = motion.WorldFromCam(0);
  for (int64_t t = step_ns; t <= motion.duration_ns(); t += step_ns) {
    const Rigid3d current = motion.WorldFromCam(t);
    const double dt = step_ns * 1e-9;
    peak.linear_m_per_s =
        std::max(peak.linear_m_per_s, (current.translation - previous.translation).norm() / dt);
    peak.angular_rad_per_s =
        std::max(peak.angular_rad_per_s, AngleBetween(current.rotation, previous.rotation) / dt);
    previous = current;
  }
  return peak;
}

Trajectory SampleMotion(const CameraMotion& motion, double rate_hz) {
  if (!(rate_hz > 0)) throw InvalidArgumentError("SampleMotion: rate must be positive.");
  const int64_t duration = motion.duration_ns();
  const auto count = static_cast<int64_t>(std::floor(duration * 1e-9 * rate_hz));
  std::vector<TimedPose> poses;
  poses.reserve(count + 2);
  for (int64_t i = 0; i <= count; ++i) {
    const auto t_ns = static_cast<int64_t>(std::llround(i * 1e9 / rate_hz));
    if (t_ns > duration) break;
    poses.push_back({t_ns, motion.WorldFromCam(t_ns)});
  }
  if (poses.back().t_ns < duration) poses.push_back({duration, motion.WorldFromCam(duration)});
  return Trajectory(std::move(poses));
}

}  // namespace evloc::sim
