// Lifting semi-dense edge pixels with depth into 3D edge points with 3D gradient directions
// (docs/mapper.md, "3D gradients"): the point on the pixel's ray at its depth,
// the gradient facing the view (ComputeGradient3d) and, where the neighbouring points form a plane,
// the in-surface gradient (SurfaceGradients3d). Shared by the mapper and by any tracker that
// builds edge points from its own keyframe depth; it depends on the camera model only.
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/camera/camera.h"

namespace evloc {

// One edge pixel of a keyframe with its depth: what lifting needs.
struct EdgeDepthPixel {
  // Pixel coordinates (integers, evloc convention: top-left pixel centre at 0, 0).
  Eigen::Vector2i pixel = Eigen::Vector2i::Zero();
  // Inverse depth along the pixel's ray (ray with z = 1), 1/m; > 0.
  double inverse_depth = 0.0;
  // Unit image gradient direction (increasing intensity).
  Eigen::Vector2d gradient_direction = Eigen::Vector2d::UnitX();
};

// Options of SurfaceGradients3d.
struct SurfaceGradientOptions {
  // Half-size of the pixel window whose points give the local surface plane, pixels; 0 keeps the
  // view-facing gradients of ComputeGradient3d.
  int window_px = 20;
  // When the window's points are too few, or lie on one line (a single edge: under a sideways
  // motion only the edges across it get depth), the window is doubled up to this many times
  // (20 -> 40 -> 80 px).
  int window_doublings = 2;
  // The window needs at least this many points on the pixel's surface.
  int min_points = 15;
  // Points whose depth differs from the pixel's by more than this fraction of it, and by more
  // than max_slope times the window's half-width at the pixel's depth, belong to another surface
  // and are left out (the second bound keeps floors and walls seen at a grazing angle).
  double max_depth_difference = 0.05;
  // Largest depth slope of a surface across the window (see max_depth_difference).
  double max_slope = 3.0;
  // Only the points on the brighter side of the edge (and on the edge line, within this many
  // pixels of it) are fitted: on a crease the gradient lies in the brighter face.
  double edge_band_px = 1.0;
  // The points are planar when their smallest principal standard deviation is below this
  // fraction of the middle one...
  double max_thickness_ratio = 0.1;
  // ... and not on one line when the middle one is above this fraction of the largest.
  double min_width_ratio = 0.15;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// The ray–plane 3D gradient direction (docs/mapper.md, "3D gradients"), in the camera frame: the
// ray through pixel + gradient_direction meets the plane through point_in_cam whose normal is the
// viewing direction; the result is the unit vector from the point to that intersection. Returns
// false when the ray cannot be formed or is parallel to the plane.
bool ComputeGradient3d(const Camera& camera, const Eigen::Vector2d& pixel,
                       const Eigen::Vector2d& gradient_direction,
                       const Eigen::Vector3d& point_in_cam, Eigen::Vector3d* gradient_in_cam);

// Per pixel (same order), in the camera frame: the 3D gradient in the surface, the in-surface
// direction perpendicular to the 3D edge, where the surface is the plane fitted to the pixels'
// points within options.window_px of the pixel (same surface: similar depth) and the 3D edge is
// its intersection with the plane through the camera centre and the image edge; signed like
// ComputeGradient3d. Unlike the ray–plane gradient, which lies in the plane facing this view, it is
// the scene's own gradient, the same from every view. std::nullopt where the points are too few,
// not planar, on one line, or the surface is seen edge-on; every entry when window_px is 0.
std::vector<std::optional<Eigen::Vector3d>> SurfaceGradients3d(
    const Camera& camera, const std::vector<EdgeDepthPixel>& pixels,
    const SurfaceGradientOptions& options);

// One edge pixel lifted into 3D, in the camera frame.
struct LiftedEdgePoint {
  // The pixel's unprojected ray, scaled to z = 1 (depth = 1 / inverse depth along it).
  Eigen::Vector3d ray = Eigen::Vector3d::UnitZ();
  // The point: ray / inverse_depth.
  Eigen::Vector3d point_in_cam = Eigen::Vector3d::Zero();
  // Unit 3D gradient: the surface gradient where there is one, else the ray–plane gradient.
  Eigen::Vector3d gradient_in_cam = Eigen::Vector3d::UnitX();
  // True when gradient_in_cam is the surface gradient (SurfaceGradients3d).
  bool surface_gradient = false;
};

// Lifts every pixel (same order): std::nullopt where its ray or its ray–plane gradient cannot be
// formed. Throws InvalidArgumentError on bad options.
std::vector<std::optional<LiftedEdgePoint>> LiftEdgePixels(
    const Camera& camera, const std::vector<EdgeDepthPixel>& pixels,
    const SurfaceGradientOptions& options);

}  // namespace evloc
