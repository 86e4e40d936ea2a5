// Camera motion for the simulator: smooth seeded trajectories with preset peak speeds, and
// recorded trajectories (TUM) replayed at a viewpoint of the scene (docs/simulator.md).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/geometry/rigid3.h"
#include "core/trajectory/trajectory.h"

namespace evloc::sim {

// A camera motion: the pose world_from_cam at every time in [0, duration_ns()].
class CameraMotion {
 public:
  virtual ~CameraMotion() = default;
  // The pose at t_ns (clamped to [0, duration_ns()]).
  virtual Rigid3d WorldFromCam(int64_t t_ns) const = 0;
  // Length of the motion, nanoseconds.
  virtual int64_t duration_ns() const = 0;
};

// The speed presets of `--motion`, named as the paper's sequences (slow, mid, fast) plus an
// aggressive one beyond them.
enum class MotionProfile { kSlow, kMid, kFast, kAggressive };

// "slow", "mid", "fast" or "aggressive".
std::string MotionProfileName(MotionProfile profile);
// Parses a profile name; throws InvalidArgumentError naming the valid values otherwise.
MotionProfile ParseMotionProfile(const std::string& name);

// Peak speeds of a motion profile.
struct PeakSpeeds {
  // Peak linear speed of the camera centre, m/s.
  double linear_m_per_s = 0;
  // Peak angular speed, rad/s.
  double angular_rad_per_s = 0;
};

// The peak speeds of a preset (table in docs/simulator.md).
PeakSpeeds PeakSpeedsOf(MotionProfile profile);

// Where the camera starts and what it looks at.
struct Viewpoint {
  // Camera centre, world metres.
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  // Point the optical axis goes through at the base orientation, world metres.
  Eigen::Vector3d look_at = Eigen::Vector3d::UnitX();
  // World up direction (image rows point against it).
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
};

// The orientation world_from_cam whose optical axis (z) points from `position` to `look_at`, with
// the image y axis (down) as close as possible to -up. Throws InvalidArgumentError when the
// direction is zero or parallel to up.
Eigen::Quaterniond LookAtRotation(const Eigen::Vector3d& position, const Eigen::Vector3d& look_at,
                                  const Eigen::Vector3d& up);

// Options of the smooth seeded motion.
struct SmoothMotionOptions {
  // Speed preset.
  MotionProfile profile = MotionProfile::kMid;
  // Duration, seconds.
  double duration_s = 10;
  // Seed of the phases and frequencies (same seed, same motion).
  uint64_t seed = 1;
  // Box the camera centre stays inside, world metres.
  Eigen::AlignedBox3d camera_region{Eigen::Vector3d(-0.5, -0.5, 1.0),
                                    Eigen::Vector3d(0.5, 0.5, 1.6)};
  // Base viewpoint: the motion oscillates around its orientation; its position is unused (the
  // motion is centred on the region's centre).
  Viewpoint viewpoint;
  // Fraction of the region's half-extent the position oscillation may use, in (0, 1].
  double region_fill = 0.8;
  // Largest yaw excursion from the base orientation, degrees.
  double max_yaw_deg = 30;
  // Largest pitch excursion, degrees.
  double max_pitch_deg = 15;
  // Largest roll excursion, degrees.
  double max_roll_deg = 8;

  // Throws InvalidArgumentError for a non-positive duration, an empty region, region_fill outside
  // (0, 1] or negative or non-finite angles.
  void Check() const;
};

// A smooth motion: position and rotation vector are each a sum of three sinusoids per axis with
// seeded frequencies and phases, time-scaled so that the measured peak speeds over the duration
// equal the preset's (within 0.1 %).
class SmoothMotion : public CameraMotion {
 public:
  // Builds the motion; throws InvalidArgumentError when options fail Check().
  explicit SmoothMotion(const SmoothMotionOptions& options);
  Rigid3d WorldFromCam(int64_t t_ns) const override;
  int64_t duration_ns() const override { return duration_ns_; }

 private:
  struct Component {
    double amplitude;
    double frequency_hz;
    double phase;
  };
  static Eigen::Vector3d Evaluate(const std::array<std::vector<Component>, 3>& components,
                                  double scale, double t_s);

  int64_t duration_ns_;
  Eigen::Vector3d centre_;
  Eigen::Quaterniond base_rotation_;
  std::array<std::vector<Component>, 3> position_components_;
  std::array<std::vector<Component>, 3> rotation_components_;
  double position_time_scale_ = 1;
  double rotation_time_scale_ = 1;
};

// A recorded trajectory replayed relative to its first pose and anchored at a viewpoint:
// world_from_cam(t) = anchor * first^-1 * recorded(first time + t).
class RecordedMotion : public CameraMotion {
 public:
  // Replays `recorded` for `duration_ns` (the whole recording when std::nullopt). Throws
  // InvalidArgumentError when it has fewer than 2 poses or is shorter than the duration asked.
  RecordedMotion(const Trajectory& recorded, const Rigid3d& anchor_world_from_cam,
                 std::optional<int64_t> duration_ns);
  Rigid3d WorldFromCam(int64_t t_ns) const override;
  int64_t duration_ns() const override { return duration_ns_; }

 private:
  Trajectory recorded_;
  Rigid3d world_from_first_;
  int64_t duration_ns_;
};

// One sinusoid of a vibration: amplitude * sin(2 pi frequency t + phase).
struct Vibration {
  // Amplitude (degrees for angles, metres for heights).
  double amplitude = 0;
  // Frequency, Hz.
  double frequency_hz = 1;
  // Phase, radians.
  double phase = 0;
};

// A camera carried along a 2D route over flat ground at constant speed: a vehicle's forward
// camera or a pedestrian's hand-held one. The optical axis follows the route's heading (smoothed
// over `heading_window_m`) turned by `yaw_offset_deg`, tilted down by `pitch_down_deg`; pitch,
// roll, yaw and height vibrate by sums of sinusoids (docs/simulator.md, "Paths").
struct PathMotionOptions {
  // The route, world (x, y) metres, at least two points, densely sampled (ResamplePolyline).
  std::vector<Eigen::Vector2d> route;
  // Speed along the route, m/s.
  double speed_m_per_s = 5;
  // Camera height above the ground (z = 0), metres.
  double height_m = 1.5;
  // Where along the route the motion starts, metres.
  double start_m = 0;
  // Duration, seconds; unset: until the end of the route.
  std::optional<double> duration_s;
  // Downward tilt of the optical axis, degrees.
  double pitch_down_deg = 5;
  // Turn of the optical axis from the heading, degrees (positive: to the left, about world z).
  double yaw_offset_deg = 0;
  // The heading is the direction between the route points this far behind and ahead, metres.
  double heading_window_m = 2;
  // Vibrations of pitch, roll and yaw (degrees) and of the height (metres).
  std::vector<Vibration> pitch_vibration, roll_vibration, yaw_vibration, height_vibration;

  // Throws InvalidArgumentError for a route of fewer than 2 points or non-finite points, a
  // non-positive speed, height, window or duration, a start outside the route, or non-finite
  // vibrations.
  void Check() const;
};

// The vehicle preset: a camera 1.5 m up, 5 degrees down, at `speed_m_per_s`, with the small
// pitch/roll of a car body on its suspension (about 0.3 degrees at 1-3 Hz) and a faint engine and
// road vibration (0.03 degrees, 2 mm at 11-15 Hz), seeded.
PathMotionOptions VehiclePathOptions(std::vector<Eigen::Vector2d> route, double speed_m_per_s,
                                     uint64_t seed);
// The pedestrian preset: a hand-held camera 1.4 m up, 8 degrees down, at 1.4 m/s with the gait's
// bob (2.5 cm at twice the 0.95 Hz stride), roll and yaw sway (1.5 and 2.5 degrees at the stride)
// and hand jitter, seeded.
PathMotionOptions PedestrianPathOptions(std::vector<Eigen::Vector2d> route, uint64_t seed);

// A camera moving along a route (PathMotionOptions).
class PathMotion : public CameraMotion {
 public:
  // Throws InvalidArgumentError when the options fail Check() or the route is shorter than the
  // distance the duration needs.
  explicit PathMotion(PathMotionOptions options);
  Rigid3d WorldFromCam(int64_t t_ns) const override;
  int64_t duration_ns() const override { return duration_ns_; }
  // The route point at arc length `s` metres (clamped to the route).
  Eigen::Vector2d PointAt(double s) const;
  // The route's length, metres.
  double length_m() const { return cumulative_.back(); }

 private:
  PathMotionOptions options_;
  std::vector<double> cumulative_;
  int64_t duration_ns_ = 0;
};

// Measured peak speeds of a motion, by finite differences at `step_ns`.
PeakSpeeds MeasurePeakSpeeds(const CameraMotion& motion, int64_t step_ns = 1'000'000);

// Samples the motion at `rate_hz` from 0 to its end (the end included), for ground truth files.
Trajectory SampleMotion(const CameraMotion& motion, double rate_hz);

}  // namespace evloc::sim
