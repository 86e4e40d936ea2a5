// Every parameter of the event tracker in one place (docs/tracking.md lists the defaults and the
// reasons for them). Fill the fields, then call Check().
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace evloc::tracking {

// Robust loss applied to the field residuals.
enum class RobustLoss {
  // Quadratic up to `robust_scale`, linear beyond.
  kHuber,
  // log(1 + (r/scale)^2): stronger down-weighting of outliers.
  kCauchy,
};

// How the time-surface potential field is evaluated at each step.
enum class FieldEvaluation {
  // Only where projected points land, memoised per step (O(points)); the default.
  kLazy,
  // Full-image rebuild of every needed channel per step (O(pixels)); for comparison.
  kDense,
};

// Which measurements drive the tracker.
enum class TrackerInput {
  // Events and time surfaces (Canny-EVT).
  kEvents,
  // Regular frames and distance transforms of their Canny edges (Canny-VT).
  kFrames,
};

// Options of the solver (Levenberg-Marquardt on SE(3), forward compositional).
struct RegistrationOptions {
  // Robust loss on the field residuals.
  RobustLoss loss = RobustLoss::kHuber;
  // Scale of the robust loss, on the 0..1 field scale.
  double robust_scale = 0.2;
  // Maximum number of linearisations (accepted or rejected LM trials) per solve.
  int max_iterations = 10;
  // Stop when the increment is below this (metres for translation, radians for rotation).
  double min_increment = 1e-6;
  // Also stop when an accepted trial lowered the cost, or a rejected trial's quadratic model
  // predicted to lower it, by less than this fraction of the cost (0 disables).
  double min_relative_decrease = 1e-4;
  // Initial LM damping, relative to the diagonal of the normal equations.
  double initial_damping = 1e-4;
  // Points projecting closer than this to the image border (pixels) are not used.
  double image_margin_px = 2.0;

  // Throws InvalidArgumentError when a field is out of range.
  void Check() const;
};

// Noise filters applied to the events before the time surfaces (event_filter.h; docs/tracking.md,
// "Noise filters").
struct EventFilterOptions {
  // Mask hot pixels: pixels whose event count in a window is far above the population's.
  bool hot_pixels = false;
  // Length of the counting windows, seconds; the first window is the learning period, whose
  // events are held back until it ends.
  double hot_pixel_window_s = 0.1;
  // A pixel is hot when its count in a window reaches this many times the median count of the
  // pixels that fired in it...
  double hot_pixel_rate_factor = 10.0;
  // ...and at least this rate, events per second.
  double hot_pixel_min_rate_hz = 100.0;
  // The learning period ends early once it holds this many events (bounds its memory: 13 bytes
  // per event).
  int64_t hot_pixel_learning_max_events = int64_t{1} << 20;
  // An event less than this after the last passed event of its pixel is removed, seconds; 0 off.
  double refractory_period_s = 0.0;
  // Background activity: an event passes only when one of its 8 neighbours had an event within
  // this window before it, seconds; 0 off.
  double background_activity_window_s = 0.0;
  // The background-activity filter also counts the pixel's own previous event as support.
  bool background_activity_include_self = false;

  // True when some filter is on.
  bool Enabled() const {
    return hot_pixels || refractory_period_s > 0 || background_activity_window_s > 0;
  }
  // Throws InvalidArgumentError when a field is out of range.
  void Check() const;
};

// Options of the event tracker (and of its frame-based twin).
struct TrackerOptions {
  // Measurements the tracker consumes.
  TrackerInput input = TrackerInput::kEvents;

  // --- Step scheduling ---
  // Tracking steps per second of event time (used when events_per_step is unset).
  double step_rate_hz = 300.0;
  // When set, a step runs after every this many events instead of at a fixed rate.
  std::optional<int64_t> events_per_step;

  // --- Noise filters, before the time surfaces ---
  // Hot pixels, refractory period, background activity (all in sensor pixels).
  EventFilterOptions event_filter;

  // --- Time surfaces ---
  // The surfaces' pixel: 1 = a sensor pixel; b > 1 = a block of b x b sensor pixels holding the
  // newest of their events (the ideal camera binned, UndistortionTable; docs/tracking.md,
  // "Binning"). Every pixel length of these options (radii, trails, margins) is then in binned
  // pixels. 2 makes a 1280x720 sensor track like a 640x360 one: the step no longer pays for the
  // HD image's cache misses. Events only (frames and odometry need 1). 0 = auto
  // (kAutoBinning): the smallest binning that fits the image in 640x480 (ResolveBinning), 1 for
  // frames.
  int binning = 1;
  // Decay time tau of T = exp(-(t - t_last) / tau), seconds. With decay_trail_px > 0, the
  // longest decay time.
  double decay_time_s = 0.03;
  // Adaptive decay: when > 0, each step's tau is this trail length (pixels) divided by the
  // median image speed of the selected points under the constant-velocity model, clamped to
  // [min_decay_time_s, decay_time_s]: short when the image moves fast (the whole image would
  // fire within a long tau), the full decay_time_s when it rests. 0 = a fixed tau.
  double decay_trail_px = 1.0;
  // The shortest adaptive decay time, seconds.
  double min_decay_time_s = 0.005;
  // Which quantile of the selected points' image speeds the adaptive decay divides the trail by,
  // in (0, 1]: 0.5 = the median. Forward motion (a vehicle) needs a high one: the points near
  // the focus of expansion barely move while the near ones, which fix the translation, sweep
  // the image; the median then gives the longest tau and their edges smear (docs/tracking.md,
  // "Vehicle speed").
  double decay_speed_quantile = 0.5;
  // Pixels with T <= this count as empty (field value 1) and as inactive for the ANNF.
  double empty_threshold = 0.1;
  // Smooth the field 1 - T with the 5x5 binomial (Gaussian) kernel.
  bool smooth_field = false;
  // Lazy (per projected point) or dense (full image) field evaluation.
  FieldEvaluation field_evaluation = FieldEvaluation::kLazy;

  // Stamp each pose at its step time: the surfaces show the edges where they were when their
  // newest events fired, a little before the step, so the registered pose is the camera's pose
  // at t - age (MeasureSurfaceAge). The tracker moves it forward by that age along the smoothed
  // constant-velocity motion (docs/tracking.md, "Pose time"). Off: the registered pose as is
  // (it lagged the ground truth by 1.5-8 ms on the simulated sequences and 5.5 ms on a real
  // one). Canny-DEVO keeps it off (CannyDevoOptions::DefaultTrackerOptions).
  bool stamp_at_step_time = true;
  // Measure each good step's surface age (TrackingQuality::surface_age_ms) also when the poses
  // are not stamped: a diagnostic, which evloc-track --stats turns on. Stamping measures it
  // anyway; otherwise it is skipped (it took 4 % of an evloc-track run at 640x480).
  bool measure_surface_age = false;
  // The window of the velocity that moves the pose forward, seconds (longer than
  // velocity_window_s: the extrapolation amplifies velocity noise more than the prior does).
  double stamp_velocity_window_s = 0.1;

  // --- Point selection ---
  // Maximum number of map points registered per step.
  int max_points = 2500;
  // With events (Canny-EVT), when > 0, register only this many of the max_points evenly selected
  // points: those that constrain the pose most (SelectInformative: a share taken evenly, the rest
  // by leverage; docs/tracking.md, "Point selection"). 0 (the default) = all of them. Measured
  // with 1000: on the slow, mid and fast 640x480 renders the median step 1.17-1.38 -> 0.51-0.62 ms
  // with the ATE within 5 % of all 2500 points'; but the car park at 10 m/s went from within
  // 10 cm to 109 cm and the motion prior at range no longer helped, so it is not the default.
  // Frames (Canny-VT) always register all of them (their ATE was 57 % worse with 1000).
  int informative_points = 0;
  // The share of informative_points taken evenly from the selection before the rest by leverage.
  double informative_seed_fraction = 0.5;
  // Side of the square image buckets used for even coverage, pixels.
  int bucket_size_px = 16;
  // Points closer than this to the camera are not selected, metres.
  double min_depth_m = 0.1;
  // Points farther than this are not selected, metres.
  double max_depth_m = 50.0;
  // Re-run the selection when the predicted pose moved more than this since the last
  // selection, metres.
  double reselect_translation_m = 0.05;
  // Same, for the rotation, degrees.
  double reselect_rotation_deg = 3.0;
  // Re-run the selection at least every this many steps.
  int reselect_every_steps = 10;
  // When the map source hands over a new point set (a tile change) while tracking, select the
  // points before building the step's surfaces, so that the adaptive decay time comes from their
  // image speeds; otherwise that step's surfaces use the longest decay time. Measured on the
  // tiled test scene (TiledTracking.CrossesTileBordersWithoutAJumpOrALostStep): ATE 0.677 ->
  // 0.626 cm (the whole map's 0.619), largest error change across a tile change 12.2 -> 9.6 mm.
  // Canny-DEVO, whose every reference frame is a new point set, keeps it off (mid 4 s at VGA:
  // ATE 0.544 -> 0.554 cm, RPE 0.528 -> 0.548 cm/s with it).
  bool select_first_on_new_points = true;

  // --- Motion prior ---
  // The constant velocity is measured between the newest estimate and the one at least this
  // long before it (seconds; 0 = the last two steps). Pose noise divided by one step period
  // swamps the velocity; the polarity prediction needs its direction.
  double velocity_window_s = 0.02;
  // The step's starting pose extrapolates a velocity that decays with this time constant
  // (seconds; ConstantVelocityModel, a first-order Gauss-Markov velocity); 0 = constant velocity,
  // the default everywhere. An experiment, not a default: along a direction the points do not
  // constrain (a wall of vertical stripes) a constant velocity re-measures its own error from
  // the poses it produced; a decay damps that, but on Canny-DEVO's 34 turning paths no time
  // constant from 5 to 33 ms lost fewer paths beyond 10 cm for certain (4-10 against 10;
  // docs/accuracy.md, "DEVO on turning paths"). With polarity it costs accuracy (the synthetic
  // scene's worst error 1.4 -> 2.9 cm at 25 ms): the polarities follow the predicted flow.
  double velocity_decay_time_s = 0.0;
  // The motion prior (docs/tracking.md, "Motion prior"): the last pose moved on by the smooth
  // velocity (measured over stamp_velocity_window_s) enters each tracking solve as a prior once
  // that velocity spans its whole window since the last Reset; recovery solves go without. The
  // velocity is trusted to this standard deviation, m/s, so the predicted position to this times
  // the step interval per axis. 0 = no translation prior (the default; vehicles: 2).
  double motion_prior_velocity_sigma_mps = 0.0;
  // The same for the angular velocity, degrees per second. 0 = no rotation prior.
  double motion_prior_angular_velocity_sigma_dps = 0.0;

  // --- Polarity-aware registration (signed time surfaces) ---
  // Register points against the ON or OFF surface of their predicted polarity.
  bool use_polarity = true;
  // Total width of the neutral band around 90 degrees between gradient and flow, degrees;
  // points inside it use the unsigned surface.
  double polarity_neutral_band_deg = 30.0;
  // Length of the 3D gradient probe P + s g used to project the gradient, as a fraction of the
  // point's depth.
  double gradient_probe_depth_fraction = 0.01;
  // Predicted flows shorter than this (pixels per step) give no polarity prediction.
  double min_flow_px = 0.05;
  // Solve with the unsigned surface from the prediction first, then with the signed surfaces
  // from that result (polarities predicted at it). Off: one signed solve from the prediction,
  // as the paper (cheaper, but a wrong flow at a turn of the motion misleads every point).
  bool polarity_after_unsigned_solve = true;

  // --- Occlusion culling (ANNF z-buffer) ---
  // Keep only the nearest point among those claiming one edge pixel; drop points far from edges.
  bool use_occlusion_culling = true;
  // Radius within which a point looks for its nearest active edge pixel, pixels.
  double annf_radius_px = 5.0;
  // With polarity too (EVT): a point with a confident polarity prediction looks for the nearest
  // pixel that fired with that polarity (the edge it registers against), not any active pixel.
  bool polarity_aware_culling = true;

  // --- Registration ---
  // Solver options.
  RegistrationOptions registration;

  // --- Tracking state ---
  // A step with fewer registered points than this is bad.
  int min_points = 50;
  // A step with a smaller fraction of points within on_edge_radius_px of an active edge pixel is
  // bad.
  double min_on_edge_fraction = 0.35;
  // Distance within which a projected point counts as on an edge, pixels.
  double on_edge_radius_px = 1.5;
  // A step whose chance-corrected alignment (TrackingQuality::alignment) is below this is bad.
  double min_alignment = 0.2;
  // A step whose mean field value at the points is above this is bad (1 disables the test: the
  // mean field value grows when the camera slows down and fewer pixels are fresh, so it cannot
  // tell a wrong pose from a slow one; min_alignment does).
  double max_mean_residual = 1.0;
  // On a bad step, retry from the last good pose and around it before declaring LOST.
  bool enable_recovery = true;
  // Translation of the recovery perturbations (along each camera axis, both signs), metres.
  double recovery_translation_m = 0.02;
  // Rotation of the recovery perturbations (about each camera axis, both signs), degrees.
  double recovery_rotation_deg = 2.0;

  // --- Relocalization (docs/relocalization.md, "Events") ---
  // After this many consecutive LOST steps (local recovery around the last good pose failed)
  // the tracker searches globally (RELOCALIZING); 0 never does.
  int lost_steps_before_relocalization = 30;
  // Base viewpoints sampled between two consecutive map keyframes (MapSource::
  // CandidateViewpoints), in addition to the keyframes themselves.
  int relocalization_samples_between_keyframes = 2;
  // Around each base viewpoint, positions on a cubic grid of this spacing within
  // relocalization_grid_radius_m are tried too, each looking at the point the base viewpoint
  // looks at (its median depth along its optical axis), metres.
  double relocalization_grid_step_m = 0.2;
  // Radius of that grid, metres (0: only the base viewpoints' own positions).
  double relocalization_grid_radius_m = 0.2;
  // Every position is also tried turned by this much about the camera x and y axes (both
  // signs), degrees (0: no turned copies).
  double relocalization_perturbation_deg = 8.0;
  // Map points projected per hypothesis by the pre-score (orientation-aware chamfer).
  int relocalization_prescore_points = 300;
  // Hypotheses pre-scored per step (bounds the work of a searching step); whole viewpoints are
  // scored (grid positions x 5 turns each), at least one per step.
  int relocalization_prescores_per_step = 400;
  // Hypotheses (the best pre-scores of a round) aligned on the chamfer field with their
  // pre-score points and scored against chance per round.
  int relocalization_coarse_candidates = 96;
  // Coarse alignments run per step.
  int relocalization_coarse_per_step = 24;
  // Hypotheses (the best coarse scores of a round) refined by full registration per round.
  int relocalization_candidates = 12;
  // The best distinct refinements of a round refined again in the next one (of the
  // relocalization_candidates), so that an ambiguity seen once stays in view.
  int relocalization_rivals = 3;
  // Refinements (coarse-to-fine registration and Assess) run per step.
  int relocalization_refinements_per_step = 2;
  // Truncation of the coarse chamfer field (distance to the nearest active pixel), pixels; the
  // refinement registers against it, then against a third of it, then the time surface.
  double relocalization_chamfer_truncation_px = 24.0;
  // A refined hypothesis is accepted only when its alignment exceeds that of the best distinct
  // refined hypothesis of the round by at least this much.
  double relocalization_min_alignment_margin = 0.15;
  // A round's winner is probed before its verification: refined again from six starts around
  // it, shifted by this fraction of the median depth of the points it sees sideways (turned
  // back onto the same point of the scene) and along its optical axis. A shift sideways with a
  // matching turn changes the image of a scene at one depth little: on the 640x480 room a
  // winner 8-11 cm and 2 degrees from the truth verified (alignment 0.49-0.60; the truth 0.69-
  // 0.73) and was tracked 8 cm off for 0.3 s. A probe that ends distinct and better aligned
  // replaces the winner, and the other probes are judged as any refinement (a neighbourhood of
  // similar fits fails the margin); docs/relocalization.md. 0: no probes.
  double relocalization_probe_depth_fraction = 0.03;
  // The winner must beat each of its probes that ended at another place by this much (and a
  // probe that won must beat the winner and the other probes by it); fits elsewhere are judged
  // with relocalization_min_alignment_margin. The probes ask whether the winner is the peak of
  // its own neighbourhood: along a flat valley (a wall of long bars) they end as well aligned as
  // the winner and the round is refused. The right pose's neighbourhood need not be steep: on the
  // rendered room at 240x180, turning back to the map, the probes around the right pose ended
  // 6-8 cm beside it 0.04-0.1 below, and the full margin refused three of the four right rounds
  // before one passed 0.8 s later (docs/accuracy.md, "Hand-over"). Above the step-to-step
  // spread of one pose's alignment (about 0.02).
  double relocalization_probe_margin = 0.05;
  // Two refined poses farther apart than this are distinct hypotheses, metres...
  double relocalization_distinct_m = 0.05;
  // ...or than this fraction of the median depth of the points the reference refinement sees,
  // when that is more. Registration at range pins a pose down only to a fraction of the depth
  // (most weakly along the optical axis): on the car park (median depth 30 m) the refinements of
  // one search round that had all converged on the truth lay 0.1-1 m apart, mostly along the
  // axis, so under a fixed 5 cm they were each other's rivals and every round was refused as
  // ambiguous (docs/relocalization.md, "Distinct at range"). 0: the metres alone.
  double relocalization_distinct_depth_fraction = 0.02;
  // Or rotated by more than this, degrees.
  double relocalization_distinct_deg = 3.0;
  // Consecutive good steps, tracked from the accepted hypothesis, before the status becomes
  // TRACKING (the first TRACKING pose is the last of them).
  int relocalization_verify_steps = 10;
  // And they must span at least this many seconds per metre of the accepted pose's median depth
  // (Refinement::depth_m). One instant of events fixes a pose along the optical axis only to a
  // few percent of the depth it sees; a camera moving along that axis (a vehicle) shows a pose
  // found that far behind it only once it has moved on by about as much, and a verification
  // from rest of a few steps passes it (docs/relocalization.md, "Verification at speed": at 10
  // m/s, a pose 0.9 m behind at 30 m verified in 10 steps and its alignment fell below 0.4
  // 20-35 steps later). 0.005: 30 ms (what 10 steps at 300 Hz span) at 6 m, 0.15 s at 30 m.
  // 0: the steps alone.
  double relocalization_verify_s_per_depth_m = 0.005;
  // Each verification step must also reach this chance-corrected alignment (above min_alignment:
  // a pose found from nothing needs a clearer fit than one tracked; a hypothesis refined into a
  // shifted-and-turned pose 5 cm from the truth verified at 0.22-0.29 where right ones verify at
  // 0.56-0.65, docs/relocalization.md).
  double relocalization_verify_min_alignment = 0.4;
  // While searching, each round's decay time leaves this fraction of the pixels active (the
  // newest events; within [min_decay_time_s, decay_time_s]): thin edges without a velocity.
  double relocalization_active_fraction = 0.1;
  // An episode that has searched this long without a verified pose ends as not found and a new
  // one starts at once (fresh viewpoints; reported by SearchProgress::gave_up), seconds; 0 never.
  double relocalization_give_up_s = 0.0;
  // Fraction of the image's pixels that must be active before a round starts (fewer events mean
  // too little to search on).
  double relocalization_min_active_fraction = 0.01;
  // Most CPU the search work of a searching tracker may use (the rounds: fields, pre-scores,
  // alignments, refinements; not the ingestion of events nor the verification steps), as a
  // fraction of one core per second of event time; 0: unbounded. A step over the budget does no
  // search work (SearchProgress::deferred) and the round goes on from the newest events at a later
  // step, so a live session whose search is slower than real time keeps up with its events
  // instead of queuing them. The budget is measured in the thread's CPU time, so with a share set
  // the steps that search depend on the machine (a run is no longer bit-reproducible). After the
  // first round, a round starts only once the budget covers the last round's CPU (the budget may
  // save up that much), so that it runs on consecutive steps and its hypotheses stay fresh.
  double relocalization_cpu_share = 0.0;
  // The most CPU time the budget saves up while the search is idle or cheap, seconds (a burst:
  // a round's first step builds its fields).
  double relocalization_cpu_burst_s = 0.05;
  // Image hypotheses (docs/relocalization.md, "Hypotheses from an image of the events"), used only
  // when the tracker has an ImageHypothesisSource: the time constant of the image of the events
  // (a leaky integrator of their polarities), seconds.
  double relocalization_image_tau_s = 0.05;
  // Events integrated before a round may ask for image hypotheses, seconds (from the start of the
  // episode).
  double relocalization_image_min_events_s = 0.15;
  // Event time between two requests for image hypotheses, seconds (each costs a feature
  // extraction and matching: hundreds of milliseconds of CPU at 640x480).
  double relocalization_image_interval_s = 0.25;
  // Standard deviation of the Gaussian blur of the image of the events before it is located,
  // pixels (0: none). Each pixel of the integrator counts its own events, so the image is
  // speckled, the more so the fewer the events (a client that thins while its session searches);
  // 0.7 px took the PnP inliers on the 640x480 far path's images from 814 to 1138 in all, and on
  // the same stream thinned to half from 179 to 304 (docs/relocalization.md).
  double relocalization_image_blur_px = 0.7;

  // --- Frame-based twin (Canny-VT) ---
  // Lower hysteresis threshold of cv::Canny on 8-bit frames.
  double canny_low_threshold = 50.0;
  // Upper hysteresis threshold of cv::Canny.
  double canny_high_threshold = 150.0;
  // Distance at which the normalised distance field saturates at 1, pixels.
  double distance_truncation_px = 10.0;

  // Throws InvalidArgumentError naming the first field out of range.
  void Check() const;

  // Sets the ablation switches from a variant name of docs/tracking.md ("Variants"): "EVT"
  // (polarity and occlusion), "EVT-PR" (polarity only), "EVT-OH" (occlusion only), "EVT--"
  // (neither). Throws InvalidArgumentError for any other name.
  void SetVariant(const std::string& name);
  // The variant name of the current switches.
  std::string VariantName() const;
};

// TrackerOptions::binning's "auto".
inline constexpr int kAutoBinning = 0;
// The largest image (width, height) "auto" binning tracks on, pixels.
inline constexpr int kAutoBinningMaxWidth = 640;
inline constexpr int kAutoBinningMaxHeight = 480;

// The binning a tracker of `options` uses on a `width` x `height` sensor: options.binning, or
// for auto the smallest B with ceil(width / B) <= 640 and ceil(height / B) <= 480 (at most 8; 1
// for frames): 1280x720 -> 2, 1920x1080 -> 3, 640x480 and smaller -> 1.
int ResolveBinning(const TrackerOptions& options, int width, int height);

// Sets options->binning from a command-line value of `flag`: "auto" or an integer (Check judges
// its range). Throws UsageError naming the flag for anything else.
void ParseBinningFlag(std::string_view flag, std::string_view value, TrackerOptions* options);

// Sets the two motion prior sigmas from a command-line value "V,W" (m/s, deg/s) of `flag`.
// Throws UsageError naming the flag for any other form (TrackerOptions::Check judges the values).
void ParseMotionPriorFlag(std::string_view flag, std::string_view value, TrackerOptions* options);

}  // namespace evloc::tracking
