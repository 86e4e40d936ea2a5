#include "localizer/tracking/tracker_options.h"

#include <cmath>
#include <string>
#include <tuple>

#include "core/common/cli.h"
#include "core/common/error.h"

namespace evloc::tracking {
namespace {

void Require(bool condition, const std::string& what) {
  if (!condition) throw InvalidArgumentError("TrackerOptions: " + what);
}

bool Positive(double value) { return std::isfinite(value) && value > 0; }

}  // namespace

void RegistrationOptions::Check() const {
  Require(Positive(robust_scale), "registration.robust_scale must be positive and finite.");
  Require(max_iterations >= 1, "registration.max_iterations must be at least 1.");
  Require(std::isfinite(min_increment) && min_increment >= 0,
          "registration.min_increment must be finite and >= 0.");
  Require(std::isfinite(min_relative_decrease) && min_relative_decrease >= 0 &&
              min_relative_decrease < 1,
          "registration.min_relative_decrease must be in [0, 1).");
  Require(Positive(initial_damping), "registration.initial_damping must be positive.");
  Require(std::isfinite(image_margin_px) && image_margin_px >= 0,
          "registration.image_margin_px must be finite and >= 0.");
}

void EventFilterOptions::Check() const {
  Require(
      std::isfinite(hot_pixel_window_s) && hot_pixel_window_s >= 1e-3 && hot_pixel_window_s <= 10,
      "event_filter.hot_pixel_window_s must be in [0.001, 10] seconds.");
  Require(std::isfinite(hot_pixel_rate_factor) && hot_pixel_rate_factor > 1,
          "event_filter.hot_pixel_rate_factor must be finite and > 1.");
  Require(Positive(hot_pixel_min_rate_hz) && hot_pixel_min_rate_hz <= 1e7,
          "event_filter.hot_pixel_min_rate_hz must be in (0, 1e7] events per second.");
  Require(hot_pixel_learning_max_events >= 1 && hot_pixel_learning_max_events <= (int64_t{1} << 28),
          "event_filter.hot_pixel_learning_max_events must be in [1, 2^28].");
  Require(
      std::isfinite(refractory_period_s) && refractory_period_s >= 0 && refractory_period_s <= 1,
      "event_filter.refractory_period_s must be in [0, 1] seconds (0: off).");
  Require(std::isfinite(background_activity_window_s) && background_activity_window_s >= 0 &&
              background_activity_window_s <= 1,
          "event_filter.background_activity_window_s must be in [0, 1] seconds (0: off).");
}

void TrackerOptions::Check() const {
  event_filter.Check();
  Require(Positive(step_rate_hz) && step_rate_hz <= 1e6, "step_rate_hz must be in (0, 1e6].");
  Require(std::isfinite(decay_trail_px) && decay_trail_px >= 0,
          "decay_trail_px must be finite and >= 0 (0 = a fixed decay time).");
  Require(Positive(min_decay_time_s) && min_decay_time_s <= decay_time_s,
          "min_decay_time_s must be positive and at most decay_time_s.");
  Require(decay_speed_quantile > 0 && decay_speed_quantile <= 1,
          "decay_speed_quantile must lie within (0, 1] (0.5: the median image speed).");
  Require(!events_per_step || *events_per_step >= 1, "events_per_step must be at least 1.");
  Require(Positive(decay_time_s), "decay_time_s must be positive.");
  Require(binning >= kAutoBinning && binning <= 8, "binning must be 0 (auto) or 1 (none) to 8.");
  Require(binning <= 1 || input == TrackerInput::kEvents,
          "binning needs events: frames (Canny-VT) are tracked at the sensor's resolution.");
  Require(std::isfinite(empty_threshold) && empty_threshold > 0 && empty_threshold < 1,
          "empty_threshold must be in (0, 1).");
  Require(max_points >= 6, "max_points must be at least 6.");
  Require(informative_points == 0 || informative_points >= 6,
          "informative_points must be 0 (off) or at least 6.");
  Require(informative_seed_fraction > 0 && informative_seed_fraction <= 1,
          "informative_seed_fraction must be in (0, 1].");
  Require(bucket_size_px >= 1, "bucket_size_px must be at least 1.");
  Require(Positive(min_depth_m) && Positive(max_depth_m) && min_depth_m < max_depth_m,
          "min_depth_m and max_depth_m must be positive with min_depth_m < max_depth_m.");
  Require(std::isfinite(reselect_translation_m) && reselect_translation_m >= 0,
          "reselect_translation_m must be finite and >= 0.");
  Require(std::isfinite(reselect_rotation_deg) && reselect_rotation_deg >= 0,
          "reselect_rotation_deg must be finite and >= 0.");
  Require(reselect_every_steps >= 1, "reselect_every_steps must be at least 1.");
  Require(std::isfinite(polarity_neutral_band_deg) && polarity_neutral_band_deg >= 0 &&
              polarity_neutral_band_deg < 180,
          "polarity_neutral_band_deg must be in [0, 180).");
  Require(Positive(gradient_probe_depth_fraction) && gradient_probe_depth_fraction < 1,
          "gradient_probe_depth_fraction must be in (0, 1).");
  Require(std::isfinite(min_flow_px) && min_flow_px >= 0, "min_flow_px must be >= 0.");
  Require(Positive(annf_radius_px) && annf_radius_px <= 32,
          "annf_radius_px must be in (0, 32] (the search window is (2r+1)^2 pixels).");
  registration.Check();
  Require(min_points >= 6, "min_points must be at least 6 (six pose parameters).");
  Require(
      std::isfinite(min_on_edge_fraction) && min_on_edge_fraction >= 0 && min_on_edge_fraction <= 1,
      "min_on_edge_fraction must be in [0, 1].");
  Require(std::isfinite(on_edge_radius_px) && on_edge_radius_px >= 0 && on_edge_radius_px <= 10,
          "on_edge_radius_px must be in [0, 10].");
  Require(std::isfinite(velocity_window_s) && velocity_window_s >= 0 && velocity_window_s <= 1,
          "velocity_window_s must be in [0, 1] seconds.");
  Require(std::isfinite(velocity_decay_time_s) && velocity_decay_time_s >= 0 &&
              velocity_decay_time_s <= 10,
          "velocity_decay_time_s must be in [0, 10] seconds (0 = constant velocity).");
  Require(std::isfinite(motion_prior_velocity_sigma_mps) && motion_prior_velocity_sigma_mps >= 0,
          "motion_prior_velocity_sigma_mps must be finite and >= 0 (0 = no prior).");
  Require(std::isfinite(motion_prior_angular_velocity_sigma_dps) &&
              motion_prior_angular_velocity_sigma_dps >= 0,
          "motion_prior_angular_velocity_sigma_dps must be finite and >= 0 (0 = no prior).");
  Require(std::isfinite(stamp_velocity_window_s) && stamp_velocity_window_s >= 0 &&
              stamp_velocity_window_s <= 1,
          "stamp_velocity_window_s must be in [0, 1] seconds.");
  Require(std::isfinite(min_alignment) && min_alignment >= -1 && min_alignment <= 1,
          "min_alignment must be in [-1, 1].");
  Require(std::isfinite(max_mean_residual) && max_mean_residual > 0,
          "max_mean_residual must be positive.");
  Require(std::isfinite(recovery_translation_m) && recovery_translation_m >= 0,
          "recovery_translation_m must be finite and >= 0.");
  Require(std::isfinite(recovery_rotation_deg) && recovery_rotation_deg >= 0,
          "recovery_rotation_deg must be finite and >= 0.");
  Require(lost_steps_before_relocalization >= 0, "lost_steps_before_relocalization must be >= 0.");
  Require(relocalization_samples_between_keyframes >= 0 &&
              relocalization_samples_between_keyframes <= 100,
          "relocalization_samples_between_keyframes must be in [0, 100].");
  Require(Positive(relocalization_grid_step_m), "relocalization_grid_step_m must be positive.");
  Require(std::isfinite(relocalization_grid_radius_m) && relocalization_grid_radius_m >= 0 &&
              relocalization_grid_radius_m <= 100 * relocalization_grid_step_m,
          "relocalization_grid_radius_m must be in [0, 100 grid steps].");
  Require(std::isfinite(relocalization_perturbation_deg) && relocalization_perturbation_deg >= 0 &&
              relocalization_perturbation_deg < 90,
          "relocalization_perturbation_deg must be in [0, 90).");
  Require(relocalization_prescore_points >= 10, "relocalization_prescore_points must be >= 10.");
  Require(relocalization_prescores_per_step >= 1,
          "relocalization_prescores_per_step must be at least 1.");
  Require(relocalization_candidates >= 1, "relocalization_candidates must be at least 1.");
  Require(relocalization_coarse_candidates >= relocalization_candidates,
          "relocalization_coarse_candidates must be at least relocalization_candidates.");
  Require(relocalization_rivals >= 0 && relocalization_rivals < relocalization_candidates,
          "relocalization_rivals must be in [0, relocalization_candidates).");
  Require(relocalization_coarse_per_step >= 1,
          "relocalization_coarse_per_step must be at least 1.");
  Require(relocalization_refinements_per_step >= 1,
          "relocalization_refinements_per_step must be at least 1.");
  Require(
      Positive(relocalization_chamfer_truncation_px) && relocalization_chamfer_truncation_px <= 200,
      "relocalization_chamfer_truncation_px must be in (0, 200].");
  Require(std::isfinite(relocalization_min_alignment_margin) &&
              relocalization_min_alignment_margin >= 0 && relocalization_min_alignment_margin <= 1,
          "relocalization_min_alignment_margin must be in [0, 1].");
  Require(Positive(relocalization_distinct_m), "relocalization_distinct_m must be positive.");
  Require(Positive(relocalization_distinct_deg), "relocalization_distinct_deg must be positive.");
  Require(std::isfinite(relocalization_distinct_depth_fraction) &&
              relocalization_distinct_depth_fraction >= 0 &&
              relocalization_distinct_depth_fraction <= 0.5,
          "relocalization_distinct_depth_fraction must be in [0, 0.5].");
  Require(relocalization_verify_steps >= 1, "relocalization_verify_steps must be at least 1.");
  Require(std::isfinite(relocalization_verify_s_per_depth_m) &&
              relocalization_verify_s_per_depth_m >= 0 && relocalization_verify_s_per_depth_m <= 1,
          "relocalization_verify_s_per_depth_m must be in [0, 1].");
  Require(std::isfinite(relocalization_verify_min_alignment) &&
              relocalization_verify_min_alignment >= 0 && relocalization_verify_min_alignment <= 1,
          "relocalization_verify_min_alignment must be in [0, 1].");
  Require(std::isfinite(relocalization_active_fraction) && relocalization_active_fraction > 0 &&
              relocalization_active_fraction <= 1,
          "relocalization_active_fraction must be in (0, 1].");
  Require(std::isfinite(relocalization_give_up_s) && relocalization_give_up_s >= 0,
          "relocalization_give_up_s must be finite and >= 0 (0 = never).");
  Require(std::isfinite(relocalization_cpu_share) && relocalization_cpu_share >= 0 &&
              relocalization_cpu_share <= 1,
          "relocalization_cpu_share must be in [0, 1] (0 = unbounded).");
  Require(Positive(relocalization_cpu_burst_s) && relocalization_cpu_burst_s <= 10,
          "relocalization_cpu_burst_s must be in (0, 10].");
  Require(Positive(relocalization_image_tau_s) && relocalization_image_tau_s <= 10,
          "relocalization_image_tau_s must be in (0, 10].");
  Require(std::isfinite(relocalization_image_min_events_s) &&
              relocalization_image_min_events_s >= 0 && relocalization_image_min_events_s <= 60,
          "relocalization_image_min_events_s must be in [0, 60].");
  Require(std::isfinite(relocalization_image_interval_s) && relocalization_image_interval_s >= 0 &&
              relocalization_image_interval_s <= 3600,
          "relocalization_image_interval_s must be in [0, 3600].");
  Require(std::isfinite(relocalization_probe_depth_fraction) &&
              relocalization_probe_depth_fraction >= 0 &&
              relocalization_probe_depth_fraction <= 0.5,
          "relocalization_probe_depth_fraction must be in [0, 0.5].");
  Require(std::isfinite(relocalization_probe_margin) && relocalization_probe_margin >= 0 &&
              relocalization_probe_margin <= 1,
          "relocalization_probe_margin must be in [0, 1].");
  Require(std::isfinite(relocalization_image_blur_px) && relocalization_image_blur_px >= 0 &&
              relocalization_image_blur_px <= 10,
          "relocalization_image_blur_px must be in [0, 10].");
  Require(std::isfinite(relocalization_min_active_fraction) &&
              relocalization_min_active_fraction >= 0 && relocalization_min_active_fraction < 1,
          "relocalization_min_active_fraction must be in [0, 1).");
  Require(std::isfinite(canny_low_threshold) && canny_low_threshold >= 0 &&
              canny_low_threshold <= canny_high_threshold,
          "canny thresholds must satisfy 0 <= canny_low_threshold <= canny_high_threshold.");
  Require(Positive(distance_truncation_px), "distance_truncation_px must be positive.");
}

void TrackerOptions::SetVariant(const std::string& name) {
  if (name == "EVT") {
    use_polarity = true;
    use_occlusion_culling = true;
  } else if (name == "EVT-PR") {
    use_polarity = true;
    use_occlusion_culling = false;
  } else if (name == "EVT-OH") {
    use_polarity = false;
    use_occlusion_culling = true;
  } else if (name == "EVT--") {
    use_polarity = false;
    use_occlusion_culling = false;
  } else {
    throw InvalidArgumentError("Unknown tracker variant '" + name +
                               "': expected EVT, EVT-PR, EVT-OH or EVT--.");
  }
}

std::string TrackerOptions::VariantName() const {
  if (use_polarity && use_occlusion_culling) return "EVT";
  if (use_polarity) return "EVT-PR";
  if (use_occlusion_culling) return "EVT-OH";
  return "EVT--";
}

int ResolveBinning(const TrackerOptions& options, int width, int height) {
  if (options.binning != kAutoBinning) return options.binning;
  if (options.input != TrackerInput::kEvents) return 1;
  int binning = 1;
  while (binning < 8 && ((width + binning - 1) / binning > kAutoBinningMaxWidth ||
                         (height + binning - 1) / binning > kAutoBinningMaxHeight)) {
    ++binning;
  }
  return binning;
}

void ParseBinningFlag(std::string_view flag, std::string_view value, TrackerOptions* options) {
  options->binning =
      value == "auto" ? kAutoBinning : static_cast<int>(ParseIntegerFlag(flag, value));
}

void ParseMotionPriorFlag(std::string_view flag, std::string_view value, TrackerOptions* options) {
  std::tie(options->motion_prior_velocity_sigma_mps,
           options->motion_prior_angular_velocity_sigma_dps) = ParseDoublePairFlag(flag, value);
}

}  // namespace evloc::tracking
