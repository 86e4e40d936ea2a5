// The exact semi-dense map of a sim::Scene: points sampled along every texture edge and every
// crease between two surfaces, with exact 3D gradient directions and albedo steps, and keyframes
// whose visible points are found by ray casting. Definitions: docs/sim-scene.md, "Ground-truth
// map".
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "maps/map.h"
#include "tools/sim/renderer.h"
#include "tools/sim/scene.h"

namespace evloc::sim {

// How the ground-truth map is sampled.
struct GroundTruthMapOptions {
  // Spacing of the points along each edge, metres.
  double point_spacing_m = 0.01;
  // Minimum contrast |ln(I_bright + log_epsilon) - ln(I_dark + log_epsilon)| of an edge point,
  // with I the linear irradiance (albedo * shading) on either side.
  double min_contrast = 0.1;
  // The epsilon of the log intensity (as in the event simulator).
  double log_epsilon = 1e-3;
  // Distance from an edge at which the two sides are probed, metres (smaller than any feature).
  double probe_offset_m = 2e-4;
  // Emit points on creases between two surfaces (geometric edges).
  bool include_creases = true;
  // Drop points that no keyframe sees (otherwise they are kept with source kNoKeyframe).
  bool drop_unseen_points = false;
  // A keyframe sees a point that projects at least this far inside the image border, pixels.
  double visibility_margin_px = 0;
  // Tool name recorded in the map provenance.
  std::string tool = "evloc-sim";

  // Throws InvalidArgumentError when a spacing, offset or epsilon is not positive, min_contrast
  // is negative, or visibility_margin_px is negative.
  void Check() const;
};

// What kind of edge a ground-truth point lies on.
enum class EdgeKind {
  // A boundary between two albedo regions of one surface.
  kTexture,
  // A crease where the two surfaces' front sides face each other (e.g. wall meets floor, box
  // stands on a table): both faces are seen together.
  kConcaveCrease,
  // A crease where the front sides face away from each other (a box's outer edge): from some
  // viewpoints only one face is seen and the image edge is an occluding contour against
  // whatever lies behind, whose contrast the map cannot know.
  kConvexCrease,
};

// One exact edge point.
struct GroundTruthEdgePoint {
  // Position, world metres.
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  // Unit 3D gradient direction, world: tangent to the brighter side's surface, perpendicular to
  // the edge, pointing from the edge into the brighter side.
  Eigen::Vector3d gradient = Eigen::Vector3d::UnitX();
  // Linear irradiance step |I_bright - I_dark|, in [0, 1].
  double intensity_step = 0;
  // |ln(I_bright + eps) - ln(I_dark + eps)|.
  double log_contrast = 0;
  // The edge kind.
  EdgeKind kind = EdgeKind::kTexture;
  // The surface the point was sampled on (the brighter side's for creases).
  int surface_index = -1;
};

// Samples every texture edge and crease of `scene` whose contrast reaches options.min_contrast.
// Deterministic. Throws InvalidArgumentError when the scene or the options fail Check().
std::vector<GroundTruthEdgePoint> SampleGroundTruthEdges(const Scene& scene,
                                                         const GroundTruthMapOptions& options);

// True when the straight segment from `camera_center` to `point` (world) hits no surface before
// reaching the point (a relative tolerance of 1e-6 lets surfaces through the point itself count
// as not occluding).
bool IsPointUnoccluded(const Scene& scene, const Eigen::Vector3d& camera_center,
                       const Eigen::Vector3d& point);
// The same through a surface index (site-scale scenes).
bool IsPointUnoccluded(const SurfaceIndex& index, const Eigen::Vector3d& camera_center,
                       const Eigen::Vector3d& point);

// The exact semi-dense map of `scene`: the points of SampleGroundTruthEdges, with gradient
// magnitude = intensity step and inverse-depth sigma 0 (exact), one camera, and one keyframe per
// pose (t_ns = index) whose visible_points are the points that project inside the image (margin
// options.visibility_margin_px) and are unoccluded. A point's source keyframe is the first
// keyframe that sees it (kNoKeyframe if none). Throws InvalidArgumentError when an input fails
// Check() or a pose is not finite.
Map BuildGroundTruthMap(const Scene& scene, const Camera& camera,
                        const std::vector<Rigid3d>& keyframe_world_from_cam,
                        const GroundTruthMapOptions& options);

}  // namespace evloc::sim
