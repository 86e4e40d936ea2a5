// The geo-reference of a map from corresponding map-frame and WGS84 points (docs/geo.md,
// "Anchors from points"): surveyed points, or camera centres with the GNSS positions of their
// photos. The points are expressed in an ENU frame at their centroid and the map frame is aligned
// to them with a rigid Umeyama fit inside RANSAC (consumer GNSS has outliers of tens of metres),
// refitted on the inliers; the residuals say how well the map and the points agree.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/geo/geo_anchor.h"

namespace evloc {

// One map-frame point and its WGS84 position.
struct GeoCorrespondence {
  // The point in the map frame, metres.
  Eigen::Vector3d p_map = Eigen::Vector3d::Zero();
  // Its WGS84 position.
  GeodeticPoint geodetic;
  // What it is, for messages ("image IMG_0001.JPG", "line 12").
  std::string label;
};

struct GeoAlignmentOptions {
  // A correspondence is an inlier when its 3D residual is at most this, metres (consumer GNSS:
  // about 3 m one-sigma per axis, so 10 m keeps 99 % of the good ones).
  double inlier_threshold_m = 10.0;
  // RANSAC samples of 3 correspondences.
  int ransac_iterations = 1000;
  // Seed of the sampler (the result is deterministic for a seed).
  uint64_t seed = 1;
  // Fewest inliers accepted.
  size_t min_inliers = 3;
  // Largest accepted |s - 1| for the scale s of a similarity fit on the inliers (a metric map
  // has s = 1 up to the points' noise; a larger deviation means the map or the points are wrong),
  // unless it is within 4 standard errors of the scale (noisy points over a small site: the
  // residual spread per axis over sqrt(n) times the points' RMS distance from their centroid).
  double max_scale_deviation = 0.05;
  // Largest accepted standard error of the fitted rotation, radians (the residual spread per
  // axis over sqrt(n) times the points' RMS distance from their centroid): beyond it the points
  // are too noisy for their spread to orient the map (3 m GNSS over a room).
  double max_rotation_sigma_rad = 0.1;

  // Throws InvalidArgumentError unless threshold > 0 and finite, iterations >= 1,
  // min_inliers >= 3, max_scale_deviation finite and >= 0 and max_rotation_sigma_rad > 0.
  void Check() const;
};

// The result of AlignMapToGeodetic.
struct GeoAlignment {
  // The anchor: origin at the centroid of the inlier points (ECEF mean), enu_from_map the rigid
  // fit, sigmas from the residuals (standard error of the fit at the centroid).
  GeoAnchor anchor;
  // Scale of a similarity fit on the same inliers (a diagnostic: the anchor is rigid), and its
  // standard error from the residuals.
  double scale = 1.0;
  double scale_sigma = 0.0;
  // Standard error of the fitted rotation, radians (the same ratio as scale_sigma).
  double rotation_sigma_rad = 0.0;
  // Per correspondence: inside the inlier threshold after the final fit.
  std::vector<bool> inliers;
  // Per correspondence: the geodetic point minus the aligned map point, in the anchor's ENU
  // frame, metres.
  std::vector<Eigen::Vector3d> residuals_enu;
  size_t num_inliers = 0;
  // Over the inliers: root mean square of the 3D residual, of its horizontal part and of its
  // vertical part, the median and the largest 3D residual, metres.
  double rms_m = 0.0;
  double horizontal_rms_m = 0.0;
  double vertical_rms_m = 0.0;
  double median_m = 0.0;
  double max_m = 0.0;
};

// Aligns the map frame to the WGS84 points; the anchor gets `source`. Throws
// InvalidArgumentError when there are fewer than 3 correspondences, a point is invalid, the
// points are degenerate (collinear), fewer than min_inliers agree, or the scale deviates.
GeoAlignment AlignMapToGeodetic(const std::vector<GeoCorrespondence>& correspondences,
                                const GeoAlignmentOptions& options, const std::string& source);

// A readable summary of an alignment (inliers, residual statistics, scale), for the CLI.
std::string FormatGeoAlignment(const GeoAlignment& alignment);

}  // namespace evloc
