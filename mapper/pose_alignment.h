// Sim(3) alignment of reconstructed camera poses to reference poses (`evloc-mapper build
// --align-to`, docs/mapper.md "Alignment"): camera centres and orientations together.
//
// Camera centres alone leave the rotation about the path poorly determined when the path is short
// or nearly straight (a 0.3 m video path: a 2 degree roll that fits the centres within 4 mm puts
// the map 7 cm off at 2 m). Every camera's orientation measures that rotation directly, so both
// are fitted: minimise
//   sum_i |s R c_i + t - c'_i|^2 + w sum_i |R R_i - R'_i|_F^2
// (c_i, R_i: model centre and world_from_cam rotation; c'_i, R'_i: the reference's). For a fixed s
// the optimal R is the orthogonal polar factor of s sum b_i a_i^T + w sum R'_i R_i^T (a, b: centred
// centres), for a fixed R, s = sum b_i . R a_i / sum |a_i|^2; the two alternate to convergence.
// The weight is the ratio of the two residual variances, w = var(centre residual) / var(rotation
// residual), re-estimated from the residuals of the previous fit (starting from the rotation of
// the orientations alone), i.e. each term is weighted by how well it is actually measured.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "core/geometry/rigid3.h"

namespace evloc::mapper {

// Options of AlignPoses.
struct PoseAlignmentOptions {
  // Re-estimations of the weight w from the residuals.
  int weight_iterations = 3;
  // Alternations of rotation and scale per weight.
  int max_iterations = 50;
  // Floors of the residual variances (metres^2, radians^2): a perfect fit of one term does not
  // give it an infinite weight.
  double min_centre_variance_m2 = 1e-12;
  double min_rotation_variance_rad2 = 1e-12;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// The alignment and its residuals.
struct PoseAlignment {
  // reference_from_model: maps model points and poses into the reference frame.
  Sim3d reference_from_model;
  // Poses used.
  size_t num_poses = 0;
  // RMS and largest distance between aligned and reference camera centres, reference units.
  double centre_rms = 0.0;
  double centre_max = 0.0;
  // RMS and largest angle between aligned and reference orientations, degrees.
  double rotation_rms_deg = 0.0;
  double rotation_max_deg = 0.0;
  // The final weight w (reference units squared).
  double orientation_weight = 0.0;
  // RMS distance of the reference camera centres from their mean (the size of the reference
  // camera path), reference units: the scale of AlignmentLimits::max_centre_rms_fraction.
  double reference_spread = 0.0;
};

// Residuals beyond which an alignment means that the model and the reference disagree (a wrong
// COLMAP model, or reference poses of other images): `evloc-mapper build --align-to` refuses the
// map (docs/mapper.md "Alignment check"). A correct model leaves its COLMAP pose noise, a few
// percent of the camera path at most (centre RMS / spread: the circling room 0.5 %,
// templeSparseRing 0.15 %, 12 frames of a 2 s room path 3.3 %); a model that cannot be brought
// onto the reference leaves residuals comparable to the path itself (a Sim(3) shrunk to a point
// leaves exactly the spread, ratio 1).
struct AlignmentLimits {
  // Largest RMS camera-centre residual as a fraction of PoseAlignment::reference_spread.
  double max_centre_rms_fraction = 0.1;
  // Largest RMS camera-orientation residual, degrees.
  double max_rotation_rms_deg = 5.0;

  // Throws InvalidArgumentError on a bad value (not positive, or NaN).
  void Check() const;
};

// What is wrong with `alignment` under `limits` (the residuals, the limits and the likely
// causes), or std::nullopt when it is within them.
std::optional<std::string> AlignmentLimitViolation(const PoseAlignment& alignment,
                                                   const AlignmentLimits& limits);

// Aligns `model` world_from_cam poses to the `reference` ones (same order and size). Throws
// InvalidArgumentError when the sizes differ, fewer than 3 poses are given, a value is not finite,
// or the model centres coincide (the scale is not determined).
PoseAlignment AlignPoses(const std::vector<Rigid3d>& model, const std::vector<Rigid3d>& reference,
                         const PoseAlignmentOptions& options = {});

}  // namespace evloc::mapper
