// The tracker's global search: the INITIALIZING and RELOCALIZING states (docs/relocalization.md,
// "Events"). Per round: hypotheses from the map source's viewpoints and perturbations around
// them, a chamfer pre-score of each (bounded per step), a coarse-to-fine registration of the best
// few (bounded per step) ending in the tracker's own Solve and Assess, a judgement (good and
// clearly better than the best distinct hypothesis), then a verification window of consecutive
// good steps before TRACKING.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <future>
#include <numbers>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/thread_cpu_time.h"
#include "localizer/tracking/point_selection.h"
#include "localizer/tracking/tracker.h"

namespace evloc::tracking {
namespace {

constexpr double kRadiansPerDegree = std::numbers::pi / 180.0;

}  // namespace

const char* TrackingStatusName(TrackingStatus status) {
  switch (status) {
    case TrackingStatus::kTracking:
      return "TRACKING";
    case TrackingStatus::kLost:
      return "LOST";
    case TrackingStatus::kInitializing:
      return "INITIALIZING";
    case TrackingStatus::kRelocalizing:
      return "RELOCALIZING";
  }
  return "LOST";
}

void Tracker::StartWithoutPose(int64_t t_ns) {
  if (options_.input != TrackerInput::kEvents) {
    throw InvalidArgumentError("Tracker::StartWithoutPose: the search needs events, not frames.");
  }
  started_ = true;
  has_pose_ = false;
  // The search's poses are registered ones (a Reset's given pose before this one is gone).
  last_pose_given_ = false;
  last_good_world_from_cam_ = Rigid3d();
  last_good_reported_world_from_cam_ = Rigid3d();
  motion_.Reset(Rigid3d(), t_ns);
  next_step_t_ns_ = t_ns;
  last_step_t_ns_ = t_ns - 1;
  events_since_step_ = 0;
  has_selection_ = false;
  lost_steps_ = 0;
  BeginSearch(TrackingStatus::kInitializing, t_ns);
}

void Tracker::SetSearchPrior(const Eigen::Vector3d& center, double radius_m) {
  CheckSearchRegion(center, radius_m, "Tracker::SetSearchPrior");
  search_center_ = center;
  search_radius_m_ = radius_m;
  // At the next round: the round in progress keeps the viewpoints its hypotheses index.
  refresh_viewpoints_ = true;
}

void Tracker::SetSearchHint(const Rigid3d& world_from_cam) {
  if (!world_from_cam.translation.allFinite() || !world_from_cam.rotation.coeffs().allFinite()) {
    throw InvalidArgumentError("Tracker::SetSearchHint: the pose is not finite");
  }
  search_hint_ = world_from_cam;
  // At the next round: the hint's orientation makes viewpoints of its own.
  refresh_viewpoints_ = true;
}

void Tracker::ClearSearchPrior() {
  search_center_.reset();
  search_radius_m_ = 0;
  refresh_viewpoints_ = true;
}

void Tracker::SetImageHypothesisSource(const ImageHypothesisSource* source) {
  if (source != nullptr && options_.input != TrackerInput::kEvents) {
    throw InvalidArgumentError(
        "Tracker::SetImageHypothesisSource: image hypotheses are for the event search.");
  }
  image_source_ = source;
  event_image_ = source == nullptr
                     ? nullptr
                     : std::make_unique<EventImage>(sensor_camera_.width, sensor_camera_.height,
                                                    options_.relocalization_image_tau_s);
  last_image_request_t_ns_.reset();
}

void Tracker::BeginSearch(TrackingStatus status, int64_t t_ns) {
  status_ = status;
  search_decay_ns_ = 0;
  search_start_t_ns_ = t_ns;
  search_credit_ns_ = options_.relocalization_cpu_burst_s * 1e9;
  search_credit_t_ns_ = t_ns;
  round_cpu_ns_ = 0;  // A round in progress is dropped; the last whole round's cost is kept.
  search_phase_ = SearchPhase::kStart;
  ++search_progress_.episode;
  search_progress_.round = 0;
  search_progress_.verified_steps = 0;
  search_progress_.best_alignment = 0;
  search_progress_.second_alignment = 0;
  viewpoints_.clear();
  hypotheses_.clear();
  refinements_.clear();
  rivals_.clear();
  // The image of the events starts again with the episode (a request in flight still joins a
  // round of it: its poses are refined against the newest events like any hypothesis).
  if (event_image_) event_image_->Clear();
  last_image_request_t_ns_.reset();
}

std::vector<Rigid3d> Tracker::ImageHypotheses(int64_t t_ns) {
  if (image_source_ == nullptr) return {};
  if (static_cast<double>(event_image_->covered_ns()) <
      options_.relocalization_image_min_events_s * 1e9) {
    return {};
  }
  if (last_image_request_t_ns_ && static_cast<double>(t_ns - *last_image_request_t_ns_) <
                                      options_.relocalization_image_interval_s * 1e9) {
    return {};
  }
  last_image_request_t_ns_ = t_ns;
  // In the step that asks, so that the poses are of this step's instant: computed on a thread of
  // their own and taken at a later round (as before 2026-11-28, with a CPU share), they were as
  // old as the round took, and a moving camera was never found from them. With a CPU share the
  // request's cost is charged like the rest of the step's search work.
  cv::Mat image = event_image_->Render(t_ns);
  if (options_.relocalization_image_blur_px > 0) {
    cv::GaussianBlur(image, image, cv::Size(), options_.relocalization_image_blur_px);
  }
  std::vector<Rigid3d> poses;
  for (const Rigid3d& pose : image_source_->Hypotheses(image, t_ns)) {
    bool is_new = true;
    for (const Rigid3d& kept : poses) is_new = is_new && Distinct(kept, pose);
    if (is_new) poses.push_back(pose);
  }
  search_progress_.image_hypotheses += static_cast<int>(poses.size());
  return poses;
}

void Tracker::ChooseSearchDecay(int64_t t_ns) {
  const double longest_ns = options_.decay_time_s * 1e9;
  const double log_ratio = std::log(1.0 / options_.empty_threshold);
  const int64_t longest_age_ns = std::llround(longest_ns * log_ratio);
  const size_t pixels = static_cast<size_t>(surface_.width()) * surface_.height();
  const int64_t* last = surface_.LastTimestamps(SurfaceChannel::kAll);
  std::vector<int64_t>& ages = scratch_ages_;
  ages.clear();
  for (size_t i = 0; i < pixels; ++i) {
    if (last[i] != kNeverFired && t_ns - last[i] <= longest_age_ns) ages.push_back(t_ns - last[i]);
  }
  const size_t wanted =
      static_cast<size_t>(options_.relocalization_active_fraction * static_cast<double>(pixels));
  double decay_ns = longest_ns;
  if (wanted > 0 && ages.size() > wanted) {
    std::nth_element(ages.begin(), ages.begin() + (wanted - 1), ages.end());
    decay_ns = static_cast<double>(ages[wanted - 1]) / log_ratio;
  }
  search_decay_ns_ = std::clamp(decay_ns, options_.min_decay_time_s * 1e9, longest_ns);
  // This step's surfaces were set up with the previous decay: again with the new one.
  UpdateSurfaces(t_ns);
}

double Tracker::BuildChamferFields(int64_t t_ns) {
  const int width = surface_.width();
  const int height = surface_.height();
  cv::Mat not_active(height, width, CV_8UC1);
  const int64_t* last = surface_.LastTimestamps(SurfaceChannel::kAll);
  const int64_t max_age = decay_.MaxActiveAgeExactNs();
  int active = 0;
  for (int y = 0; y < height; ++y) {
    uint8_t* row = not_active.ptr<uint8_t>(y);
    for (int x = 0; x < width; ++x) {
      const int64_t t_last = last[static_cast<size_t>(y) * width + x];
      const bool fired = t_last != kNeverFired && t_ns - t_last <= max_age;
      row[x] = fired ? 0 : 255;
      active += fired ? 1 : 0;
    }
  }
  if (active == 0) {
    chamfer_distance_px_ = cv::Mat(height, width, CV_32FC1, cv::Scalar(1e6f));
  } else {
    cv::distanceTransform(not_active, chamfer_distance_px_, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  }
  const double coarse = options_.relocalization_chamfer_truncation_px;
  const double fine = coarse / 3;
  cv::Mat coarse_values;
  cv::Mat fine_values;
  cv::min(chamfer_distance_px_, coarse, coarse_values);
  cv::min(chamfer_distance_px_, fine, fine_values);
  chamfer_coarse_ = DenseField(coarse_values / coarse);
  chamfer_fine_ = DenseField(fine_values / fine);
  return static_cast<double>(active) / (static_cast<double>(width) * height);
}

void Tracker::RestartSearchRound() {
  search_phase_ = SearchPhase::kStart;
  refresh_viewpoints_ = false;
  viewpoints_.clear();
  viewpoint_points_.clear();
  hypotheses_.clear();
  refinements_.clear();
  rivals_.clear();
}

void Tracker::GenerateHypotheses() {
  if (viewpoints_.empty() || refresh_viewpoints_) {
    // New viewpoints: the last round's rivals index the old ones.
    if (refresh_viewpoints_) rivals_.clear();
    refresh_viewpoints_ = false;
    viewpoints_.clear();
    ViewpointQuery query;
    query.samples_between_keyframes = options_.relocalization_samples_between_keyframes;
    query.search_center = search_center_;
    query.search_radius_m = search_radius_m_;
    source_->CandidateViewpoints(query, &viewpoints_);
    if (search_hint_) {
      // Each viewpoint's position also with the hint's orientation, where that is turned from
      // the viewpoint's beyond the perturbations: an odometry drifts in position by tens of
      // centimetres but in orientation by a few degrees, and a camera turning back to the map
      // sees it long before it faces the way a keyframe did (the rendered room: the map in view
      // 50 degrees from the keyframes' orientation, found from the keyframes only at 7 degrees;
      // docs/accuracy.md, "Hand-over").
      const size_t base_viewpoints = viewpoints_.size();
      for (size_t i = 0; i < base_viewpoints; ++i) {
        if (AngleBetween(viewpoints_[i].rotation, search_hint_->rotation) >
            options_.relocalization_perturbation_deg * kRadiansPerDegree) {
          viewpoints_.push_back(Rigid3d(search_hint_->rotation, viewpoints_[i].translation));
        }
      }
    }
    if (has_pose_ &&
        (!search_center_ ||
         (last_good_world_from_cam_.translation - *search_center_).norm() <= search_radius_m_)) {
      viewpoints_.insert(viewpoints_.begin(), last_good_world_from_cam_);
    }
    // The pre-score points of each viewpoint are sampled when first needed.
    viewpoint_points_.assign(viewpoints_.size(), {});
    viewpoint_depth_m_.assign(viewpoints_.size(), 0);
    viewpoint_sampled_.assign(viewpoints_.size(), 0);
    // The grid of position offsets around each viewpoint, nearest first.
    grid_offsets_.clear();
    const double step = options_.relocalization_grid_step_m;
    const double radius = options_.relocalization_grid_radius_m;
    const int cells = static_cast<int>(std::floor(radius / step + 1e-9));
    for (int i = -cells; i <= cells; ++i) {
      for (int j = -cells; j <= cells; ++j) {
        for (int k = -cells; k <= cells; ++k) {
          const Eigen::Vector3d offset(i * step, j * step, k * step);
          if (offset.norm() <= radius + 1e-9) grid_offsets_.push_back(offset);
        }
      }
    }
    std::stable_sort(
        grid_offsets_.begin(), grid_offsets_.end(),
        [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return a.norm() < b.norm(); });
  }
  hypotheses_.clear();
  next_viewpoint_ = 0;
}

int Tracker::PrescoreViewpoint(size_t viewpoint) {
  SampleViewpointPoints(viewpoint);
  if (viewpoint_points_[viewpoint].empty()) return 0;
  const Rigid3d& base = viewpoints_[viewpoint];
  const Eigen::Vector3d axis = base.rotation * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d target = base.translation + viewpoint_depth_m_[viewpoint] * axis;
  const double r = options_.relocalization_perturbation_deg * kRadiansPerDegree;
  const size_t keep = static_cast<size_t>(options_.relocalization_coarse_candidates);
  const auto worse = [](const Hypothesis& a, const Hypothesis& b) {
    return a.prescore < b.prescore;
  };
  int scored = 0;
  for (const Eigen::Vector3d& offset : grid_offsets_) {
    const Eigen::Vector3d position = base.translation + offset;
    const Eigen::Vector3d towards = target - position;
    if (towards.norm() < options_.min_depth_m) continue;
    // Turn the base orientation so that it looks at the same target (the roll is kept).
    const Eigen::Quaterniond turn = Eigen::Quaterniond::FromTwoVectors(axis, towards);
    const Rigid3d looking((turn * base.rotation).normalized(), position);
    for (int variant = 0; variant < 5; ++variant) {
      if (variant > 0 && r <= 0) break;
      Vector6d perturbation = Vector6d::Zero();
      if (variant > 0) perturbation(3 + (variant - 1) / 2) = (variant % 2 == 1 ? 1 : -1) * r;
      Hypothesis hypothesis{variant == 0 ? looking : looking * ExpSE3(perturbation), viewpoint, 1};
      hypothesis.prescore = Prescore(hypothesis);
      ++scored;
      // Keep the best `keep` in a max-heap on the pre-score.
      if (hypotheses_.size() < keep) {
        hypotheses_.push_back(hypothesis);
        std::push_heap(hypotheses_.begin(), hypotheses_.end(), worse);
      } else if (hypothesis.prescore < hypotheses_.front().prescore) {
        std::pop_heap(hypotheses_.begin(), hypotheses_.end(), worse);
        hypotheses_.back() = hypothesis;
        std::push_heap(hypotheses_.begin(), hypotheses_.end(), worse);
      }
    }
  }
  return scored;
}

double Tracker::MedianDepth(const std::vector<uint32_t>& indices,
                            const Rigid3d& cam_from_world) const {
  const Eigen::Matrix3d rotation = cam_from_world.RotationMatrix();
  std::vector<double> depths;
  depths.reserve(indices.size());
  for (const uint32_t index : indices) {
    depths.push_back(
        (rotation * points_.positions[index].cast<double>() + cam_from_world.translation).z());
  }
  std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
  return depths[depths.size() / 2];
}

void Tracker::SampleViewpointPoints(size_t viewpoint) {
  if (viewpoint_sampled_[viewpoint]) return;
  viewpoint_sampled_[viewpoint] = 1;
  const Camera& ideal = ideal_camera_;
  VisibilityQueryOptions query;
  query.min_depth_m = options_.min_depth_m;
  query.max_depth_m = options_.max_depth_m;
  query.image_margin_px = options_.registration.image_margin_px;
  source_->VisibleCandidates(ideal, viewpoints_[viewpoint], query, &candidates_);
  // The candidates inside the image, then every k-th of them (cheaper than SelectEvenly's
  // buckets; the pre-score only ranks hypotheses).
  const Rigid3d cam_from_world = viewpoints_[viewpoint].Inverse();
  const Eigen::Matrix3d rotation = cam_from_world.RotationMatrix();
  std::vector<uint32_t>& inside = scratch_group_indices_;
  inside.clear();
  for (const uint32_t index : candidates_) {
    const Eigen::Vector3d point_in_cam =
        rotation * points_.positions[index].cast<double>() + cam_from_world.translation;
    Eigen::Vector2d pixel;
    if (point_in_cam.z() < options_.min_depth_m || point_in_cam.z() > options_.max_depth_m ||
        !intrinsics_.Project(point_in_cam, &pixel) || !InsideImage(pixel)) {
      continue;
    }
    inside.push_back(index);
  }
  std::vector<uint32_t>& sample = viewpoint_points_[viewpoint];
  sample.clear();
  const size_t wanted = static_cast<size_t>(options_.relocalization_prescore_points);
  if (inside.size() < static_cast<size_t>(options_.min_points)) return;
  viewpoint_depth_m_[viewpoint] = MedianDepth(inside, cam_from_world);
  const double stride = std::max(1.0, static_cast<double>(inside.size()) / wanted);
  for (double k = 0; k < static_cast<double>(inside.size()) && sample.size() < wanted;
       k += stride) {
    sample.push_back(inside[static_cast<size_t>(k)]);
  }
}

double Tracker::Prescore(const Hypothesis& hypothesis) const {
  if (viewpoint_points_[hypothesis.viewpoint].empty()) return 1;
  const Rigid3d cam_from_world = hypothesis.world_from_cam.Inverse();
  const Eigen::Matrix3d rotation = cam_from_world.RotationMatrix();
  const double truncation = options_.relocalization_chamfer_truncation_px;
  const int width = chamfer_distance_px_.cols;
  const int height = chamfer_distance_px_.rows;
  double cost = 0;
  int count = 0;
  for (const uint32_t index : viewpoint_points_[hypothesis.viewpoint]) {
    ++count;
    Eigen::Vector2d pixel;
    const Eigen::Vector3d point_in_cam =
        rotation * points_.positions[index].cast<double>() + cam_from_world.translation;
    int x;
    int y;
    if (!intrinsics_.Project(point_in_cam, &pixel) ||
        !NearestEdgeField::RoundToPixel(pixel, &x, &y) || x < 0 || y < 0 || x >= width ||
        y >= height) {
      cost += 1;
      continue;
    }
    cost += std::min<double>(chamfer_distance_px_.ptr<float>(y)[x], truncation) / truncation;
  }
  return count > 0 ? cost / count : 1;
}

void Tracker::CoarseAlign(Hypothesis* hypothesis) {
  const std::vector<uint32_t>& sample = viewpoint_points_[hypothesis->viewpoint];
  Rigid3d pose = hypothesis->world_from_cam;
  for (DenseField* field : {&chamfer_coarse_, &chamfer_fine_}) {
    scratch_points_.clear();
    for (const uint32_t index : sample) {
      scratch_points_.push_back({points_.positions[index].cast<double>(), field});
    }
    pose = RegisterPoints(scratch_points_, intrinsics_, pose.Inverse(), options_.registration)
               .cam_from_world.Inverse();
  }
  hypothesis->world_from_cam = pose;
  // On-edge fraction of the sample at the aligned pose minus that of its copies displaced by
  // 4 px (as Assess): high only where the points fit better than texture fits anything.
  static const Eigen::Vector2d kOffsets[4] = {{4.0, 1.0}, {-1.0, 4.0}, {-4.0, -1.0}, {1.0, -4.0}};
  const Rigid3d cam_from_world = pose.Inverse();
  const Eigen::Matrix3d rotation = cam_from_world.RotationMatrix();
  const auto near_edge = [this](const Eigen::Vector2d& pixel) {
    int x;
    int y;
    if (!NearestEdgeField::RoundToPixel(pixel, &x, &y) || x < 0 || y < 0 ||
        x >= chamfer_distance_px_.cols || y >= chamfer_distance_px_.rows) {
      return false;
    }
    return chamfer_distance_px_.ptr<float>(y)[x] <= options_.on_edge_radius_px;
  };
  int on = 0;
  int chance = 0;
  int count = 0;
  for (const uint32_t index : sample) {
    Eigen::Vector2d pixel;
    if (!intrinsics_.Project(
            rotation * points_.positions[index].cast<double>() + cam_from_world.translation,
            &pixel)) {
      ++count;
      continue;
    }
    on += near_edge(pixel) ? 1 : 0;
    chance += near_edge(pixel + kOffsets[count % 4]) ? 1 : 0;
    ++count;
  }
  hypothesis->coarse_score = count > 0 ? static_cast<double>(on - chance) / count : -1;
}

RegistrationResult Tracker::RegisterSelection(PotentialField* field,
                                              const Rigid3d& start_world_from_cam) {
  scratch_points_.clear();
  for (const uint32_t index : selected_) {
    scratch_points_.push_back({points_.positions[index].cast<double>(), field});
  }
  return RegisterPoints(scratch_points_, intrinsics_, start_world_from_cam.Inverse(),
                        options_.registration);
}

std::optional<Rigid3d> Tracker::ChamferStages(const Rigid3d& start_world_from_cam) {
  SelectPoints(start_world_from_cam);
  if (selected_.size() < static_cast<size_t>(options_.min_points)) return std::nullopt;
  const Rigid3d coarse =
      RegisterSelection(&chamfer_coarse_, start_world_from_cam).cam_from_world.Inverse();
  const Rigid3d fine = RegisterSelection(&chamfer_fine_, coarse).cam_from_world.Inverse();
  // Select again where the chamfer stages ended when they moved the pose (as tracking would).
  if ((fine.translation - start_world_from_cam.translation).norm() >
          options_.reselect_translation_m ||
      AngleBetween(fine.rotation, start_world_from_cam.rotation) >
          options_.reselect_rotation_deg * kRadiansPerDegree) {
    SelectPoints(fine);
  }
  if (selected_.size() < static_cast<size_t>(options_.min_points)) return std::nullopt;
  return fine;
}

Tracker::Refinement Tracker::Refine(const Rigid3d& start_world_from_cam, int64_t t_ns) {
  Refinement refinement;
  refinement.world_from_cam = start_world_from_cam;
  refinement.t_ns = t_ns;
  const std::optional<Rigid3d> fine = ChamferStages(start_world_from_cam);
  if (!fine) return refinement;
  // The selection is still the one ChamferStages ended with, at about the refined place.
  refinement.depth_m = MedianDepth(selected_, fine->Inverse());
  const Attempt attempt = Solve(*fine, nullptr);
  refinement.world_from_cam = attempt.registration.cam_from_world.Inverse();
  refinement.alignment = attempt.quality.alignment;
  refinement.points_used = attempt.quality.points_used;
  refinement.good = attempt.good;
  refinement.motion = ConstantVelocityModel(std::llround(options_.velocity_window_s * 1e9));
  refinement.motion.Reset(refinement.world_from_cam, t_ns);
  return refinement;
}

void Tracker::AddRefinement(Refinement refinement) {
  for (Refinement& kept : refinements_) {
    if (kept.t_ns == refinement.t_ns && !DistinctPlaces(refinement, kept)) {
      // One place: the better pose, under the first one's name (a probe that came back to its
      // winner is the winner).
      const bool probe = kept.probe;
      if (refinement.alignment > kept.alignment) kept = std::move(refinement);
      kept.probe = probe;
      return;
    }
  }
  refinements_.push_back(std::move(refinement));
}

void Tracker::FollowBestRefinement(int64_t t_ns) {
  if (!SurfacesFull(t_ns)) return;  // a step inside a silence would lose it
  Refinement* best = BestRefinement();
  if (best == nullptr || best->t_ns >= t_ns) return;
  const Rigid3d predicted = best->motion.Predict(t_ns);
  SelectPoints(predicted);
  const Attempt attempt = Solve(predicted, nullptr);
  search_progress_.followed = attempt.good;
  if (!attempt.good) return;
  best->alignment = attempt.quality.alignment;
  best->points_used = attempt.quality.points_used;
  best->world_from_cam = attempt.registration.cam_from_world.Inverse();
  best->t_ns = t_ns;
  best->motion.Update(best->world_from_cam, t_ns);
}

bool Tracker::SurfacesFull(int64_t t_ns) const {
  return events_since_t_ns_ && t_ns - *events_since_t_ns_ >= options_.decay_time_s * 1e9 &&
         last_inserted_t_ns_ && t_ns - *last_inserted_t_ns_ <= SilenceNs();
}

int64_t Tracker::SilenceNs() const {
  return static_cast<int64_t>(options_.min_decay_time_s * 1e9 *
                              std::log(1.0 / options_.empty_threshold));
}

Tracker::Refinement* Tracker::BestRefinement(bool with_probes) {
  Refinement* best = nullptr;
  for (Refinement& refinement : refinements_) {
    if (refinement.good && (with_probes || !refinement.probe) &&
        (best == nullptr || refinement.alignment > best->alignment)) {
      best = &refinement;
    }
  }
  return best;
}

bool Tracker::Distinct(const Rigid3d& a, const Rigid3d& b, double distinct_m) const {
  return (a.translation - b.translation).norm() >
             std::max(distinct_m, options_.relocalization_distinct_m) ||
         AngleBetween(a.rotation, b.rotation) >
             options_.relocalization_distinct_deg * kRadiansPerDegree;
}

bool Tracker::DistinctPlaces(const Refinement& other, const Refinement& reference) const {
  return Distinct(other.world_from_cam, reference.world_from_cam,
                  options_.relocalization_distinct_depth_fraction * reference.depth_m);
}

void Tracker::KeepRivals() {
  std::vector<const Refinement*> order;
  for (const Refinement& refinement : refinements_) {
    if (refinement.points_used >= options_.min_points) order.push_back(&refinement);
  }
  std::stable_sort(order.begin(), order.end(), [](const Refinement* a, const Refinement* b) {
    return a->alignment > b->alignment;
  });
  rivals_.clear();
  for (const Refinement* refinement : order) {
    if (rivals_.size() == static_cast<size_t>(options_.relocalization_rivals)) break;
    bool is_new = true;
    for (const Hypothesis& kept : rivals_) {
      is_new =
          is_new && Distinct(kept.world_from_cam, refinement->world_from_cam,
                             options_.relocalization_distinct_depth_fraction * refinement->depth_m);
    }
    if (is_new) rivals_.push_back({refinement->world_from_cam, 0, 0, refinement->alignment});
  }
}

bool Tracker::JudgeRound(Refinement* accepted, const Refinement* probed_winner) {
  // The best good refinement, against the best distinct one that registered enough points
  // (good or not: an ambiguity need not pass every threshold to make the best one doubtful).
  const Refinement* best = BestRefinement();
  search_progress_.best_alignment = 0;
  search_progress_.second_alignment = 0;
  if (best == nullptr) {
    KeepRivals();
    return false;
  }
  // The probes and the winner they started around are one neighbourhood, judged with the probe
  // margin (is the best its peak?); any other distinct fit with the full margin.
  const auto local = [probed_winner](const Refinement& refinement) {
    return refinement.probe || &refinement == probed_winner;
  };
  const bool local_best = local(*best);
  double second = 0;
  double second_local = 0;
  for (const Refinement& other : refinements_) {
    if (other.points_used >= options_.min_points && DistinctPlaces(other, *best)) {
      if (local_best && local(other)) {
        second_local = std::max(second_local, other.alignment);
      } else {
        second = std::max(second, other.alignment);
      }
    }
  }
  search_progress_.best_alignment = best->alignment;
  search_progress_.second_alignment = std::max(second, second_local);
  KeepRivals();
  if (best->alignment - second < options_.relocalization_min_alignment_margin ||
      best->alignment - second_local < options_.relocalization_probe_margin) {
    return false;
  }
  *accepted = *best;
  return true;
}

void Tracker::SearchStep(int64_t t_ns, PoseEstimate* estimate) {
  SearchProgress& progress = search_progress_;
  progress.prescored = 0;
  progress.coarse = 0;
  progress.refined = 0;
  progress.gave_up = false;
  progress.deferred = false;
  progress.refilling = false;
  progress.followed = false;
  progress.probe_replaced = false;
  progress.image_hypotheses = 0;
  estimate->world_from_cam = last_good_reported_world_from_cam_;
  estimate->covariance = Matrix6d::Identity() * kUnconstrainedVariance;
  estimate->quality.decay_time_ms = decay_.decay_time_ns * 1e-6;

  if (search_phase_ == SearchPhase::kVerify) {
    // Track the accepted hypothesis normally (unsigned surface, constant velocity) and require
    // every step of the window to be good. The accepted pose is that of the step it was last
    // followed to (FollowBestRefinement: usually the judging step; older when following
    // failed), and the camera has moved since: the first step aligns it on chamfer fields of
    // its own events first, as a refinement does.
    //
    // A silence in the stream (a blackout, or a live session's queue that dropped packets while
    // it searched) leaves the surfaces with only the events since: a step on them is not a test
    // of the hypothesis. The window waits for one decay time of events, then starts again with
    // the chamfer alignment, from the motion model's prediction across the gap.
    if (!SurfacesFull(t_ns)) {
      progress.verified_steps = 0;
      progress.refilling = true;
      estimate->status = status_;
      estimate->search = progress;
      return;
    }
    Rigid3d start = motion_.Predict(t_ns);
    std::optional<Rigid3d> aligned;
    if (progress.verified_steps == 0) {
      BuildChamferFields(t_ns);
      aligned = ChamferStages(start);
    }
    if (aligned) {
      start = *aligned;
    } else {
      SelectPoints(start);
    }
    const Attempt attempt = Solve(start, nullptr);
    estimate->quality = attempt.quality;
    estimate->quality.decay_time_ms = decay_.decay_time_ns * 1e-6;
    if (attempt.good && attempt.quality.alignment >= options_.relocalization_verify_min_alignment) {
      const Rigid3d pose = attempt.registration.cam_from_world.Inverse();
      // The accepted pose only predicts the first verification step: it was refined partly on
      // fields built when the round began, several steps ago, so a velocity measured from it
      // over one step would carry that age (decimetres per second after a centimetre), and
      // tracking would start from a wrong prediction. The velocity comes from tracked steps.
      if (progress.verified_steps == 0) {
        motion_.Reset(pose, t_ns);
        verify_start_t_ns_ = t_ns;
      } else {
        motion_.Update(pose, t_ns);
      }
      ++progress.verified_steps;
      const double window_s = static_cast<double>(t_ns - verify_start_t_ns_) * 1e-9;
      if (progress.verified_steps >= options_.relocalization_verify_steps &&
          window_s >= options_.relocalization_verify_s_per_depth_m * verify_depth_m_) {
        status_ = TrackingStatus::kTracking;
        has_pose_ = true;
        lost_steps_ = 0;
        last_good_world_from_cam_ = pose;
        last_good_reported_world_from_cam_ = pose;
        estimate->world_from_cam = pose;
        estimate->covariance = attempt.registration.covariance;
        estimate->status = status_;
        estimate->search = progress;
        return;
      }
    } else {
      progress.verified_steps = 0;
      search_phase_ = SearchPhase::kStart;
    }
    estimate->status = status_;
    estimate->search = progress;
    return;
  }

  // The CPU share: the budget grows with event time, up to the burst or the last whole round's
  // cost if larger; a step without credit does no search work, and a round about to start waits
  // until the budget covers the last round's cost, so that it runs on consecutive steps.
  const bool bounded = options_.relocalization_cpu_share > 0;
  const auto in_round = [this] {
    return search_phase_ == SearchPhase::kPrescore || search_phase_ == SearchPhase::kCoarse ||
           search_phase_ == SearchPhase::kRefine || search_phase_ == SearchPhase::kProbe;
  };
  // The round's best refinement follows the camera on every step, deferred or not: a pose left
  // behind for a few steps would no longer register. It is one tracking step, as a session
  // that tracks pays, and not charged to the share: charged, a share below one step's cost
  // (5 % of a core on this room) would spend every step's credit on it and the round would
  // never end.
  const bool was_in_round = in_round();
  if (was_in_round) FollowBestRefinement(t_ns);
  int64_t cpu_start_ns = 0;
  if (bounded) {
    search_credit_ns_ =
        std::min(search_credit_ns_ + options_.relocalization_cpu_share *
                                         static_cast<double>(t_ns - search_credit_t_ns_),
                 std::max(options_.relocalization_cpu_burst_s * 1e9, last_round_cpu_ns_));
    search_credit_t_ns_ = t_ns;
    const bool saving_up =
        search_phase_ == SearchPhase::kStart && search_credit_ns_ < last_round_cpu_ns_;
    if (search_credit_ns_ <= 0 || saving_up) {
      progress.deferred = true;
      FinishSearchStep(t_ns, estimate);
      return;
    }
    cpu_start_ns = ThreadCpuTimeNs();
  }
  SearchWork(t_ns);
  if (bounded) {
    const double used = static_cast<double>(ThreadCpuTimeNs() - cpu_start_ns);
    search_credit_ns_ -= used;
    // A round runs from the step that leaves kStart to the step that judges it (or finds no
    // hypothesis); its cost is what the next round saves up for.
    if (was_in_round || in_round()) round_cpu_ns_ += used;
    if (!in_round()) {
      if (round_cpu_ns_ > 0) last_round_cpu_ns_ = round_cpu_ns_;
      round_cpu_ns_ = 0;
    }
  }
  FinishSearchStep(t_ns, estimate);
}

void Tracker::SearchWork(int64_t t_ns) {
  SearchProgress& progress = search_progress_;
  // A round needs full surfaces and enough active pixels; so does a refinement, whose
  // registration ends on this step's surfaces.
  const bool surfaces_full = SurfacesFull(t_ns);
  progress.refilling = !surfaces_full && (search_phase_ == SearchPhase::kStart ||
                                          search_phase_ == SearchPhase::kRefine ||
                                          search_phase_ == SearchPhase::kProbe);
  if (search_phase_ == SearchPhase::kStart && surfaces_full) {
    ChooseSearchDecay(t_ns);
    const double active = BuildChamferFields(t_ns);
    if (active >= options_.relocalization_min_active_fraction) {
      GenerateHypotheses();
      next_refinement_ = 0;
      refinements_.clear();
      ++progress.round;
      // Image hypotheses are refined at once, on this step's fields: a pose of this instant.
      for (const Rigid3d& pose : ImageHypotheses(t_ns)) {
        AddRefinement(Refine(pose, t_ns));
        ++progress.refined;
      }
      if (!viewpoints_.empty()) {
        search_phase_ = SearchPhase::kPrescore;
      } else if (search_hint_) {
        // No viewpoint (a map without keyframes, or none within the prior): the hint stands in
        // for them, judged at the next step. Only then: beside the viewpoints, a hint that
        // drifted onto a false fit of a repeated pattern becomes the right pose's rival and the
        // margin refuses both (the rendered room turned 60 degrees right, docs/accuracy.md).
        AddRefinement(Refine(*search_hint_, t_ns));
        ++progress.refined;
        hypotheses_.clear();
        next_refinement_ = 0;
        search_phase_ = SearchPhase::kRefine;
      }
    }
  }
  if (search_phase_ == SearchPhase::kPrescore) {
    // Whole viewpoints (their grid and turns) while the step's budget allows (at least one).
    const int per_viewpoint = static_cast<int>(grid_offsets_.size()) *
                              (options_.relocalization_perturbation_deg > 0 ? 5 : 1);
    while (next_viewpoint_ < viewpoints_.size() &&
           (progress.prescored == 0 ||
            progress.prescored + per_viewpoint <= options_.relocalization_prescores_per_step)) {
      progress.prescored += PrescoreViewpoint(next_viewpoint_++);
    }
    if (next_viewpoint_ == viewpoints_.size()) {
      std::sort_heap(
          hypotheses_.begin(), hypotheses_.end(),
          [](const Hypothesis& a, const Hypothesis& b) { return a.prescore < b.prescore; });
      next_coarse_ = 0;
      search_phase_ = hypotheses_.empty() ? SearchPhase::kStart : SearchPhase::kCoarse;
    }
  } else if (search_phase_ == SearchPhase::kCoarse) {
    // Chamfer registration of the pre-score points, then a chance-corrected score: ranks the
    // survivors of the pre-score by how well they fit once aligned.
    for (int i = 0;
         i < options_.relocalization_coarse_per_step && next_coarse_ < hypotheses_.size(); ++i) {
      CoarseAlign(&hypotheses_[next_coarse_++]);
      ++progress.coarse;
    }
    if (next_coarse_ == hypotheses_.size()) {
      std::stable_sort(
          hypotheses_.begin(), hypotheses_.end(),
          [](const Hypothesis& a, const Hypothesis& b) { return a.coarse_score > b.coarse_score; });
      // The previous round's best distinct refinements first (an ambiguity seen once stays in
      // view: rounds see different subsets of the hypotheses), then the best distinct aligned
      // poses (hypotheses aligned onto one pose would refine to it alike, and a list of one
      // place would hide the ambiguity the judgement looks for).
      std::vector<Hypothesis> distinct = rivals_;
      for (const Hypothesis& hypothesis : hypotheses_) {
        if (distinct.size() >= static_cast<size_t>(options_.relocalization_candidates)) break;
        bool is_new = true;
        for (const Hypothesis& kept : distinct) {
          is_new = is_new && Distinct(kept.world_from_cam, hypothesis.world_from_cam);
        }
        if (is_new) distinct.push_back(hypothesis);
      }
      hypotheses_ = std::move(distinct);
      search_phase_ = SearchPhase::kRefine;
    }
  } else if (search_phase_ == SearchPhase::kRefine && surfaces_full) {
    for (int i = 0;
         i < options_.relocalization_refinements_per_step && next_refinement_ < hypotheses_.size();
         ++i) {
      AddRefinement(Refine(hypotheses_[next_refinement_++].world_from_cam, t_ns));
      ++progress.refined;
    }
    if (next_refinement_ == hypotheses_.size()) {
      Refinement accepted;
      if (!JudgeRound(&accepted)) {
        search_phase_ = SearchPhase::kStart;
      } else {
        probe_offsets_ = ProbeOffsets(accepted.world_from_cam);
        next_probe_ = 0;
        search_phase_ = SearchPhase::kProbe;
      }
    }
  } else if (search_phase_ == SearchPhase::kProbe && surfaces_full) {
    // The winner is followed to this step (FollowBestRefinement) while it is the best; the
    // probes start around where it is now.
    const Refinement* best = BestRefinement();
    const Rigid3d around = best ? best->world_from_cam : Rigid3d();
    // The round's fields are of its first step; the probes start from a pose of this one.
    if (best) BuildChamferFields(t_ns);
    for (int i = 0; best && i < options_.relocalization_refinements_per_step &&
                    next_probe_ < probe_offsets_.size();
         ++i) {
      Refinement probe = Refine(around * probe_offsets_[next_probe_++], t_ns);
      probe.probe = true;
      AddRefinement(std::move(probe));
      ++progress.refined;
    }
    if (best == nullptr || next_probe_ == probe_offsets_.size()) {
      Refinement accepted;
      if (best && JudgeProbedRound(&accepted)) {
        motion_.Reset(accepted.world_from_cam, accepted.t_ns);
        verify_depth_m_ = accepted.depth_m;
        progress.verified_steps = 0;
        search_phase_ = SearchPhase::kVerify;
      } else {
        search_phase_ = SearchPhase::kStart;
      }
    }
  }
}

std::vector<Rigid3d> Tracker::ProbeOffsets(const Rigid3d& world_from_cam) {
  std::vector<Rigid3d> offsets;
  if (options_.relocalization_probe_depth_fraction <= 0) return offsets;
  SelectPoints(world_from_cam);
  if (selected_.size() < static_cast<size_t>(options_.min_points)) return offsets;
  const double depth = MedianDepth(selected_, world_from_cam.Inverse());
  if (!(depth > 0)) return offsets;
  const double shift = options_.relocalization_probe_depth_fraction * depth;
  const Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  for (const double sign : {1.0, -1.0}) {
    for (const Eigen::Vector3d sideways : {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY()}) {
      // Shifted sideways, turned to look at the point `depth` ahead of the winner.
      const Eigen::Vector3d position = sign * shift * sideways;
      offsets.emplace_back(Eigen::Quaterniond::FromTwoVectors(axis, depth * axis - position),
                           position);
    }
    offsets.emplace_back(Eigen::Quaterniond::Identity(), sign * shift * axis);
  }
  return offsets;
}

Tracker::ProbeCheck Tracker::ProbeLastPose() {
  ProbeCheck check;
  if (status_ != TrackingStatus::kTracking || !has_pose_ || !SurfacesFull(last_step_t_ns_)) {
    return check;
  }
  // Refine selects points: the step's selection is put back after the probes.
  const std::vector<uint32_t> selected = selected_;
  const Rigid3d selection_world_from_cam = selection_world_from_cam_;
  const int steps_since_selection = steps_since_selection_;
  const bool has_selection = has_selection_;
  const int64_t t_ns = last_step_t_ns_;
  BuildChamferFields(t_ns);
  const Refinement reference = Refine(last_good_world_from_cam_, t_ns);
  if (reference.good) {
    check.alignment = reference.alignment;
    for (const Rigid3d& offset : ProbeOffsets(reference.world_from_cam)) {
      const Refinement probe = Refine(reference.world_from_cam * offset, t_ns);
      ++check.probes;
      if (probe.points_used >= options_.min_points && DistinctPlaces(probe, reference)) {
        check.distinct_alignment = std::max(check.distinct_alignment, probe.alignment);
      }
    }
    check.unique =
        reference.alignment - check.distinct_alignment >= options_.relocalization_probe_margin;
  }
  selected_ = selected;
  selection_world_from_cam_ = selection_world_from_cam;
  steps_since_selection_ = steps_since_selection;
  has_selection_ = has_selection;
  return check;
}

bool Tracker::JudgeProbedRound(Refinement* accepted) {
  const Refinement* winner = BestRefinement(/*with_probes=*/false);
  bool superseded = false;
  for (const Refinement& refinement : refinements_) {
    superseded =
        superseded ||
        (winner && refinement.probe && refinement.good &&
         refinement.alignment > winner->alignment + options_.relocalization_min_alignment_margin &&
         DistinctPlaces(refinement, *winner));
  }
  // The other probes stay: fits around the winner nearly as good as it are an ambiguity the
  // judgement's margin refuses (kept only to polish the winner, they let the 10.6 cm winner of
  // docs/relocalization.md through).
  if (superseded) refinements_.erase(refinements_.begin() + (winner - refinements_.data()));
  search_progress_.probe_replaced = superseded;
  return JudgeRound(accepted, superseded ? nullptr : winner);
}

void Tracker::FinishSearchStep(int64_t t_ns, PoseEstimate* estimate) {
  estimate->status = status_;
  estimate->search = search_progress_;
  if (options_.relocalization_give_up_s > 0 &&
      t_ns - search_start_t_ns_ >= options_.relocalization_give_up_s * 1e9) {
    estimate->search.gave_up = true;
    BeginSearch(status_, t_ns);
  }
}

}  // namespace evloc::tracking
