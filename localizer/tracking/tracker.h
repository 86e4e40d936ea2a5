// The map-based 6-DoF tracker of an event camera (Canny-EVT, docs/tracking.md) and its frame-based
// twin (Canny-VT). Feed it event packets of any size; it runs tracking steps at a fixed
// rate in event time (or every N events) and returns one PoseEstimate per step. The output is
// deterministic: the same events give the same poses however they are split into packets (only
// the measured timings differ). Not thread-safe: one Tracker per session.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/camera/undistortion_table.h"
#include "core/events/event.h"
#include "core/geometry/rigid3.h"
#include "localizer/tracking/event_filter.h"
#include "localizer/tracking/event_image.h"
#include "localizer/tracking/image_hypothesis_source.h"
#include "localizer/tracking/map_source.h"
#include "localizer/tracking/motion_model.h"
#include "localizer/tracking/occlusion.h"
#include "localizer/tracking/polarity.h"
#include "localizer/tracking/potential_field.h"
#include "localizer/tracking/registration.h"
#include "localizer/tracking/time_surface.h"
#include "localizer/tracking/tracker_options.h"
#include "maps/map.h"
#include "maps/visibility.h"

namespace evloc::tracking {

// Whether the tracker trusts its estimate (docs/tracking.md, "States").
enum class TrackingStatus {
  // The last step met the quality thresholds (after a search: a verified hypothesis).
  kTracking,
  // The last step (and its recovery attempts) failed them; the tracker searches around the last
  // good pose at every step.
  kLost,
  // Started without a pose and none verified yet: searching the whole map (or the search prior).
  kInitializing,
  // Had a pose, lost it, and the local recovery gave up: searching the whole map again.
  kRelocalizing,
};

// "TRACKING", "LOST", "INITIALIZING" or "RELOCALIZING".
const char* TrackingStatusName(TrackingStatus status);

// True for the statuses whose steps carry no estimate (LOST, INITIALIZING, RELOCALIZING): their
// pose is the last good one (identity before any) with a covariance of 1e6 * I.
inline bool HasNoEstimate(TrackingStatus status) { return status != TrackingStatus::kTracking; }

// True for the statuses of the global search (INITIALIZING, RELOCALIZING): no pose is reported.
inline bool IsSearching(TrackingStatus status) {
  return status == TrackingStatus::kInitializing || status == TrackingStatus::kRelocalizing;
}

// What the global search (INITIALIZING / RELOCALIZING) did in a step.
struct SearchProgress {
  // Search episodes started so far (0: never searched); an episode runs from the step that left
  // TRACKING or LOST for a search until the step that returns to TRACKING.
  int64_t episode = 0;
  // Rounds (hypotheses generated, pre-scored, the best refined, judged) of this episode so far.
  int round = 0;
  // Hypotheses pre-scored in this step.
  int prescored = 0;
  // Hypotheses aligned on the chamfer field with their pre-score points in this step.
  int coarse = 0;
  // Hypotheses refined (coarse-to-fine registration and Assess) in this step.
  int refined = 0;
  // Consecutive good steps tracked from the accepted hypothesis (verification), after this step.
  int verified_steps = 0;
  // True when this step ended an episode that searched relocalization_give_up_s without a
  // verified pose (a new episode starts with the next step).
  bool gave_up = false;
  // True when this step did no search work because the search had used its CPU share
  // (TrackerOptions::relocalization_cpu_share).
  bool deferred = false;
  // True when this step waited for the surfaces to hold one decay time of events (after the
  // first event or a silence in the stream) before a round's start, a refinement or a
  // verification step.
  bool refilling = false;
  // True when this step tracked the round's best refinement to it (FollowBestRefinement).
  bool followed = false;
  // Image hypotheses (ImageHypothesisSource) refined in this step (counted in `refined` too).
  int image_hypotheses = 0;
  // True when this step judged a round whose winner a probe replaced: refined from a start
  // around it, it ended elsewhere better aligned (TrackerOptions::
  // relocalization_probe_depth_fraction).
  bool probe_replaced = false;
  // Alignment of the best refined hypothesis of the last judged round (0 before one).
  double best_alignment = 0;
  // Alignment of the best refined hypothesis distinct from it (0 when there was none).
  double second_alignment = 0;
};

// How well a step's estimate fits the measurements.
struct TrackingQuality {
  // Fraction of the selected points (before occlusion culling) inside the image that lie within
  // on_edge_radius_px of an active edge pixel at the estimate.
  double on_edge_fraction = 0;
  // The same fraction for the points displaced by 4 pixels (one of four directions per point):
  // what an unrelated pose scores by chance on this step's edges. High on dense, textured event
  // images; low when few pixels are active.
  double chance_on_edge_fraction = 0;
  // Chance-corrected alignment, (on_edge - chance) / (1 - chance): 1 when every point lies on an
  // edge, 0 when the points fit no better than displaced copies of themselves. Unlike the mean
  // residual it does not depend on how fresh the events are (how fast the camera moves).
  double alignment = 0;
  // Mean field value at the registered points (0 on fresh edges, 1 far from any).
  double mean_residual = 1;
  // Number of points registered (after occlusion culling, inside the image).
  int points_used = 0;
  // Number of points selected from the map before occlusion culling.
  int points_selected = 0;
  // LM iterations of the accepted attempt (of both solves when it is two-stage).
  int iterations = 0;
  // Number of recovery attempts run in this step (0 when the first solve was good).
  int recovery_attempts = 0;
  // Points with a confident (ON or OFF) polarity prediction that fired in this step: the pixel
  // they project to at the estimate has an event since the previous step.
  int polarity_predictions = 0;
  // Of those, the points whose pixel fired last with the predicted polarity.
  int polarity_matches = 0;
  // The time-surface decay time of the step, milliseconds (adaptive with decay_trail_px).
  double decay_time_ms = 0;
  // The age of the events the estimate was registered to (MeasureSurfaceAge), milliseconds; with
  // stamp_at_step_time the reported pose was moved forward by it to the step time. 0 when not
  // measured (neither stamp_at_step_time nor measure_surface_age, frames, no velocity yet, a step
  // that is no estimate).
  double surface_age_ms = 0;
};

// Wall-clock time spent in each stage of a step, milliseconds.
struct StageTimings {
  // Time-surface (or frame field) upkeep and the ANNF.
  double surface_ms = 0;
  // Visibility query and even subsampling (0 when the previous selection was kept).
  double selection_ms = 0;
  // Polarity prediction, occlusion culling, registration and quality of every attempt.
  double solve_ms = 0;
  // The whole step.
  double total_ms = 0;
};

// The outcome of one tracking step.
struct PoseEstimate {
  // Time of the step, nanoseconds.
  int64_t t_ns = 0;
  // The estimated pose.
  Rigid3d world_from_cam;
  // Covariance of xi in world_from_cam * ExpSE3(xi), xi = (v, omega) in the camera frame.
  Matrix6d covariance = Matrix6d::Identity();
  // Tracking status after this step.
  TrackingStatus status = TrackingStatus::kLost;
  // Fit quality of the estimate.
  TrackingQuality quality;
  // Stage timings (the only field that differs between identical runs).
  StageTimings timings;
  // The global search's work in this step (all zero but `episode` while not searching).
  SearchProgress search;
};

// The tracker of one session.
class Tracker {
 public:
  // Tracks against `source`, which must outlive the tracker; a change of its generation takes
  // effect at the next step (the selection is redone from the new points). `camera` is the
  // event (or frame) camera; its undistortion table is built here once. Throws
  // InvalidArgumentError when the options, the camera or the source's points are invalid (also
  // from the first step after a generation change with invalid points).
  Tracker(const MapSource& source, const Camera& camera, const TrackerOptions& options);

  // Tracks against a fixed map through a StaticMapSource the tracker owns: `map` (and
  // `visibility`, when given; built on `map`) must outlive the tracker. Without a visibility
  // index every map point is a selection candidate.
  Tracker(const Map& map, const VisibilityIndex* visibility, const Camera& camera,
          const TrackerOptions& options);

  // Sets the pose at t_ns (initialisation or an external pose hint): status kTracking, zero
  // velocity, the next fixed-rate step at t_ns + 1 / step_rate_hz.
  void Reset(const Rigid3d& world_from_cam, int64_t t_ns);
  // The same, moving with `velocity` (body-frame twist per second: world_from_cam(t + dt) =
  // world_from_cam(t) * ExpSE3(velocity * dt)), e.g. a session resumed on another server with the
  // velocity of its last poses: the first steps then predict, set their decay time, predict
  // polarities and stamp their poses as the uninterrupted session would (ConstantVelocityModel).
  // Throws InvalidArgumentError for a non-finite pose or velocity.
  void Reset(const Rigid3d& world_from_cam, int64_t t_ns, const Vector6d& velocity);

  // Starts without a pose at t_ns: status kInitializing, the first fixed-rate step at t_ns; the
  // steps search the map (docs/relocalization.md, "Events") until a hypothesis is verified.
  // Throws InvalidArgumentError for a frame tracker (the search works on events).
  void StartWithoutPose(int64_t t_ns);

  // Narrows the global search to viewpoints whose camera centre is within `radius_m` of
  // `center` (world frame, metres); takes effect at the next search round. Throws
  // InvalidArgumentError for a non-finite centre or a radius that is not positive.
  void SetSearchPrior(const Eigen::Vector3d& center, double radius_m);
  // Removes the search prior (the whole map is searched again from the next round).
  void ClearSearchPrior();
  // A hand-over's odometry pose (docs/tracking.md, "Hand-over"): each search round also tries
  // every viewpoint's position with the hint's orientation, and refines the hint itself when the
  // map offers no viewpoint (no keyframe, or none within the prior); all judged as the search
  // judges its refinements (margin, probes, verification). Takes effect at the next round.
  // Throws InvalidArgumentError for a non-finite pose.
  void SetSearchHint(const Rigid3d& world_from_cam);
  // Removes the hint of SetSearchHint (from the next round).
  void ClearSearchHint() {
    search_hint_.reset();
    refresh_viewpoints_ = true;
  }

  // Adds poses located from an image of the events to the global search's rounds
  // (docs/relocalization.md, "Hypotheses from an image of the events"); they are refined and
  // verified like the search's own. `source` must outlive the tracker; null removes it. With a
  // CPU share (relocalization_cpu_share > 0) a request runs on a thread of its own while the
  // steps go on, its CPU time charged to the share when its result is taken; without one it runs
  // within the step (a run stays reproducible).
  void SetImageHypothesisSource(const ImageHypothesisSource* source);

  // Ingests events (time-ordered, also across calls) and runs every step that became due; the
  // step at time t uses every event with t_ns <= t. Before the first Reset (or StartWithoutPose)
  // events are stored but no step runs. Throws InvalidArgumentError (nothing ingested) when the
  // events go back in time or the tracker takes frames; an event outside the sensor throws too.
  std::vector<PoseEstimate> AddEvents(const EventBuffer& events);

  // Declares that every event with t_ns <= `t_ns` has been given (a packet's end time, or a
  // quiet sensor): runs every fixed-rate step whose time is at most `t_ns` without waiting for a
  // later event, so a pose need not wait for the next packet. Events given afterwards must be
  // later than `t_ns`. Steps and poses are the same as when the next event triggers them. Does
  // nothing in every-N-events mode, for frame trackers, or before the first Reset or
  // StartWithoutPose (except to record the bound). Throws InvalidArgumentError when `t_ns` is
  // before the last event.
  std::vector<PoseEstimate> AdvanceTo(int64_t t_ns);

  // Runs one Canny-VT step on a grey frame (CV_8UC1, the camera's size) taken at t_ns. Returns
  // nothing before the first Reset. Throws InvalidArgumentError when the tracker takes events,
  // the image is of another type or size, or t_ns is not after the last step.
  std::optional<PoseEstimate> AddFrame(int64_t t_ns, const cv::Mat& gray);

  // True once Reset or StartWithoutPose was called.
  bool initialized() const { return started_; }
  // Status after the last step (kTracking after Reset, kInitializing after StartWithoutPose).
  TrackingStatus status() const { return status_; }
  // The last good pose (identity before any).
  const Rigid3d& last_good_world_from_cam() const { return last_good_world_from_cam_; }
  // True once the tracker has had a pose (Reset, or a search that found one); false after
  // StartWithoutPose until the search finds the camera.
  bool has_pose() const { return has_pose_; }
  // The options in use.
  const TrackerOptions& options() const { return options_; }
  // The ideal pinhole camera the fields live in.
  const Camera& ideal_camera() const { return ideal_camera_; }
  // The time surface (for inspection and tests).
  const TimeSurface& time_surface() const { return surface_; }
  // The noise filters before the surfaces (their counts, for statistics).
  const EventFilter& event_filter() const { return filter_; }
  // The body-frame velocity of the motion prior, (v, omega) per second.
  const Vector6d& velocity() const { return motion_.velocity(); }
  // The time span of the poses that velocity was measured over, ns (0 after a reset).
  int64_t velocity_span_ns() const { return motion_.velocity_span_ns(); }

  // What the relocalization search's probes find around the last good pose, on the surfaces of
  // the last step: for a pose the search did not judge, such as a hand-over's return from an
  // odometry hint (a drifted hint can settle on the wrong stripe of a repeated pattern and
  // track there). The pose is registered again from itself and from each probe offset
  // (relocalization_probe_depth_fraction), each as the search refines a hypothesis (chamfer
  // stages, then the unsigned solve). The tracking state is left as it was: the next step
  // runs as if this had not been called.
  struct ProbeCheck {
    // Alignment of the registration from the pose itself (0 when it is not good).
    double alignment = 0;
    // The best alignment of the probes that ended at another place (DistinctPlaces), 0 if none.
    double distinct_alignment = 0;
    // Probes registered.
    int probes = 0;
    // The search's judgement: the pose's own registration is good and beats every distinct
    // probe by relocalization_probe_margin.
    bool unique = false;
  };
  // Runs the check at the last step (kTracking; otherwise returns an empty, non-unique check).
  ProbeCheck ProbeLastPose();

 private:
  // The state after a Reset (the motion model already set): TRACKING at the pose, the next step
  // one period after t_ns.
  void StartTrackingAt(const Rigid3d& world_from_cam, int64_t t_ns);
  // The outcome of one solve from one starting pose.
  struct Attempt {
    RegistrationResult registration;
    TrackingQuality quality;
    bool good = false;
  };

  // Tracks against `borrowed`, or when it is null against `owned`.
  Tracker(std::unique_ptr<const MapSource> owned, const MapSource* borrowed, const Camera& camera,
          const TrackerOptions& options);

  // True while the global search runs (INITIALIZING or RELOCALIZING).
  bool searching() const { return IsSearching(status_); }
  // Runs the events that passed the noise filters into the surfaces and the steps they complete.
  std::vector<PoseEstimate> Ingest(const EventBuffer& events);
  // Events [begin, end) into the time surface and, while searching with an image source, into
  // the image of the events.
  void InsertEvents(const EventBuffer& events, size_t begin, size_t end);
  PoseEstimate Step(int64_t t_ns);
  // Reads the source's points and generation; throws InvalidArgumentError when they are
  // inconsistent.
  void ReadSourcePoints();
  void UpdateSurfaces(int64_t t_ns);
  double StepDecayTimeNs() const;
  void SelectPoints(const Rigid3d& predicted_world_from_cam);
  // Predicts polarities (when `previous_world_from_cam` is given), culls, registers from the
  // start pose and, when `assess`, judges the result (Assess); otherwise only the quality fields
  // that come from the registration are set and `good` is false.
  // With `prior`, its term joins the registration's cost (the motion prior of a tracking step).
  Attempt Solve(const Rigid3d& start_world_from_cam, const Rigid3d* previous_world_from_cam,
                bool assess = true, const PosePrior* prior = nullptr);
  // The motion prior of a tracking step at t_ns (TrackerOptions::motion_prior_*), when the
  // options ask for one and the smooth velocity spans its whole window since the last Reset;
  // nullopt otherwise.
  std::optional<PosePrior> MotionPrior(int64_t t_ns) const;
  // On-edge, chance and alignment figures of `attempt` at its estimate over the current
  // selection, the polarity check when its points had `predicted_polarity` (the per-point fields
  // of the last Solve), and `good`.
  void Assess(bool predicted_polarity, Attempt* attempt);
  bool IsGood(const TrackingQuality& quality) const;

  // Global search (INITIALIZING / RELOCALIZING; tracker_search.cc).
  // A starting pose of a round: the base viewpoint it perturbs and its pre-score.
  struct Hypothesis {
    Rigid3d world_from_cam;
    size_t viewpoint = 0;
    double prescore = 1;
    // After CoarseAlign: on-edge minus chance fraction of the pre-score points (higher is better).
    double coarse_score = -1;
  };
  // A refined hypothesis: the registered pose at its step and its quality.
  struct Refinement {
    Rigid3d world_from_cam;
    int64_t t_ns = 0;
    double alignment = 0;
    int points_used = 0;
    bool good = false;
    // Refined from a start around the round's winner (kProbe).
    bool probe = false;
    // Median depth of the points selected at its pose, metres (0 when it selected too few): the
    // scale of its place (relocalization_distinct_depth_fraction).
    double depth_m = 0;
    // Its poses since it was refined (FollowBestRefinement): the velocity that predicts the next.
    ConstantVelocityModel motion;
  };
  enum class SearchPhase { kStart, kPrescore, kCoarse, kRefine, kProbe, kVerify };
  // Starts a search episode in `status` (kInitializing or kRelocalizing) at t_ns.
  void BeginSearch(TrackingStatus status, int64_t t_ns);
  // One searching step at t_ns (the surfaces are up to date): fills `estimate`.
  void SearchStep(int64_t t_ns, PoseEstimate* estimate);
  // The work of a searching step outside verification: a round's start, pre-scores, alignments
  // or refinements, within the per-step counts of the options.
  void SearchWork(int64_t t_ns);
  // Tracks the best good refinement of the round in progress to t_ns (its motion model's
  // prediction, then Solve and Assess on this step's surfaces), so that the pose the round
  // accepts is of the step that judges it, not of the step that refined it: a round spans tens
  // of steps (hundreds of milliseconds of events in a live session with a CPU share), and a
  // pose 50 ms old no longer registers. A step that fails leaves it as it was (the first
  // verification step aligns it again). Nothing in a silence (SurfacesFull).
  void FollowBestRefinement(int64_t t_ns);
  // Adds a refinement to the round's, or when one of the same instant is the same place
  // (not Distinct) keeps the better of the two: the followed best refinement and a new one of
  // the same place are one candidate, not the ambiguity the judgement looks for (compared
  // later, after the camera moved on, they would look distinct).
  void AddRefinement(Refinement refinement);
  // The probes of a round's winner (relocalization_probe_depth_fraction): offsets in its camera
  // frame, at the median depth of the map points it sees, along which a pose may fit the events
  // nearly as well (a shift sideways turned back onto the scene, a shift along the optical
  // axis); empty when it sees too few points.
  std::vector<Rigid3d> ProbeOffsets(const Rigid3d& world_from_cam);
  // After the probes: a probe that ended distinct from the winner and better aligned replaces
  // it (the winner was a poorer optimum of the same neighbourhood), then the round is judged
  // again, the other probes among its refinements.
  bool JudgeProbedRound(Refinement* accepted);
  // The status and progress of a searching step, and the give-up of a long episode.
  void FinishSearchStep(int64_t t_ns, PoseEstimate* estimate);
  // Sets the decay time of the search's steps from the events themselves: the one that leaves
  // relocalization_active_fraction of the pixels active at t_ns, within [min_decay_time_s,
  // decay_time_s] (the velocity that sets the tracking decay is unknown while searching).
  void ChooseSearchDecay(int64_t t_ns);
  // Builds the chamfer fields (distance to the nearest active pixel) of this step; returns the
  // fraction of active pixels.
  double BuildChamferFields(int64_t t_ns);
  // Whether the surfaces hold one decay time of events at t_ns: since the first event, or since
  // the stream came back from a silence (events_since_t_ns_). The search work that reads the
  // live surfaces (a round's start, a refinement, a verification step) waits for it.
  bool SurfacesFull(int64_t t_ns) const;
  // The shortest gap between two events that empties the shortest-lived surfaces
  // (min_decay_time_s × ln(1 / empty threshold)): a search chooses its decay time from the
  // events (ChooseSearchDecay) and a verification step takes the tracking's, so a gap of 20 ms
  // can empty a step's surfaces.
  int64_t SilenceNs() const;
  // Starts the hypotheses of a new round: the source's viewpoints (and the last good pose when
  // relocalizing) once per episode, and the grid of offsets around them.
  void GenerateHypotheses();
  // Drops the round in progress and the episode's viewpoints (their pre-score points are indices
  // into the source's points): the next search step starts a round on the source's new point
  // set, asking it for viewpoints again (a site's tiles composed near a GNSS fix, say).
  void RestartSearchRound();
  // Pre-scores every hypothesis of one base viewpoint (its grid positions looking at its target,
  // each turned) and keeps the best relocalization_candidates of the round; returns how many
  // were scored.
  int PrescoreViewpoint(size_t viewpoint);
  // Samples the pre-score points of a base viewpoint (once per episode): up to
  // relocalization_prescore_points of the points visible from it.
  void SampleViewpointPoints(size_t viewpoint);
  // Median depth in the camera of the map points `indices` (not empty), metres.
  double MedianDepth(const std::vector<uint32_t>& indices, const Rigid3d& cam_from_world) const;
  // The chamfer pre-score of a hypothesis: mean truncated distance of its viewpoint's sample
  // points to the nearest active pixel, 0..1, lower is better.
  double Prescore(const Hypothesis& hypothesis) const;
  // Registers a hypothesis' pre-score points against the chamfer fields and scores the result
  // (Hypothesis::coarse_score); moves the hypothesis to the aligned pose.
  void CoarseAlign(Hypothesis* hypothesis);
  // The chamfer stages of a refinement: selects the points at the start pose, registers them on
  // the coarse then the fine chamfer field, and selects again where that ended when it moved;
  // nullopt when too few points are selected.
  std::optional<Rigid3d> ChamferStages(const Rigid3d& start_world_from_cam);
  // Coarse-to-fine registration from a hypothesis: chamfer fields, then Solve (unsigned) with
  // Assess.
  Refinement Refine(const Rigid3d& start_world_from_cam, int64_t t_ns);
  // Registers the current selection against `field` (no culling) from `start`.
  RegistrationResult RegisterSelection(PotentialField* field, const Rigid3d& start_world_from_cam);
  // True when two poses are farther apart than `distinct_m` (default relocalization_distinct_m)
  // or relocalization_distinct_deg.
  bool Distinct(const Rigid3d& a, const Rigid3d& b, double distinct_m = 0) const;
  // True when `other` is another place than `reference`: farther than relocalization_distinct_m
  // or relocalization_distinct_depth_fraction of reference's depth, or turned by more than
  // relocalization_distinct_deg. (Refinements of a round are of different instants; comparing
  // them at one instant through the followed one's motion changed nothing measured, at 5 and
  // 10 m/s on the car park, and is not done.)
  bool DistinctPlaces(const Refinement& other, const Refinement& reference) const;
  // The round's good refinement with the highest alignment (among the non-probes only when
  // `with_probes` is false); null when none is good.
  Refinement* BestRefinement(bool with_probes = true);
  // At a round's start: the image source's hypotheses for this step's image of the events,
  // distinct from each other, when a request is due (enough events integrated,
  // relocalization_image_interval_s since the last request); none otherwise.
  std::vector<Rigid3d> ImageHypotheses(int64_t t_ns);
  // Keeps the best distinct refinements of the round (relocalization_rivals) for the next one.
  void KeepRivals();
  // Judges the refinements of a finished round: true (and `accepted`) when the best is good and
  // clearly better than every distinct one: by relocalization_min_alignment_margin, and within
  // the neighbourhood of `probed_winner` (it and the probes, when the best is one of them) by
  // relocalization_probe_margin. `probed_winner`: the refinement the probes started around, if
  // it is still among the refinements.
  bool JudgeRound(Refinement* accepted, const Refinement* probed_winner = nullptr);
  bool InsideImage(const Eigen::Vector2d& pixel) const;
  bool NearEdge(const Eigen::Vector2d& pixel) const;
  PotentialField* Field(SurfaceChannel channel);

  // Set by the Map constructor only.
  std::unique_ptr<const MapSource> owned_source_;
  const MapSource* source_;
  // The source's points of generation source_generation_.
  MapPoints points_;
  uint64_t source_generation_ = 0;
  TrackerOptions options_;
  // The sensor's camera, the binning resolved for it (ResolveBinning: options_.binning, or the
  // automatic choice), and the ideal pinhole camera the surfaces live in. The undistortion table
  // itself is only needed to build the surface's sensor-to-pixel look-up: not kept (18 MB at
  // 1280x720).
  Camera sensor_camera_;
  int binning_;
  Camera ideal_camera_;
  PinholeIntrinsics intrinsics_;
  // The decay of the current step (options_.decay_time_s unless the decay is adaptive).
  SurfaceDecay decay_;
  PolarityPredictionOptions polarity_options_;
  TimeSurface surface_;
  EventFilter filter_;
  std::unique_ptr<TimeSurfaceField> lazy_fields_[3];
  DenseField dense_fields_[3];
  DenseField frame_field_;
  cv::Mat frame_distance_px_;
  // Active edge pixels (events) or Canny edges (frames) of the current step.
  NearestEdgeField edges_;
  // Active ON and OFF pixels, for polarity-aware occlusion culling.
  NearestEdgeField polarity_edges_[2];
  EdgeZBuffer zbuffer_;
  ConstantVelocityModel motion_;
  TrackingStatus status_ = TrackingStatus::kTracking;
  // The last good registered pose (the motion model's, the recovery's centre).
  Rigid3d last_good_world_from_cam_;
  // The points' residual variance at the last good registration (the motion prior's scale; see
  // PosePrior), the robust scale squared until one.
  double last_residual_variance_ = 0;
  // The last good pose as reported (stamped at its step time): what steps without an estimate
  // report.
  Rigid3d last_good_reported_world_from_cam_;
  // True once Reset or StartWithoutPose was called.
  bool started_ = false;
  // True once a pose was set or verified.
  bool has_pose_ = false;
  // True while the motion model's last pose is one given to Reset (at its own time) rather than
  // a registered one (which shows the camera when the events under its points fired).
  bool last_pose_given_ = false;
  // Consecutive LOST steps (reset by a good step).
  int lost_steps_ = 0;

  // Global search state.
  SearchPhase search_phase_ = SearchPhase::kStart;
  SearchProgress search_progress_;
  int64_t search_start_t_ns_ = 0;
  // The search's CPU budget (relocalization_cpu_share): CPU time it may still use, ns, as of the
  // step at search_credit_t_ns_.
  double search_credit_ns_ = 0;
  int64_t search_credit_t_ns_ = 0;
  // The verification: the accepted pose's median depth (Refinement::depth_m) and the time of the
  // window's first good step.
  double verify_depth_m_ = 0;
  int64_t verify_start_t_ns_ = 0;
  // With a CPU share a round starts only once the budget covers the CPU of the last whole round
  // of this session (0: none ended yet), and the budget may save up that much: a round then runs
  // on consecutive steps unless it costs more than the last one. (Spread over deferred steps, a
  // round's hypotheses, pre-scored and aligned on the fields of its first step, were refined on
  // events up to half a second newer, and failed.)
  double last_round_cpu_ns_ = 0;
  double round_cpu_ns_ = 0;  // The round in progress.
  // The decay time of the search's steps, nanoseconds (0: not chosen yet).
  double search_decay_ns_ = 0;
  std::optional<Eigen::Vector3d> search_center_;
  double search_radius_m_ = 0;
  // SetSearchHint's pose.
  std::optional<Rigid3d> search_hint_;
  // Base viewpoints of the episode (regenerated when empty) and their pre-score points.
  std::vector<Rigid3d> viewpoints_;
  // The search prior changed: the next round asks the source for viewpoints again.
  bool refresh_viewpoints_ = false;
  std::vector<std::vector<uint32_t>> viewpoint_points_;
  std::vector<uint8_t> viewpoint_sampled_;
  // Median depth of each viewpoint's sampled points, metres (its look-at distance).
  std::vector<double> viewpoint_depth_m_;
  std::vector<Eigen::Vector3d> grid_offsets_;
  size_t next_viewpoint_ = 0;
  size_t next_coarse_ = 0;
  std::vector<uint32_t> scratch_group_indices_;
  std::vector<int64_t> scratch_ages_;
  std::vector<Hypothesis> hypotheses_;
  size_t next_refinement_ = 0;
  std::vector<Refinement> refinements_;
  // The winner's probes (kProbe): start offsets in its camera frame, the next one to refine.
  std::vector<Rigid3d> probe_offsets_;
  size_t next_probe_ = 0;
  // The previous round's best distinct refinements, refined again first in the next round.
  std::vector<Hypothesis> rivals_;
  // Image hypotheses: the source (not owned), the image of the events and the event time of the
  // last request.
  const ImageHypothesisSource* image_source_ = nullptr;
  std::unique_ptr<EventImage> event_image_;
  std::optional<int64_t> last_image_request_t_ns_;
  cv::Mat chamfer_distance_px_;
  DenseField chamfer_coarse_;
  DenseField chamfer_fine_;
  int64_t step_t_ns_ = 0;

  // Selection state.
  std::vector<uint32_t> candidates_;
  std::vector<uint32_t> selected_;
  Rigid3d selection_world_from_cam_;
  int steps_since_selection_ = 0;
  bool has_selection_ = false;

  // Scheduling state.
  int64_t period_ns_ = 0;
  int64_t next_step_t_ns_ = 0;
  int64_t events_since_step_ = 0;
  std::optional<int64_t> last_event_t_ns_;
  // The first event ever given (the surfaces are full one decay time after it).
  std::optional<int64_t> first_event_t_ns_;
  // The first event after the last silence longer than the shortest-lived surfaces keep an
  // event (min_decay_time_s × ln(1 / empty threshold)), or the first event ever: a search round
  // needs one decay time of events since it, so that a stream that went dark (a blackout, a covered
  // lens) is searched on full surfaces again, not on the first milliseconds of its return.
  std::optional<int64_t> events_since_t_ns_;
  // The newest event in the surfaces. A step can run inside a silence before the events after
  // it arrive (AdvanceTo: the stream says nothing came until then), when events_since_t_ns_
  // does not know of it yet.
  std::optional<int64_t> last_inserted_t_ns_;
  // Every later event must be after this time (set by AdvanceTo).
  std::optional<int64_t> complete_until_t_ns_;
  int64_t last_step_t_ns_ = 0;

  // Per-step scratch.
  std::vector<Eigen::Vector2d> scratch_pixels_;
  std::vector<double> scratch_depths_;
  std::vector<uint8_t> scratch_keep_;
  std::vector<PotentialField*> scratch_fields_;
  std::vector<RegistrationPoint> scratch_points_;
  std::vector<size_t> scratch_group_;
  std::vector<Eigen::Vector2d> scratch_group_pixels_;
  std::vector<double> scratch_group_depths_;
  std::vector<uint8_t> scratch_group_keep_;
  std::vector<std::pair<int64_t, double>> scratch_age_samples_;
};

}  // namespace evloc::tracking
