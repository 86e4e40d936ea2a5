#include "core/geo/geo_alignment.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <random>
#include <sstream>

#include "core/common/error.h"

namespace evloc {
namespace {

// The ECEF mean of the points, as a WGS84 point.
GeodeticPoint Centroid(const std::vector<GeoCorrespondence>& correspondences,
                       const std::vector<bool>& use) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  size_t count = 0;
  for (size_t i = 0; i < correspondences.size(); ++i) {
    if (!use[i]) continue;
    sum += EcefFromGeodetic(correspondences[i].geodetic);
    ++count;
  }
  return GeodeticFromEcef(sum / static_cast<double>(count));
}

Rigid3d ToRigid(const Sim3d& sim) { return Rigid3d(sim.rotation, sim.translation); }

// The columns of `points` whose `use` entry is true.
Eigen::Matrix3Xd Select(const Eigen::Matrix3Xd& points, const std::vector<bool>& use) {
  Eigen::Matrix3Xd out(3, std::count(use.begin(), use.end(), true));
  Eigen::Index column = 0;
  for (size_t i = 0; i < use.size(); ++i) {
    if (use[i]) out.col(column++) = points.col(static_cast<Eigen::Index>(i));
  }
  return out;
}

}  // namespace

void GeoAlignmentOptions::Check() const {
  if (!std::isfinite(inlier_threshold_m) || inlier_threshold_m <= 0.0) {
    throw InvalidArgumentError("geo alignment: inlier threshold must be a finite value > 0 m");
  }
  if (ransac_iterations < 1) {
    throw InvalidArgumentError("geo alignment: RANSAC iterations must be >= 1");
  }
  if (min_inliers < 3) throw InvalidArgumentError("geo alignment: min_inliers must be >= 3");
  if (!std::isfinite(max_scale_deviation) || max_scale_deviation < 0.0) {
    throw InvalidArgumentError("geo alignment: max_scale_deviation must be a finite value >= 0");
  }
  if (!(max_rotation_sigma_rad > 0.0)) {
    throw InvalidArgumentError("geo alignment: max_rotation_sigma_rad must be > 0");
  }
}

GeoAlignment AlignMapToGeodetic(const std::vector<GeoCorrespondence>& correspondences,
                                const GeoAlignmentOptions& options, const std::string& source) {
  options.Check();
  const size_t count = correspondences.size();
  if (count < 3) {
    throw InvalidArgumentError("geo alignment needs at least 3 points with a WGS84 position, got " +
                               std::to_string(count));
  }
  for (const GeoCorrespondence& correspondence : correspondences) {
    CheckGeodeticPoint(correspondence.geodetic, correspondence.label);
    if (!correspondence.p_map.allFinite()) {
      throw InvalidArgumentError(correspondence.label + ": map point is not finite");
    }
  }
  // ENU frame at the centroid of all points (recentred on the inliers at the end).
  const std::vector<bool> all(count, true);
  EnuFrame frame(Centroid(correspondences, all));
  Eigen::Matrix3Xd map_points(3, count), enu_points(3, count);
  for (size_t i = 0; i < count; ++i) {
    map_points.col(static_cast<Eigen::Index>(i)) = correspondences[i].p_map;
    enu_points.col(static_cast<Eigen::Index>(i)) = frame.FromGeodetic(correspondences[i].geodetic);
  }
  const double threshold_squared = options.inlier_threshold_m * options.inlier_threshold_m;
  const auto inliers_of = [&](const Rigid3d& enu_from_map, double* score) {
    std::vector<bool> inliers(count);
    double cost = 0.0;
    for (size_t i = 0; i < count; ++i) {
      const auto column = static_cast<Eigen::Index>(i);
      const double squared =
          (enu_points.col(column) - enu_from_map * Eigen::Vector3d(map_points.col(column)))
              .squaredNorm();
      inliers[i] = squared <= threshold_squared;
      cost += std::min(squared, threshold_squared);  // MSAC
    }
    if (score) *score = cost;
    return inliers;
  };

  // RANSAC over minimal samples of 3; every triple when there are few points.
  std::mt19937_64 random(options.seed);
  std::uniform_int_distribution<size_t> pick(0, count - 1);
  double best_cost = std::numeric_limits<double>::infinity();
  std::vector<bool> best_inliers;
  const auto try_sample = [&](size_t a, size_t b, size_t c) {
    if (a == b || b == c || a == c) return;
    Eigen::Matrix3Xd source_points(3, 3), target_points(3, 3);
    size_t k = 0;
    for (size_t index : {a, b, c}) {
      source_points.col(static_cast<Eigen::Index>(k)) =
          map_points.col(static_cast<Eigen::Index>(index));
      target_points.col(static_cast<Eigen::Index>(k)) =
          enu_points.col(static_cast<Eigen::Index>(index));
      ++k;
    }
    Rigid3d model;
    try {
      model = ToRigid(AlignUmeyama(source_points, target_points, /*with_scale=*/false));
    } catch (const InvalidArgumentError&) {
      return;  // collinear sample
    }
    double cost = 0.0;
    std::vector<bool> inliers = inliers_of(model, &cost);
    if (cost < best_cost) {
      best_cost = cost;
      best_inliers = std::move(inliers);
    }
  };
  const size_t triples = count * (count - 1) * (count - 2) / 6;
  if (triples <= static_cast<size_t>(options.ransac_iterations)) {
    for (size_t a = 0; a < count; ++a) {
      for (size_t b = a + 1; b < count; ++b) {
        for (size_t c = b + 1; c < count; ++c) try_sample(a, b, c);
      }
    }
  } else {
    for (int iteration = 0; iteration < options.ransac_iterations; ++iteration) {
      try_sample(pick(random), pick(random), pick(random));
    }
  }
  if (best_inliers.empty()) {
    throw InvalidArgumentError(
        "geo alignment: the " + std::to_string(count) +
        " points are collinear (a straight path or one survey line); the rotation about that line "
        "is not determined: add points off the line");
  }
  // Refit on the inliers until they stop changing (a few rounds at most).
  std::vector<bool> inliers = best_inliers;
  Rigid3d enu_from_map;
  for (int round = 0; round < 5; ++round) {
    if (static_cast<size_t>(std::count(inliers.begin(), inliers.end(), true)) <
        std::max<size_t>(options.min_inliers, 3)) {
      break;
    }
    try {
      enu_from_map =
          ToRigid(AlignUmeyama(Select(map_points, inliers), Select(enu_points, inliers), false));
    } catch (const InvalidArgumentError&) {
      throw InvalidArgumentError(
          "geo alignment: the points that agree with each other are collinear; add points off "
          "their line");
    }
    std::vector<bool> next = inliers_of(enu_from_map, nullptr);
    if (next == inliers) break;
    inliers = std::move(next);
  }
  const size_t num_inliers = static_cast<size_t>(std::count(inliers.begin(), inliers.end(), true));
  if (num_inliers < options.min_inliers) {
    throw InvalidArgumentError(
        "geo alignment: only " + std::to_string(num_inliers) + " of " + std::to_string(count) +
        " points agree within " + std::to_string(options.inlier_threshold_m) + " m (at least " +
        std::to_string(options.min_inliers) +
        " needed); check that the WGS84 positions belong to these points, or raise the threshold");
  }
  const Sim3d similarity =
      AlignUmeyama(Select(map_points, inliers), Select(enu_points, inliers), true);

  // The anchor: ENU origin at the inliers' centroid; enu_from_map re-expressed in it.
  GeoAlignment result;
  const GeodeticPoint origin = Centroid(correspondences, inliers);
  const EnuFrame anchor_frame(origin);
  // A rigid map from the first frame to the anchor frame, exact for the ENU frames' relation
  // (both are rotations and translations of ECEF).
  const Eigen::Matrix3d anchor_from_first =
      EcefFromEnuRotation(origin).transpose() * EcefFromEnuRotation(frame.origin());
  const Eigen::Vector3d first_origin_in_anchor = anchor_frame.FromGeodetic(frame.origin());
  const Rigid3d anchor_from_first_frame(Eigen::Quaterniond(anchor_from_first),
                                        first_origin_in_anchor);
  result.anchor.origin = origin;
  result.anchor.enu_from_map = anchor_from_first_frame * enu_from_map;
  result.anchor.source = source;
  result.scale = similarity.scale;
  result.inliers = inliers;
  result.num_inliers = num_inliers;
  std::vector<double> norms;
  double sum_squared = 0.0, sum_horizontal = 0.0, sum_vertical = 0.0;
  for (size_t i = 0; i < count; ++i) {
    const Eigen::Vector3d residual = anchor_frame.FromGeodetic(correspondences[i].geodetic) -
                                     result.anchor.enu_from_map * correspondences[i].p_map;
    result.residuals_enu.push_back(residual);
    if (!inliers[i]) continue;
    norms.push_back(residual.norm());
    sum_squared += residual.squaredNorm();
    sum_horizontal += residual.head<2>().squaredNorm();
    sum_vertical += residual.z() * residual.z();
  }
  const double n = static_cast<double>(num_inliers);
  result.rms_m = std::sqrt(sum_squared / n);
  result.horizontal_rms_m = std::sqrt(sum_horizontal / n);
  result.vertical_rms_m = std::sqrt(sum_vertical / n);
  std::sort(norms.begin(), norms.end());
  result.median_m = norms.size() % 2
                        ? norms[norms.size() / 2]
                        : 0.5 * (norms[norms.size() / 2 - 1] + norms[norms.size() / 2]);
  result.max_m = norms.back();
  // Standard error at the centroid: the residual spread (corrected for the 6 fitted parameters)
  // over sqrt(n). With n = 3 the fit is exact and nothing is known of the noise: sigma 0.
  const double dof_correction = 3.0 * n > 6.0 ? std::sqrt(3.0 * n / (3.0 * n - 6.0)) : 0.0;
  result.anchor.horizontal_sigma_m = result.horizontal_rms_m * dof_correction / std::sqrt(n);
  result.anchor.vertical_sigma_m = result.vertical_rms_m * dof_correction / std::sqrt(n);
  // The scale's standard error: the per-axis residual spread over sqrt(n) x the map points' RMS
  // distance from their centroid.
  const Eigen::Matrix3Xd inlier_map_points = Select(map_points, inliers);
  const double spread = std::sqrt((inlier_map_points.colwise() - inlier_map_points.rowwise().mean())
                                      .colwise()
                                      .squaredNorm()
                                      .mean());
  result.scale_sigma = spread > 0.0 ? result.rms_m / std::sqrt(3.0 * n) / spread : 0.0;
  result.rotation_sigma_rad = result.scale_sigma;
  const double scale_deviation = std::abs(result.scale - 1.0);
  if (scale_deviation > options.max_scale_deviation && scale_deviation > 4.0 * result.scale_sigma) {
    throw InvalidArgumentError(
        "geo alignment: the map's scale differs from the WGS84 points' by a factor " +
        std::to_string(result.scale) + " (at most 1 +- " +
        std::to_string(options.max_scale_deviation) +
        ", or 4 standard errors: " + std::to_string(4.0 * result.scale_sigma) +
        "); the map is not metric (COLMAP without reference positions?) or the points are wrong");
  }
  if (result.rotation_sigma_rad > options.max_rotation_sigma_rad) {
    throw InvalidArgumentError(
        "geo alignment: the points' residuals (" + std::to_string(result.rms_m) +
        " m RMS) are too large for their spread (" + std::to_string(spread) +
        " m RMS from their centroid) to orient the map (rotation standard error " +
        std::to_string(result.rotation_sigma_rad) + " rad, at most " +
        std::to_string(options.max_rotation_sigma_rad) +
        "); give the anchor (--geo-anchor with a heading) or points farther apart");
  }
  result.anchor.Check();
  return result;
}

std::string FormatGeoAlignment(const GeoAlignment& alignment) {
  std::ostringstream text;
  text.precision(3);
  text << std::fixed;
  text << "inliers " << alignment.num_inliers << " of " << alignment.inliers.size()
       << ", residual rms " << alignment.rms_m << " m (horizontal " << alignment.horizontal_rms_m
       << " m, vertical " << alignment.vertical_rms_m << " m), median " << alignment.median_m
       << " m, max " << alignment.max_m << " m, similarity scale " << std::setprecision(5)
       << alignment.scale << " +- " << alignment.scale_sigma;
  return text.str();
}

}  // namespace evloc
