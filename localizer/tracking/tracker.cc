#include "localizer/tracking/tracker.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <string>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "localizer/tracking/point_selection.h"
#include "localizer/tracking/pose_time.h"

namespace evloc::tracking {
namespace {

using Clock = std::chrono::steady_clock;

double MillisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

constexpr double kRadiansPerDegree = std::numbers::pi / 180.0;

}  // namespace

Tracker::Tracker(const MapSource& source, const Camera& camera, const TrackerOptions& options)
    : Tracker(nullptr, &source, camera, options) {}

Tracker::Tracker(const Map& map, const VisibilityIndex* visibility, const Camera& camera,
                 const TrackerOptions& options)
    : Tracker(std::make_unique<const StaticMapSource>(map, visibility), nullptr, camera, options) {}

Tracker::Tracker(std::unique_ptr<const MapSource> owned, const MapSource* borrowed,
                 const Camera& camera, const TrackerOptions& options)
    : owned_source_(std::move(owned)),
      source_(borrowed != nullptr ? borrowed : owned_source_.get()),
      options_((options.Check(), options)),
      sensor_camera_(camera),
      binning_(ResolveBinning(options, camera.width, camera.height)),
      ideal_camera_(UndistortionTable::BinnedIdealCamera(camera, binning_)),
      intrinsics_(PinholeIntrinsics::FromCamera(ideal_camera_)),
      decay_{options.decay_time_s * 1e9, options.empty_threshold},
      polarity_options_{options.polarity_neutral_band_deg, options.gradient_probe_depth_fraction,
                        options.min_flow_px},
      surface_(camera, binning_),
      filter_(SensorSize{camera.width, camera.height}, options.event_filter),
      motion_(std::llround(options.velocity_window_s * 1e9),
              std::llround(options.stamp_velocity_window_s * 1e9),
              std::llround(options.velocity_decay_time_s * 1e9)) {
  if (ideal_camera_.width < 8 || ideal_camera_.height < 8) {
    throw InvalidArgumentError("Tracker: the camera image must be at least 8x8 pixels.");
  }
  for (int channel = 0; channel < 3; ++channel) {
    lazy_fields_[channel] = std::make_unique<TimeSurfaceField>(
        surface_, static_cast<SurfaceChannel>(channel), decay_, options_.smooth_field);
  }
  ReadSourcePoints();
  period_ns_ = std::max<int64_t>(1, std::llround(1e9 / options_.step_rate_hz));
}

void Tracker::ReadSourcePoints() {
  const MapPoints points = source_->points();
  if (points.positions.size() != points.gradients.size()) {
    throw InvalidArgumentError("Tracker: the map source has not one gradient per point.");
  }
  points_ = points;
  source_generation_ = source_->generation();
}

void Tracker::Reset(const Rigid3d& world_from_cam, int64_t t_ns) {
  if (!world_from_cam.IsFinite()) {
    throw InvalidArgumentError("Tracker::Reset: the pose is not finite.");
  }
  motion_.Reset(world_from_cam, t_ns);
  StartTrackingAt(world_from_cam, t_ns);
}

void Tracker::Reset(const Rigid3d& world_from_cam, int64_t t_ns, const Vector6d& velocity) {
  if (!world_from_cam.IsFinite()) {
    throw InvalidArgumentError("Tracker::Reset: the pose is not finite.");
  }
  motion_.Reset(world_from_cam, t_ns, velocity);
  StartTrackingAt(world_from_cam, t_ns);
}

void Tracker::StartTrackingAt(const Rigid3d& world_from_cam, int64_t t_ns) {
  last_good_world_from_cam_ = world_from_cam;
  last_good_reported_world_from_cam_ = world_from_cam;
  status_ = TrackingStatus::kTracking;
  started_ = true;
  has_pose_ = true;
  last_pose_given_ = true;
  lost_steps_ = 0;
  next_step_t_ns_ = t_ns + period_ns_;
  last_step_t_ns_ = t_ns;
  events_since_step_ = 0;
  has_selection_ = false;
}

std::vector<PoseEstimate> Tracker::AddEvents(const EventBuffer& events) {
  if (options_.input != TrackerInput::kEvents) {
    throw InvalidArgumentError("Tracker::AddEvents: this tracker takes frames (Canny-VT).");
  }
  if (!events.IsConsistent()) {
    throw InvalidArgumentError("Tracker::AddEvents: the event arrays differ in length.");
  }
  const size_t count = events.size();
  const int64_t* t_ns = events.t_ns.data();
  // Reject the whole packet before storing anything when it goes back in time.
  if (count > 0) {
    bool ordered = (!last_event_t_ns_ || t_ns[0] >= *last_event_t_ns_) &&
                   (!complete_until_t_ns_ || t_ns[0] > *complete_until_t_ns_);
    for (size_t i = 1; i < count; ++i) ordered &= t_ns[i] >= t_ns[i - 1];
    if (!ordered) {
      throw InvalidArgumentError("Tracker::AddEvents: event time stamps must not decrease.");
    }
  }
  if (count > 0 && !first_event_t_ns_) first_event_t_ns_ = t_ns[0];
  if (count > 0) {
    const int64_t silence_ns = SilenceNs();
    if (!last_event_t_ns_ || t_ns[0] - *last_event_t_ns_ > silence_ns) events_since_t_ns_ = t_ns[0];
    for (size_t i = 1; i < count; ++i) {
      if (t_ns[i] - t_ns[i - 1] > silence_ns) events_since_t_ns_ = t_ns[i];
    }
  }
  // The noise filters (event_filter.h) choose the events that reach the surfaces.
  std::vector<PoseEstimate> estimates = Ingest(filter_.Process(events));
  if (count > 0) last_event_t_ns_ = t_ns[count - 1];
  return estimates;
}

std::vector<PoseEstimate> Tracker::Ingest(const EventBuffer& events) {
  const size_t count = events.size();
  const int64_t* t_ns = events.t_ns.data();
  std::vector<PoseEstimate> estimates;
  size_t begin = 0;
  while (begin < count) {
    if (!initialized()) {
      InsertEvents(events, begin, count);
      begin = count;
    } else if (options_.events_per_step) {
      const size_t take =
          std::min<size_t>(count - begin, *options_.events_per_step - events_since_step_);
      InsertEvents(events, begin, begin + take);
      begin += take;
      events_since_step_ += static_cast<int64_t>(take);
      if (events_since_step_ == *options_.events_per_step) {
        events_since_step_ = 0;
        const int64_t step_t_ns = t_ns[begin - 1];
        // Several steps at one time stamp would add nothing: the step waits for a later event.
        if (step_t_ns > last_step_t_ns_) estimates.push_back(Step(step_t_ns));
      }
    } else {
      // Events up to and including the next step time belong to that step.
      const size_t end =
          static_cast<size_t>(std::upper_bound(t_ns + begin, t_ns + count, next_step_t_ns_) - t_ns);
      InsertEvents(events, begin, end);
      begin = end;
      if (end < count) {
        // An event after the step time proves that every event of the step has arrived.
        estimates.push_back(Step(next_step_t_ns_));
        next_step_t_ns_ += period_ns_;
      }
    }
  }
  return estimates;
}

void Tracker::InsertEvents(const EventBuffer& events, size_t begin, size_t end) {
  surface_.Insert(events, begin, end);
  if (end > begin) last_inserted_t_ns_ = events.t_ns[end - 1];
  if (event_image_ && searching()) {
    event_image_->Insert(events, begin, end);
  }
}

std::vector<PoseEstimate> Tracker::AdvanceTo(int64_t t_ns) {
  if (last_event_t_ns_ && t_ns < *last_event_t_ns_) {
    throw InvalidArgumentError("Tracker::AdvanceTo: the time " + std::to_string(t_ns) +
                               " ns is before the last event (" +
                               std::to_string(*last_event_t_ns_) + " ns).");
  }
  if (!complete_until_t_ns_ || t_ns > *complete_until_t_ns_) complete_until_t_ns_ = t_ns;
  std::vector<PoseEstimate> estimates;
  if (options_.input == TrackerInput::kEvents) estimates = Ingest(filter_.AdvanceTo(t_ns));
  if (options_.input != TrackerInput::kEvents || options_.events_per_step || !initialized() ||
      filter_.holding()) {
    return estimates;
  }
  while (next_step_t_ns_ <= t_ns) {
    estimates.push_back(Step(next_step_t_ns_));
    next_step_t_ns_ += period_ns_;
  }
  return estimates;
}

std::optional<PoseEstimate> Tracker::AddFrame(int64_t t_ns, const cv::Mat& gray) {
  if (options_.input != TrackerInput::kFrames) {
    throw InvalidArgumentError("Tracker::AddFrame: this tracker takes events (Canny-EVT).");
  }
  if (gray.type() != CV_8UC1 || gray.cols != sensor_camera_.width ||
      gray.rows != sensor_camera_.height) {
    throw InvalidArgumentError("Tracker::AddFrame: the frame must be CV_8UC1 of " +
                               std::to_string(sensor_camera_.width) + "x" +
                               std::to_string(sensor_camera_.height) + " pixels.");
  }
  if (!initialized()) return std::nullopt;
  if (t_ns <= last_step_t_ns_) {
    throw InvalidArgumentError("Tracker::AddFrame: frames must come after the last step.");
  }
  // Canny on the sensor image, then each edge pixel moved to its ideal pixel (no remapping).
  cv::Mat sensor_edges;
  cv::Canny(gray, sensor_edges, options_.canny_low_threshold, options_.canny_high_threshold);
  cv::Mat ideal_edges = cv::Mat::zeros(surface_.height(), surface_.width(), CV_8UC1);
  uint8_t* ideal = ideal_edges.ptr<uint8_t>(0);
  for (int y = 0; y < sensor_edges.rows; ++y) {
    const uint8_t* row = sensor_edges.ptr<uint8_t>(y);
    for (int x = 0; x < sensor_edges.cols; ++x) {
      if (row[x] == 0) continue;
      surface_.ForEachIdealPixel(x, y, [ideal](int32_t index) { ideal[index] = 255; });
    }
  }
  const cv::Mat distance_field =
      TruncatedDistanceField(ideal_edges, options_.distance_truncation_px, false);
  frame_distance_px_ = distance_field * options_.distance_truncation_px;
  frame_field_ = DenseField(options_.smooth_field ? SmoothField(distance_field) : distance_field);
  edges_.Build(ideal_edges);
  return Step(t_ns);
}

double Tracker::StepDecayTimeNs() const {
  const double longest_ns = options_.decay_time_s * 1e9;
  if (search_decay_ns_ > 0 && searching()) {
    return search_decay_ns_;
  }
  if (options_.decay_trail_px <= 0 || status_ != TrackingStatus::kTracking || !has_selection_ ||
      motion_.velocity_span_ns() == 0) {
    return longest_ns;
  }
  // The decay_speed_quantile image speed (the median by default) of (up to 256 of) the selected
  // points at the last pose, from the displacement over 1 ms of the constant-velocity motion.
  constexpr double kProbeS = 1e-3;
  const Rigid3d cam_from_world = motion_.last_world_from_cam().Inverse();
  const Rigid3d moved_cam_from_world =
      (motion_.last_world_from_cam() * ExpSE3(motion_.velocity() * kProbeS)).Inverse();
  const size_t stride = std::max<size_t>(1, selected_.size() / 256);
  std::vector<double> speeds;
  speeds.reserve(selected_.size() / stride + 1);
  for (size_t i = 0; i < selected_.size(); i += stride) {
    const Eigen::Vector3d world = points_.positions[selected_[i]].cast<double>();
    Eigen::Vector2d before;
    Eigen::Vector2d after;
    if (!intrinsics_.Project(cam_from_world * world, &before) ||
        !intrinsics_.Project(moved_cam_from_world * world, &after)) {
      continue;
    }
    speeds.push_back((after - before).norm() / kProbeS);
  }
  if (speeds.empty()) return longest_ns;
  const size_t rank =
      options_.decay_speed_quantile == 0.5
          ? speeds.size() / 2
          : std::min(speeds.size() - 1, static_cast<size_t>(std::floor(
                                            options_.decay_speed_quantile * (speeds.size() - 1))));
  std::nth_element(speeds.begin(), speeds.begin() + rank, speeds.end());
  const double speed_px_s = speeds[rank];
  if (speed_px_s <= 0) return longest_ns;
  return std::clamp(options_.decay_trail_px / speed_px_s * 1e9, options_.min_decay_time_s * 1e9,
                    longest_ns);
}

void Tracker::UpdateSurfaces(int64_t t_ns) {
  if (options_.input == TrackerInput::kFrames) return;  // Built by AddFrame.
  decay_.decay_time_ns = StepDecayTimeNs();
  const int num_channels = options_.use_polarity ? 3 : 1;
  for (int channel = 0; channel < num_channels; ++channel) {
    lazy_fields_[channel]->SetDecay(decay_);
    lazy_fields_[channel]->SetTime(t_ns);
    if (options_.field_evaluation == FieldEvaluation::kDense) {
      dense_fields_[channel] = DenseField(lazy_fields_[channel]->RenderDense());
    }
  }
  // O(1): the edge search reads the surface in a window around each query.
  edges_.Build(surface_, SurfaceChannel::kAll, t_ns, decay_);
  if (options_.use_polarity) {
    polarity_edges_[0].Build(surface_, SurfaceChannel::kOn, t_ns, decay_);
    polarity_edges_[1].Build(surface_, SurfaceChannel::kOff, t_ns, decay_);
  }
}

PotentialField* Tracker::Field(SurfaceChannel channel) {
  if (options_.input == TrackerInput::kFrames) return &frame_field_;
  const int index = static_cast<int>(channel);
  if (options_.field_evaluation == FieldEvaluation::kDense) return &dense_fields_[index];
  return lazy_fields_[index].get();
}

void Tracker::SelectPoints(const Rigid3d& predicted_world_from_cam) {
  const Camera& ideal = ideal_camera_;
  PointSelectionOptions selection;
  selection.max_points = options_.max_points;
  selection.bucket_size_px = options_.bucket_size_px;
  selection.min_depth_m = options_.min_depth_m;
  selection.max_depth_m = options_.max_depth_m;
  selection.image_margin_px = options_.registration.image_margin_px;
  const Rigid3d cam_from_world = predicted_world_from_cam.Inverse();
  VisibilityQueryOptions query;
  query.min_depth_m = options_.min_depth_m;
  query.max_depth_m = options_.max_depth_m;
  query.image_margin_px = options_.registration.image_margin_px;
  source_->VisibleCandidates(ideal, predicted_world_from_cam, query, &candidates_);
  selected_ = SelectEvenly(points_.positions, candidates_, intrinsics_, ideal.width, ideal.height,
                           cam_from_world, selection);
  if (options_.informative_points > 0 && options_.input == TrackerInput::kEvents) {
    InformativeSelectionOptions informative;
    informative.count = options_.informative_points;
    informative.seed_fraction = options_.informative_seed_fraction;
    informative.gradient_probe_depth_fraction = options_.gradient_probe_depth_fraction;
    selected_ = SelectInformative(points_.positions, points_.gradients, selected_, intrinsics_,
                                  cam_from_world, informative);
  }
  selection_world_from_cam_ = predicted_world_from_cam;
  steps_since_selection_ = 0;
  has_selection_ = true;
}

bool Tracker::InsideImage(const Eigen::Vector2d& pixel) const {
  return pixel.x() >= 0 && pixel.y() >= 0 && pixel.x() <= surface_.width() - 1 &&
         pixel.y() <= surface_.height() - 1;
}

bool Tracker::NearEdge(const Eigen::Vector2d& pixel) const {
  int x;
  int y;
  // Rounds as std::lround, without its library call (two calls per point in Assess).
  if (!NearestEdgeField::RoundToPixel(pixel, &x, &y)) return false;
  if (x < 0 || y < 0 || x >= surface_.width() || y >= surface_.height()) return false;
  const double radius = options_.on_edge_radius_px;
  if (options_.input == TrackerInput::kFrames) {
    return frame_distance_px_.ptr<float>(y)[x] <= radius;
  }
  int edge_pixel;
  float distance;
  return edges_.Nearest(x, y, radius, &edge_pixel, &distance);
}

bool Tracker::IsGood(const TrackingQuality& quality) const {
  return quality.points_used >= options_.min_points &&
         quality.on_edge_fraction >= options_.min_on_edge_fraction &&
         quality.alignment >= options_.min_alignment &&
         quality.mean_residual <= options_.max_mean_residual;
}

std::optional<PosePrior> Tracker::MotionPrior(int64_t t_ns) const {
  const double sigma_v = options_.motion_prior_velocity_sigma_mps;
  const double sigma_w = options_.motion_prior_angular_velocity_sigma_dps * kRadiansPerDegree;
  const double dt_s = static_cast<double>(t_ns - motion_.last_t_ns()) * 1e-9;
  if ((sigma_v <= 0 && sigma_w <= 0) || !(dt_s > 0)) return std::nullopt;
  // As for stamping: right after a Reset the velocity is the difference of a few poses.
  if (motion_.smooth_velocity_span_ns() <= 0 ||
      motion_.smooth_velocity_span_ns() < motion_.smooth_window_ns()) {
    return std::nullopt;
  }
  const double residual_variance =
      last_residual_variance_ > 0
          ? last_residual_variance_
          : options_.registration.robust_scale * options_.registration.robust_scale;
  PosePrior prior;
  // Centred on the last pose moved on by the smooth velocity (the stamping window, 0.1 s): the
  // short window's velocity follows the estimates' own step-to-step noise, and a prior that
  // holds each pose to it feeds that noise back (measured: 2.5 m excursions at 10 m/s).
  prior.cam_from_world = motion_.PredictSmooth(t_ns).Inverse();
  // The prediction's error after dt at a velocity known to sigma: sigma * dt per axis.
  const double translation_information =
      sigma_v > 0 ? residual_variance / ((sigma_v * dt_s) * (sigma_v * dt_s)) : 0.0;
  const double rotation_information =
      sigma_w > 0 ? residual_variance / ((sigma_w * dt_s) * (sigma_w * dt_s)) : 0.0;
  prior.information.diagonal() << Eigen::Vector3d::Constant(translation_information),
      Eigen::Vector3d::Constant(rotation_information);
  return prior;
}

Tracker::Attempt Tracker::Solve(const Rigid3d& start_world_from_cam,
                                const Rigid3d* previous_world_from_cam, bool assess,
                                const PosePrior* prior) {
  const Rigid3d start_cam_from_world = start_world_from_cam.Inverse();
  const bool predict_polarity = options_.use_polarity && previous_world_from_cam != nullptr &&
                                options_.input == TrackerInput::kEvents;
  const Rigid3d previous_cam_from_world =
      previous_world_from_cam ? previous_world_from_cam->Inverse() : Rigid3d();
  const size_t num_selected = selected_.size();
  scratch_pixels_.resize(num_selected);
  scratch_depths_.resize(num_selected);
  scratch_fields_.resize(num_selected);
  const Eigen::Matrix3d start_rotation = start_cam_from_world.RotationMatrix();
  const PolarityPredictor predictor(intrinsics_, start_cam_from_world, previous_cam_from_world,
                                    polarity_options_);
  for (size_t i = 0; i < num_selected; ++i) {
    const uint32_t index = selected_[i];
    const Eigen::Vector3d position = points_.positions[index].cast<double>();
    const Eigen::Vector3d point_in_cam =
        start_rotation * position + start_cam_from_world.translation;
    scratch_depths_[i] = point_in_cam.z();
    if (!intrinsics_.Project(point_in_cam, &scratch_pixels_[i])) {
      scratch_pixels_[i].setConstant(-1e9);
    }
    SurfaceChannel channel = SurfaceChannel::kAll;
    if (predict_polarity) {
      const PredictedPolarity polarity =
          predictor.Predict(position, points_.gradients[index].cast<double>());
      if (polarity == PredictedPolarity::kOn) channel = SurfaceChannel::kOn;
      if (polarity == PredictedPolarity::kOff) channel = SurfaceChannel::kOff;
    }
    scratch_fields_[i] = Field(channel);
  }
  if (options_.use_occlusion_culling && predict_polarity && options_.polarity_aware_culling) {
    // Each point claims the nearest edge pixel of its own surface: ON points compete for pixels
    // that fired ON, OFF points for OFF pixels, unsigned points for any active pixel.
    scratch_keep_.assign(num_selected, 0);
    for (int channel = 0; channel < 3; ++channel) {
      const PotentialField* field = Field(static_cast<SurfaceChannel>(channel));
      scratch_group_.clear();
      scratch_group_pixels_.clear();
      scratch_group_depths_.clear();
      for (size_t i = 0; i < num_selected; ++i) {
        if (scratch_fields_[i] != field) continue;
        scratch_group_.push_back(i);
        scratch_group_pixels_.push_back(scratch_pixels_[i]);
        scratch_group_depths_.push_back(scratch_depths_[i]);
      }
      if (scratch_group_.empty()) continue;
      const NearestEdgeField& edges = channel == 0 ? edges_ : polarity_edges_[channel - 1];
      zbuffer_.Cull(scratch_group_pixels_, scratch_group_depths_, edges, options_.annf_radius_px,
                    &scratch_group_keep_);
      for (size_t k = 0; k < scratch_group_.size(); ++k) {
        scratch_keep_[scratch_group_[k]] = scratch_group_keep_[k];
      }
    }
  } else if (options_.use_occlusion_culling) {
    zbuffer_.Cull(scratch_pixels_, scratch_depths_, edges_, options_.annf_radius_px,
                  &scratch_keep_);
  } else {
    scratch_keep_.assign(num_selected, 1);
  }
  std::vector<RegistrationPoint>& points = scratch_points_;
  points.clear();
  for (size_t i = 0; i < num_selected; ++i) {
    if (scratch_keep_[i]) {
      points.push_back({points_.positions[selected_[i]].cast<double>(), scratch_fields_[i]});
    }
  }
  Attempt attempt;
  attempt.registration =
      RegisterPoints(points, intrinsics_, start_cam_from_world, options_.registration, prior);
  attempt.quality.mean_residual = attempt.registration.mean_residual;
  attempt.quality.points_used = attempt.registration.points_used;
  attempt.quality.points_selected = static_cast<int>(num_selected);
  attempt.quality.iterations = attempt.registration.iterations;
  if (assess) Assess(predict_polarity, &attempt);
  return attempt;
}

void Tracker::Assess(bool predicted_polarity, Attempt* attempt) {
  const size_t num_selected = selected_.size();
  const Eigen::Matrix3d estimate_rotation = attempt->registration.cam_from_world.RotationMatrix();
  const Eigen::Vector3d& estimate_translation = attempt->registration.cam_from_world.translation;
  // On-edge fraction over every selected point, culled or not: culling keeps only points near
  // edges, so counting the survivors alone would flatter a wrong pose.
  // The chance level: each point displaced by one of four 4-pixel offsets (not along the image
  // axes, so that axis-aligned structure does not line up with its own copy).
  static const Eigen::Vector2d kChanceOffsets[4] = {
      {4.0, 1.0}, {-1.0, 4.0}, {-4.0, -1.0}, {1.0, -4.0}};
  int in_image = 0;
  int on_edge = 0;
  int chance_trials = 0;
  int chance_on_edge = 0;
  for (const uint32_t index : selected_) {
    Eigen::Vector2d pixel;
    const Eigen::Vector3d point_in_cam =
        estimate_rotation * points_.positions[index].cast<double>() + estimate_translation;
    if (!intrinsics_.Project(point_in_cam, &pixel) || !InsideImage(pixel)) continue;
    const Eigen::Vector2d displaced = pixel + kChanceOffsets[in_image % 4];
    ++in_image;
    on_edge += NearEdge(pixel) ? 1 : 0;
    if (InsideImage(displaced)) {
      ++chance_trials;
      chance_on_edge += NearEdge(displaced) ? 1 : 0;
    }
  }
  // Check the confident polarity predictions against the events the point fired in this step:
  // when the pixel it projects to at the estimate has an event since the previous step, its last
  // event must have the predicted polarity (ON for ON, OFF for OFF).
  if (predicted_polarity) {
    for (size_t i = 0; i < num_selected; ++i) {
      const PotentialField* field = scratch_fields_[i];
      const bool on = field == Field(SurfaceChannel::kOn);
      if (!on && field != Field(SurfaceChannel::kOff)) continue;
      Eigen::Vector2d pixel;
      const Eigen::Vector3d point_in_cam =
          estimate_rotation * points_.positions[selected_[i]].cast<double>() + estimate_translation;
      int x;
      int y;
      if (!intrinsics_.Project(point_in_cam, &pixel) || !InsideImage(pixel) ||
          !NearestEdgeField::RoundToPixel(pixel, &x, &y)) {
        continue;
      }
      const int64_t t_on = surface_.LastTimestamp(SurfaceChannel::kOn, x, y);
      const int64_t t_off = surface_.LastTimestamp(SurfaceChannel::kOff, x, y);
      if (std::max(t_on, t_off) <= last_step_t_ns_) continue;
      ++attempt->quality.polarity_predictions;
      attempt->quality.polarity_matches += (t_on >= t_off) == on ? 1 : 0;
    }
  }
  attempt->quality.on_edge_fraction = in_image > 0 ? static_cast<double>(on_edge) / in_image : 0;
  attempt->quality.chance_on_edge_fraction =
      chance_trials > 0 ? static_cast<double>(chance_on_edge) / chance_trials : 0;
  attempt->quality.alignment =
      attempt->quality.chance_on_edge_fraction < 1
          ? (attempt->quality.on_edge_fraction - attempt->quality.chance_on_edge_fraction) /
                (1 - attempt->quality.chance_on_edge_fraction)
          : 0;
  attempt->good = IsGood(attempt->quality);
}

PoseEstimate Tracker::Step(int64_t t_ns) {
  const Clock::time_point step_start = Clock::now();
  PoseEstimate estimate;
  estimate.t_ns = t_ns;
  step_t_ns_ = t_ns;
  bool new_point_set = false;
  if (source_->generation() != source_generation_) {
    // A new point set: the selected indices (which the adaptive decay reads too) are stale, and
    // so are the search's.
    ReadSourcePoints();
    has_selection_ = false;
    new_point_set = true;
    if (searching()) RestartSearchRound();
  }

  // The adaptive decay time comes from the selected points' image speeds. Right after a Reset
  // with a velocity, or a new point set while tracking (select_first_on_new_points), the tracker
  // has a velocity but no selection: it selects first, so that the step's surfaces are built
  // with the decay time of that velocity instead of the longest.
  if ((last_pose_given_ || (new_point_set && options_.select_first_on_new_points)) &&
      !has_selection_ && !searching() && status_ == TrackingStatus::kTracking &&
      motion_.velocity_span_ns() > 0) {
    const Clock::time_point selection_start = Clock::now();
    SelectPoints(motion_.Predict(t_ns));
    estimate.timings.selection_ms = MillisecondsSince(selection_start);
  }
  const Clock::time_point surface_start = Clock::now();
  UpdateSurfaces(t_ns);
  estimate.timings.surface_ms = MillisecondsSince(surface_start);
  estimate.search.episode = search_progress_.episode;

  if (searching()) {
    const Clock::time_point search_start = Clock::now();
    SearchStep(t_ns, &estimate);
    estimate.timings.solve_ms = MillisecondsSince(search_start);
    last_step_t_ns_ = t_ns;
    estimate.timings.total_ms = MillisecondsSince(step_start);
    return estimate;
  }

  const Clock::time_point selection_start = Clock::now();
  const bool was_tracking = status_ == TrackingStatus::kTracking;
  const Rigid3d predicted = was_tracking ? motion_.Predict(t_ns) : last_good_world_from_cam_;
  ++steps_since_selection_;
  const bool moved =
      has_selection_ && ((predicted.translation - selection_world_from_cam_.translation).norm() >
                             options_.reselect_translation_m ||
                         AngleBetween(predicted.rotation, selection_world_from_cam_.rotation) >
                             options_.reselect_rotation_deg * kRadiansPerDegree);
  if (!has_selection_ || moved || steps_since_selection_ >= options_.reselect_every_steps) {
    SelectPoints(predicted);
    estimate.timings.selection_ms += MillisecondsSince(selection_start);
  }

  const Clock::time_point solve_start = Clock::now();
  const Rigid3d previous = motion_.last_world_from_cam();
  // Polarity needs the direction of the image motion: only once the velocity spans half its
  // window (right after a Reset it is zero, then the noisy difference of two close poses).
  const bool velocity_settled =
      2 * motion_.velocity_span_ns() >= std::llround(options_.velocity_window_s * 1e9) &&
      motion_.velocity_span_ns() > 0;
  const bool predict_polarity = was_tracking && velocity_settled && options_.use_polarity;
  // The smooth constant-velocity prediction as a prior, once there is a velocity to trust.
  const std::optional<PosePrior> motion_prior = was_tracking ? MotionPrior(t_ns) : std::nullopt;
  const PosePrior* prior = motion_prior ? &*motion_prior : nullptr;
  Attempt best;
  bool solved_unsigned_from_prediction = false;
  if (predict_polarity && options_.polarity_after_unsigned_solve) {
    // Unsigned first, then signed from there: the signed surfaces split the edges of thin lines
    // apart, but a polarity predicted from a wrong flow (the motion turned within the step)
    // attracts points to the wrong edges; starting the signed solve from the unsigned optimum
    // predicts the polarities from a flow measured up to it.
    // The unsigned result's quality only matters when the signed one is bad: assessed then.
    Attempt coarse = Solve(predicted, nullptr, /*assess=*/false, prior);
    solved_unsigned_from_prediction = true;
    const Rigid3d coarse_world_from_cam = coarse.registration.cam_from_world.Inverse();
    // Right after a Reset with a velocity the last pose is the given one, at its own time, while
    // the unsigned optimum lags the step by the events' age (milliseconds): it can lie behind the
    // given pose, and the polarities predicted from that backward motion would all be wrong
    // (measured on the test scene: 3 of 469 right, a first pose 30 mm off). The motion over
    // the step comes from the velocity then.
    const Rigid3d polarity_previous =
        last_pose_given_ ? coarse_world_from_cam *
                               ExpSE3(-motion_.velocity() *
                                      (static_cast<double>(t_ns - motion_.last_t_ns()) * 1e-9))
                         : previous;
    best = Solve(coarse_world_from_cam, &polarity_previous, /*assess=*/true, prior);
    best.quality.iterations += coarse.quality.iterations;
    if (!best.good) {
      Assess(/*predicted_polarity=*/false, &coarse);
      if (coarse.good) best = std::move(coarse);
    }
  } else {
    best = Solve(predicted, predict_polarity ? &previous : nullptr, /*assess=*/true, prior);
  }
  int recovery_attempts = 0;
  // While the surfaces hold less than one decay time of events (the start of a stream), a bad
  // fit means too few events, not a wrong pose: hold the pose instead of declaring LOST. Frames
  // are whole at once: no warm-up.
  const bool warming_up =
      was_tracking && options_.input == TrackerInput::kEvents &&
      (!first_event_t_ns_ || t_ns - *first_event_t_ns_ < options_.decay_time_s * 1e9);
  const bool hold_prediction = !best.good && warming_up;
  if (!best.good && !hold_prediction && options_.enable_recovery) {
    // Retry with the unsigned surface (the motion, hence the polarity prediction, is what
    // failed): from the prediction itself unless that was done (a motion that turns within a
    // step makes the constant-velocity flow, and every polarity, point the wrong way), then from
    // the last good pose and from perturbations around it.
    std::vector<Rigid3d> starts;
    if (predict_polarity && !solved_unsigned_from_prediction) starts.push_back(predicted);
    starts.push_back(last_good_world_from_cam_);
    const double t = options_.recovery_translation_m;
    const double r = options_.recovery_rotation_deg * kRadiansPerDegree;
    for (int axis = 0; axis < 6; ++axis) {
      for (const double sign : {1.0, -1.0}) {
        Vector6d perturbation = Vector6d::Zero();
        perturbation(axis) = sign * (axis < 3 ? t : r);
        if (perturbation.isZero()) continue;
        starts.push_back(last_good_world_from_cam_ * ExpSE3(perturbation));
      }
    }
    for (const Rigid3d& start : starts) {
      Attempt attempt = Solve(start, nullptr);
      ++recovery_attempts;
      const bool better =
          (attempt.good && !best.good) ||
          (attempt.good == best.good && attempt.quality.alignment > best.quality.alignment);
      if (better) best = std::move(attempt);
      if (best.good) break;
    }
  }
  estimate.timings.solve_ms = MillisecondsSince(solve_start);

  estimate.world_from_cam = best.registration.cam_from_world.Inverse();
  estimate.covariance = best.registration.covariance;
  estimate.quality = best.quality;
  estimate.quality.decay_time_ms = decay_.decay_time_ns * 1e-6;
  estimate.quality.recovery_attempts = recovery_attempts;
  if (hold_prediction) {
    // Still TRACKING; the motion model keeps its state.
    estimate.world_from_cam = predicted;
    estimate.covariance = Matrix6d::Identity() * kUnconstrainedVariance;
  } else if (best.good) {
    if (was_tracking) {
      motion_.Update(estimate.world_from_cam, t_ns);
    } else {
      motion_.Reset(estimate.world_from_cam, t_ns);
    }
    last_pose_given_ = false;
    last_good_world_from_cam_ = estimate.world_from_cam;
    last_residual_variance_ = best.registration.residual_variance;
    status_ = TrackingStatus::kTracking;
    lost_steps_ = 0;
    // The registered pose shows the camera when the events under its points fired: move it
    // forward by their age to the step time (the motion model keeps the registered poses, which
    // the surfaces of the next step will match again).
    // Only once the smooth velocity spans its whole window since the last Reset: right after a
    // Reset (a pose hint, a return from LOST) it is the difference of a few poses, one of them
    // possibly centimetres off, and moving a pose forward by it would add that error.
    if ((options_.stamp_at_step_time || options_.measure_surface_age) &&
        options_.input == TrackerInput::kEvents && motion_.smooth_velocity_span_ns() > 0 &&
        motion_.smooth_velocity_span_ns() >= motion_.smooth_window_ns()) {
      const SurfaceAge age =
          MeasureSurfaceAge(surface_, SurfaceChannel::kAll, decay_, t_ns, intrinsics_,
                            best.registration.cam_from_world, motion_.smooth_velocity(),
                            points_.positions, selected_, &scratch_age_samples_);
      estimate.quality.surface_age_ms = static_cast<double>(age.age_ns) * 1e-6;
      if (options_.stamp_at_step_time) {
        estimate.world_from_cam =
            estimate.world_from_cam * ExpSE3(motion_.smooth_velocity() * (age.age_ns * 1e-9));
        // A unit quaternion, as every reader of a pose normalises it (bit-identical poses
        // through the service).
        estimate.world_from_cam.rotation.normalize();
      }
    }
    last_good_reported_world_from_cam_ = estimate.world_from_cam;
  } else {
    // The best failed attempt is no estimate: a LOST step reports the last good pose, with a
    // covariance that says it carries no information.
    status_ = TrackingStatus::kLost;
    motion_.Reset(last_good_world_from_cam_, t_ns);
    last_pose_given_ = false;
    // The pose last reported as good (at its step time when stamped).
    estimate.world_from_cam = last_good_reported_world_from_cam_;
    estimate.covariance = Matrix6d::Identity() * kUnconstrainedVariance;
    // The local recovery gave up for long enough: search the whole map from the next step.
    ++lost_steps_;
    if (options_.lost_steps_before_relocalization > 0 &&
        lost_steps_ >= options_.lost_steps_before_relocalization &&
        options_.input == TrackerInput::kEvents) {
      BeginSearch(TrackingStatus::kRelocalizing, t_ns);
      estimate.search.episode = search_progress_.episode;
    }
  }
  estimate.status = status_;
  last_step_t_ns_ = t_ns;
  estimate.timings.total_ms = MillisecondsSince(step_start);
  return estimate;
}

}  // namespace evloc::tracking
