#include "localizer/odometry/canny_devo.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/thread_cpu_time.h"
#include "localizer/tracking/point_selection.h"
#include "localizer/tracking/registration.h"
#include "maps/edge_lifting.h"

namespace evloc::odometry {
namespace {

// The CPU time of the calling thread, milliseconds.
double ThreadCpuMilliseconds() { return static_cast<double>(ThreadCpuTimeNs()) * 1e-6; }

// Room for `points` more than `vector` holds, its memory touched: filled with zeros (Eigen's
// default constructor writes nothing), then shrunk back; the capacity stays.
void ReserveTouched(size_t points, std::vector<Eigen::Vector3f>* vector) {
  const size_t size = vector->size();
  if (vector->capacity() >= size + points) return;
  vector->resize(size + points, Eigen::Vector3f::Zero());
  vector->resize(size);
}

}  // namespace

tracking::TrackerOptions CannyDevoOptions::DefaultTrackerOptions() {
  tracking::TrackerOptions options;
  options.use_polarity = false;
  options.use_occlusion_culling = false;
  options.decay_time_s = 0.01;
  // A reference map has no viewpoints to search from: a lost step stays LOST (the hand-over
  // restarts DEVO from its last good pose instead, handover.h).
  options.lost_steps_before_relocalization = 0;
  // Poses at their step time and reference frames built at them: better at 640x480 (RPE 1.2 ->
  // 0.94 %), worse at 240x180 (bright 3.3 -> 3.4 %, dark 2.9 -> 4.1 %, hdr 5.3 -> 16.1 %;
  // docs/accuracy.md, "DEVO with poses at their step time"). Off unless asked.
  options.stamp_at_step_time = false;
  // Every reference frame is a new point set; the decay time of its first step stays the longest
  // (TrackerOptions::select_first_on_new_points says what was measured).
  options.select_first_on_new_points = false;
  return options;
}

void CannyDevoOptions::Check() const {
  tracker.Check();
  if (tracker.input != tracking::TrackerInput::kEvents) {
    throw InvalidArgumentError("CannyDevoOptions: the tracker must take events");
  }
  if (tracker.binning != 1) {
    // The reference frames are built on the sensor's pixels from the tracker's surface.
    throw InvalidArgumentError("CannyDevoOptions: the tracker's binning must be 1 (none)");
  }
  reference.Check();
  if (!(mapping_decay_time_s > 0) || !(mapping_empty_threshold > 0) ||
      !(mapping_empty_threshold < 1)) {
    throw InvalidArgumentError(
        "CannyDevoOptions: need mapping_decay_time_s > 0 and 0 < mapping_empty_threshold < 1");
  }
  if (max_reference_points < 10 || min_reference_points < 1 || local_map_frames < 1 ||
      max_kept_frames < local_map_frames) {
    throw InvalidArgumentError(
        "CannyDevoOptions: need max_reference_points >= 10, min_reference_points >= 1, "
        "local_map_frames >= 1 and max_kept_frames >= local_map_frames");
  }
  if (!(reference_max_baseline_fraction > 0) || !(reference_max_rotation_deg > 0)) {
    throw InvalidArgumentError("CannyDevoOptions: reference-frame thresholds must be positive");
  }
}

void ReferenceMapSource::VisibleCandidates(const Camera&, const Rigid3d&,
                                           const VisibilityQueryOptions&,
                                           std::vector<uint32_t>* candidates) const {
  candidates->resize(positions_.size());
  for (size_t i = 0; i < positions_.size(); ++i) (*candidates)[i] = static_cast<uint32_t>(i);
}

void ReferenceMapSource::Replace(std::vector<Eigen::Vector3f>* positions,
                                 std::vector<Eigen::Vector3f>* gradients) {
  if (positions->size() != gradients->size()) {
    throw InvalidArgumentError("ReferenceMapSource: one gradient per position needed");
  }
  positions_.swap(*positions);
  gradients_.swap(*gradients);
  ++generation_;
}

void ReferenceMapSource::Reserve(size_t points) {
  ReserveTouched(points, &positions_);
  ReserveTouched(points, &gradients_);
}

double CannyDevo::Nearness(const KeptFrame& frame, const Rigid3d& world_from_cam) const {
  const Rigid3d frame_from_cam = frame.world_from_cam.Inverse() * world_from_cam;
  const double rotation_deg =
      AngleBetween(frame_from_cam.rotation, Eigen::Quaterniond::Identity()) * 180.0 / M_PI;
  const double baseline_m = options_.reference_max_baseline_fraction * frame.median_depth_m;
  const double translation = baseline_m > 0 ? frame_from_cam.translation.norm() / baseline_m
                                            : std::numeric_limits<double>::infinity();
  return std::max(translation, rotation_deg / options_.reference_max_rotation_deg);
}

void CannyDevo::UpdateLocalMap(const Rigid3d& world_from_cam) {
  std::vector<std::pair<double, size_t>> order;
  order.reserve(kept_frames_.size());
  for (size_t i = 0; i < kept_frames_.size(); ++i) {
    order.emplace_back(Nearness(kept_frames_[i], world_from_cam), i);
  }
  const size_t count = std::min(order.size(), static_cast<size_t>(options_.local_map_frames));
  std::partial_sort(order.begin(), order.begin() + count, order.end());
  order.resize(count);
  std::vector<uint64_t> ids;
  for (const auto& [nearness, index] : order) ids.push_back(kept_frames_[index].id);
  std::sort(ids.begin(), ids.end());
  if (ids == local_map_ids_) return;
  local_map_ids_ = ids;
  size_t total = 0;
  for (const auto& [nearness, index] : order) total += kept_frames_[index].positions.size();
  std::vector<Eigen::Vector3f>& positions = spare_positions_;
  std::vector<Eigen::Vector3f>& gradients = spare_gradients_;
  positions.clear();
  gradients.clear();
  positions.reserve(total);
  gradients.reserve(total);
  for (const auto& [nearness, index] : order) {
    const KeptFrame& frame = kept_frames_[index];
    positions.insert(positions.end(), frame.positions.begin(), frame.positions.end());
    gradients.insert(gradients.end(), frame.gradients.begin(), frame.gradients.end());
  }
  source_.Replace(&positions, &gradients);
}

CannyDevo::CannyDevo(const Camera& event_camera, const Camera& depth_camera,
                     const Rigid3d& event_from_depth, const CannyDevoOptions& options)
    : event_camera_(event_camera),
      depth_camera_(depth_camera),
      event_from_depth_(event_from_depth),
      options_(options),
      table_(event_camera) {
  options_.Check();
  depth_camera_.Check();
  if (!event_from_depth_.IsFinite()) {
    throw InvalidArgumentError("CannyDevo: the depth-to-event extrinsic is not finite");
  }
  tracker_ = std::make_unique<tracking::Tracker>(source_, event_camera_, options_.tracker);
  // The local map's two sets of vectors (the source's and the spare one UpdateLocalMap fills)
  // get their full size now: growing them over the first reference frames cost up to 5 ms of
  // page faults per build at VGA (measured).
  const size_t local_map_points = static_cast<size_t>(options_.local_map_frames) *
                                  static_cast<size_t>(options_.max_reference_points);
  source_.Reserve(local_map_points);
  ReserveTouched(local_map_points, &spare_positions_);
  ReserveTouched(local_map_points, &spare_gradients_);
}

std::vector<tracking::PoseEstimate> CannyDevo::AddEvents(const EventBuffer& events) {
  if (events.empty()) return {};
  std::vector<tracking::PoseEstimate> steps = tracker_->AddEvents(events);
  last_event_t_ns_ = events.t_ns.back();
  if (!steps.empty()) {
    last_step_ = steps.back();
    has_step_ = true;
  }
  return steps;
}

ReferenceFrameInfo CannyDevo::BuildReference(const Rigid3d& world_from_cam, int64_t t_ns,
                                             const cv::Mat& depth_m, double decay_time_s,
                                             const Rigid3d& event_from_depth) {
  const auto start = std::chrono::steady_clock::now();
  const double start_cpu_ms = ThreadCpuMilliseconds();
  const Camera& ideal = table_.ideal_camera();
  tracking::SurfaceDecay decay;
  decay.decay_time_ns = decay_time_s * 1e9;
  decay.empty_threshold = options_.mapping_empty_threshold;
  // The tracker's surface: every event given so far (after the noise filters, when they are on).
  const tracking::TimeSurface& surface = tracker_->time_surface();
  // Its values, and its active pixels (T > delta) as the semi-dense region. (The images are
  // members so that each build reuses their memory.)
  cv::Mat& values = build_.values;
  surface.Values(tracking::SurfaceChannel::kAll, t_ns, decay, &values);
  cv::Mat& semi_dense = build_.semi_dense;
  cv::compare(values, 0.0, semi_dense, cv::CMP_GT);
  cv::Mat& gradient_x = build_.gradient_x;
  cv::Mat& gradient_y = build_.gradient_y;
  cv::Sobel(values, gradient_x, CV_32F, 1, 0, 3);
  cv::Sobel(values, gradient_y, CV_32F, 0, 1, 3);
  if (options_.thin_to_front) {
    // Keep the front of each edge's trail: the active pixels whose surface value is not below
    // either neighbour along the surface's gradient (non-maximum suppression, as Canny's).
    cv::Mat front = cv::Mat::zeros(semi_dense.size(), CV_8UC1);
    for (int y = 1; y + 1 < semi_dense.rows; ++y) {
      for (int x = 1; x + 1 < semi_dense.cols; ++x) {
        if (semi_dense.at<uint8_t>(y, x) == 0) continue;
        const double gx = gradient_x.at<float>(y, x);
        const double gy = gradient_y.at<float>(y, x);
        const double norm = std::hypot(gx, gy);
        int dx = 0;
        int dy = 0;
        if (norm > 1e-9) {
          dx = static_cast<int>(std::lround(gx / norm));
          dy = static_cast<int>(std::lround(gy / norm));
        }
        const float value = values.at<float>(y, x);
        if (value >= values.at<float>(y + dy, x + dx) &&
            value >= values.at<float>(y - dy, x - dx)) {
          front.at<uint8_t>(y, x) = 255;
        }
      }
    }
    semi_dense = front;
  }
  ReferenceFrameInfo info;
  info.t_ns = t_ns;
  info.world_from_cam = world_from_cam;
  info.decay_time_s = decay_time_s;
  std::vector<ReferencePoint>& points = build_.points;
  BuildReferenceMap(ideal, semi_dense, depth_camera_, depth_m, event_from_depth, options_.reference,
                    &points, &info.stats);
  // Even subsampling to the budget.
  std::vector<Eigen::Vector3f>& positions_in_cam = build_.positions_in_cam;
  positions_in_cam.clear();
  for (const ReferencePoint& point : points)
    positions_in_cam.push_back(point.position.cast<float>());
  std::vector<uint32_t>& candidates = build_.candidates;
  candidates.resize(points.size());
  for (size_t i = 0; i < candidates.size(); ++i) candidates[i] = static_cast<uint32_t>(i);
  tracking::PointSelectionOptions selection;
  selection.max_points = options_.max_reference_points;
  selection.min_depth_m = options_.reference.min_depth_m;
  selection.max_depth_m = options_.reference.max_depth_m;
  selection.image_margin_px = 0;
  const std::vector<uint32_t> chosen = tracking::SelectEvenly(
      positions_in_cam, candidates, tracking::PinholeIntrinsics::FromCamera(ideal), ideal.width,
      ideal.height, Rigid3d(), selection);
  // Each point's 3D gradient: the direction in which the time surface rises across the edge
  // (towards where the edge moved), lifted by the ray-plane rule (maps/edge_lifting.h). Its sign
  // comes from the motion, not from the intensity: the polarity prediction cannot use it.
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Vector3f> gradients;
  std::vector<ReferencePoint>& kept = build_.kept;
  std::vector<double>& depths = build_.depths;
  kept.clear();
  depths.clear();
  positions.reserve(chosen.size());
  gradients.reserve(chosen.size());
  const Eigen::Matrix3d rotation = world_from_cam.RotationMatrix();
  const Vector6d& velocity = tracker_->velocity();
  for (const uint32_t index : chosen) {
    ReferencePoint point = points[index];
    const int x = point.pixel.x();
    const int y = point.pixel.y();
    Eigen::Vector2d direction(gradient_x.at<float>(y, x), gradient_y.at<float>(y, x));
    if (!(direction.norm() > 1e-6)) direction = Eigen::Vector2d::UnitX();
    Eigen::Vector3d gradient;
    if (!ComputeGradient3d(ideal, point.pixel.cast<double>(), direction.normalized(),
                           point.position, &gradient)) {
      continue;
    }
    if (options_.edges_at_reference_time) {
      const int64_t last_t_ns = surface.LastTimestamp(tracking::SurfaceChannel::kAll, x, y);
      if (last_t_ns != tracking::kNeverFired && last_t_ns <= t_ns) {
        point.position = EdgeAfter(ideal, point.pixel, point.position, velocity,
                                   static_cast<double>(t_ns - last_t_ns) * 1e-9);
      }
    }
    positions.push_back((world_from_cam * point.position).cast<float>());
    gradients.push_back((rotation * gradient).cast<float>());
    kept.push_back(point);
    depths.push_back(point.position.z());
  }
  info.points = static_cast<int>(kept.size());
  if (!depths.empty()) {
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    info.median_depth_m = depths[depths.size() / 2];
  }
  if (info.points >= options_.min_reference_points) {
    KeptFrame frame;
    frame.id = next_frame_id_++;
    frame.world_from_cam = world_from_cam;
    frame.median_depth_m = info.median_depth_m;
    frame.positions = std::move(positions);
    frame.gradients = std::move(gradients);
    kept_frames_.push_back(std::move(frame));
    if (static_cast<int>(kept_frames_.size()) > options_.max_kept_frames) {
      kept_frames_.erase(kept_frames_.begin());
    }
    UpdateLocalMap(world_from_cam);
    reference_points_.swap(kept);
  }
  info.build_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  info.build_cpu_ms = ThreadCpuMilliseconds() - start_cpu_ms;
  return info;
}

void CannyDevo::Start(const Rigid3d& world_from_cam, int64_t t_ns, const cv::Mat& depth_m) {
  if (started_) throw InvalidArgumentError("CannyDevo::Start: already started");
  if (t_ns < last_event_t_ns_) {
    throw InvalidArgumentError("CannyDevo::Start: events after the start time were given");
  }
  const ReferenceFrameInfo info = BuildReference(world_from_cam, t_ns, depth_m,
                                                 options_.mapping_decay_time_s, event_from_depth_);
  if (info.points < options_.min_reference_points) {
    throw InvalidArgumentError(
        "CannyDevo::Start: the first reference map has " + std::to_string(info.points) +
        " points (at least " + std::to_string(options_.min_reference_points) +
        " needed): too few events before the first depth frame, or no depth on their edges");
  }
  references_.push_back(info);
  tracker_->Reset(world_from_cam, t_ns);
  started_ = true;
}

bool CannyDevo::Restart(const Rigid3d& world_from_cam, int64_t t_ns, const Vector6d& velocity,
                        const cv::Mat& depth_m, const Rigid3d& world_from_cam_at_depth,
                        double decay_time_s) {
  if (!(decay_time_s > 0)) decay_time_s = options_.mapping_decay_time_s;
  // The depth camera at its frame's time, seen from the event camera at t_ns.
  const Rigid3d event_from_depth =
      (world_from_cam.Inverse() * world_from_cam_at_depth) * event_from_depth_;
  // The kept reference frames hold poses of a run that ended or went wrong: none is kept (keeping
  // them when DEVO lost its step was tried in the hand-over: the rendered room's run ended 4.6 m
  // off instead of 0.25 m, docs/accuracy.md "Hand-over").
  kept_frames_.clear();
  const ReferenceFrameInfo info =
      BuildReference(world_from_cam, t_ns, depth_m, decay_time_s, event_from_depth);
  if (info.points < options_.min_reference_points) {
    Stop();
    return false;
  }
  references_.push_back(info);
  tracker_->Reset(world_from_cam, t_ns, velocity);
  has_step_ = false;
  started_ = true;
  return true;
}

void CannyDevo::Stop() {
  // A tracker that was never reset only keeps its surfaces up to date.
  tracker_ = std::make_unique<tracking::Tracker>(source_, event_camera_, options_.tracker);
  kept_frames_.clear();
  started_ = false;
  has_step_ = false;
}

std::vector<tracking::PoseEstimate> CannyDevo::AdvanceTo(int64_t t_ns) {
  std::vector<tracking::PoseEstimate> steps = tracker_->AdvanceTo(t_ns);
  if (!steps.empty()) {
    last_step_ = steps.back();
    has_step_ = true;
  }
  return steps;
}

std::vector<tracking::PoseEstimate> CannyDevo::AddDepthFrame(int64_t t_ns, const cv::Mat& depth_m) {
  if (!started_) throw InvalidArgumentError("CannyDevo::AddDepthFrame: call Start first");
  std::vector<tracking::PoseEstimate> steps = AdvanceTo(t_ns);
  ConsiderDepthFrame(t_ns, depth_m);
  return steps;
}

void CannyDevo::ConsiderDepthFrame(int64_t t_ns, const cv::Mat& depth_m) {
  if (!started_) throw InvalidArgumentError("CannyDevo::ConsiderDepthFrame: call Start first");
  if (!has_step_ || last_step_.status != tracking::TrackingStatus::kTracking) return;
  // The pose at the depth frame: the last step's, moved on by the tracker's velocity.
  const double dt_s = static_cast<double>(t_ns - last_step_.t_ns) * 1e-9;
  const Rigid3d world_from_cam = last_step_.world_from_cam * ExpSE3(tracker_->velocity() * dt_s);
  double nearest = std::numeric_limits<double>::infinity();
  for (const KeptFrame& frame : kept_frames_) {
    nearest = std::min(nearest, Nearness(frame, world_from_cam));
  }
  if (nearest <= 1) {
    UpdateLocalMap(world_from_cam);
    return;
  }
  const ReferenceFrameInfo info = BuildReference(
      world_from_cam, t_ns, depth_m, last_step_.quality.decay_time_ms * 1e-3, event_from_depth_);
  if (info.points >= options_.min_reference_points) references_.push_back(info);
}

}  // namespace evloc::odometry
