#include "tools/sim/ground_truth_map.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <opencv2/core/utility.hpp>

#include "core/common/error.h"
#include "core/common/provenance.h"
#include "tools/sim/renderer.h"

namespace evloc::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
// Distance below which a point counts as lying on a plane or a quad outline, metres.
constexpr double kOnSurfaceTolerance = 1e-6;

// A boundary curve of a texture region in (u, v): a segment, or a full circle.
struct BoundaryCurve {
  bool is_circle = false;
  Eigen::Vector2d a = Eigen::Vector2d::Zero(), b = Eigen::Vector2d::Zero();
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  double radius = 0;
};

void AddRectangleOutline(const Eigen::Vector2d& min, const Eigen::Vector2d& max,
                         std::vector<BoundaryCurve>* curves) {
  const Eigen::Vector2d corners[4] = {min, Eigen::Vector2d(max.x(), min.y()), max,
                                      Eigen::Vector2d(min.x(), max.y())};
  for (int i = 0; i < 4; ++i) curves->push_back({false, corners[i], corners[(i + 1) % 4]});
}

// Every curve on which a layer changes colour (some may show no contrast: they are filtered by
// probing the texture on both sides).
std::vector<BoundaryCurve> LayerBoundaries(const TextureLayer& layer) {
  std::vector<BoundaryCurve> curves;
  switch (layer.shape) {
    case LayerShape::kRectangle:
      AddRectangleOutline(layer.min, layer.max, &curves);
      break;
    case LayerShape::kDisc: {
      BoundaryCurve circle;
      circle.is_circle = true;
      circle.center = layer.center;
      circle.radius = layer.radius;
      curves.push_back(circle);
      break;
    }
    case LayerShape::kPolygon:
      for (size_t i = 0; i < layer.vertices.size(); ++i) {
        curves.push_back(
            {false, layer.vertices[i], layer.vertices[(i + 1) % layer.vertices.size()]});
      }
      break;
    case LayerShape::kStripes: {
      AddRectangleOutline(layer.min, layer.max, &curves);
      const int axis = layer.axis, other = 1 - axis;
      for (int k = 0;; ++k) {
        const double start = layer.min[axis] + k * layer.period;
        if (start >= layer.max[axis]) break;
        for (const double position : {start, start + layer.stripe_width}) {
          if (position <= layer.min[axis] || position >= layer.max[axis]) continue;
          Eigen::Vector2d a, b;
          a[axis] = b[axis] = position;
          a[other] = layer.min[other];
          b[other] = layer.max[other];
          curves.push_back({false, a, b});
        }
      }
      break;
    }
    case LayerShape::kCheckerboard:
      AddRectangleOutline(layer.min, layer.max, &curves);
      for (int axis = 0; axis < 2; ++axis) {
        const int other = 1 - axis;
        for (int k = 1;; ++k) {
          const double position = layer.min[axis] + k * layer.square_size;
          if (position >= layer.max[axis]) break;
          Eigen::Vector2d a, b;
          a[axis] = b[axis] = position;
          a[other] = layer.min[other];
          b[other] = layer.max[other];
          curves.push_back({false, a, b});
        }
      }
      break;
  }
  return curves;
}

// Calls sample(point, unit normal) at evenly spaced points of the curve (midpoints of n equal
// pieces, so never at a corner).
template <typename Sample>
void SampleCurve(const BoundaryCurve& curve, double spacing, const Sample& sample) {
  if (curve.is_circle) {
    const int count =
        std::max(8, static_cast<int>(std::ceil(2 * kPi * curve.radius / spacing - 1e-9)));
    for (int k = 0; k < count; ++k) {
      const double angle = (k + 0.5) * 2 * kPi / count;
      const Eigen::Vector2d normal(std::cos(angle), std::sin(angle));
      sample(Eigen::Vector2d(curve.center + curve.radius * normal), normal);
    }
    return;
  }
  const Eigen::Vector2d direction = curve.b - curve.a;
  const double length = direction.norm();
  if (!(length > 0)) return;
  // The tolerance keeps lengths that are whole multiples of the spacing from gaining a point.
  const int count = std::max(1, static_cast<int>(std::ceil(length / spacing - 1e-9)));
  const Eigen::Vector2d normal = Eigen::Vector2d(-direction.y(), direction.x()) / length;
  for (int k = 0; k < count; ++k) {
    sample(Eigen::Vector2d(curve.a + (k + 0.5) / count * direction), normal);
  }
}

bool InsideDomain(const Surface& surface, const Eigen::Vector2d& uv, double margin) {
  return uv.x() >= margin && uv.x() <= surface.width - margin && uv.y() >= margin &&
         uv.y() <= surface.height - margin;
}

Eigen::Vector2d SurfaceCoordinates(const Surface& surface, const Eigen::Vector3d& point) {
  const Eigen::Vector3d offset = point - surface.origin;
  return Eigen::Vector2d(offset.dot(surface.u_axis), offset.dot(surface.v_axis));
}

// Whether `point` lies on the surface (plane and outline, within the tolerance).
bool OnSurface(const Surface& surface, const Eigen::Vector3d& point) {
  if (std::abs(surface.Normal().dot(point - surface.origin)) > kOnSurfaceTolerance) return false;
  return InsideDomain(surface, SurfaceCoordinates(surface, point), -kOnSurfaceTolerance);
}

// Whether `point` lies on the outline of the surface.
bool OnOutline(const Surface& surface, const Eigen::Vector3d& point) {
  if (!OnSurface(surface, point)) return false;
  return !InsideDomain(surface, SurfaceCoordinates(surface, point), kOnSurfaceTolerance);
}

double LogContrast(double a, double b, double epsilon) {
  return std::abs(std::log(a + epsilon) - std::log(b + epsilon));
}

}  // namespace

void GroundTruthMapOptions::Check() const {
  if (!std::isfinite(point_spacing_m) || point_spacing_m <= 0) {
    throw InvalidArgumentError("GroundTruthMapOptions.point_spacing_m must be positive");
  }
  if (!std::isfinite(min_contrast) || min_contrast < 0) {
    throw InvalidArgumentError("GroundTruthMapOptions.min_contrast must be >= 0");
  }
  if (!std::isfinite(log_epsilon) || log_epsilon <= 0) {
    throw InvalidArgumentError("GroundTruthMapOptions.log_epsilon must be positive");
  }
  if (!std::isfinite(probe_offset_m) || probe_offset_m <= 0) {
    throw InvalidArgumentError("GroundTruthMapOptions.probe_offset_m must be positive");
  }
  if (!std::isfinite(visibility_margin_px) || visibility_margin_px < 0) {
    throw InvalidArgumentError("GroundTruthMapOptions.visibility_margin_px must be >= 0");
  }
}

std::vector<GroundTruthEdgePoint> SampleGroundTruthEdges(const Scene& scene,
                                                         const GroundTruthMapOptions& options) {
  scene.Check();
  options.Check();
  const double delta = options.probe_offset_m;
  std::vector<GroundTruthEdgePoint> points;

  // Texture edges.
  for (size_t s = 0; s < scene.surfaces.size(); ++s) {
    const Surface& surface = scene.surfaces[s];
    for (const TextureLayer& layer : surface.texture.layers) {
      for (const BoundaryCurve& curve : LayerBoundaries(layer)) {
        SampleCurve(
            curve, options.point_spacing_m,
            [&](const Eigen::Vector2d& uv, const Eigen::Vector2d& normal) {
              // Points on (or next to) the quad outline belong to the creases.
              if (!InsideDomain(surface, uv, 2 * delta)) return;
              const double plus = surface.GrayAt(uv + delta * normal);
              const double minus = surface.GrayAt(uv - delta * normal);
              const double contrast = LogContrast(plus, minus, options.log_epsilon);
              if (contrast < options.min_contrast || contrast == 0) return;
              const Eigen::Vector2d gradient = plus > minus ? normal : Eigen::Vector2d(-normal);
              GroundTruthEdgePoint point;
              point.position = surface.PointAt(uv.x(), uv.y());
              point.gradient =
                  (gradient.x() * surface.u_axis + gradient.y() * surface.v_axis).normalized();
              point.intensity_step = std::abs(plus - minus);
              point.log_contrast = contrast;
              point.kind = EdgeKind::kTexture;
              point.surface_index = static_cast<int>(s);
              points.push_back(point);
            });
      }
    }
  }
  if (!options.include_creases) return points;

  // Creases: sample each quad's outline and find the surface meeting it there.
  std::vector<Eigen::AlignedBox3d> boxes(scene.surfaces.size());
  for (size_t b = 0; b < scene.surfaces.size(); ++b) {
    for (const Eigen::Vector3d& corner : scene.surfaces[b].Corners()) boxes[b].extend(corner);
  }
  for (size_t a = 0; a < scene.surfaces.size(); ++a) {
    const Surface& surface_a = scene.surfaces[a];
    const Eigen::Vector3d normal_a = surface_a.Normal();
    const std::array<Eigen::Vector2d, 4> corners = {
        Eigen::Vector2d(0, 0), Eigen::Vector2d(surface_a.width, 0),
        Eigen::Vector2d(surface_a.width, surface_a.height), Eigen::Vector2d(0, surface_a.height)};
    // Surfaces that may touch this one (bounding boxes overlap).
    Eigen::AlignedBox3d box_a = boxes[a];
    box_a.extend(box_a.min() - Eigen::Vector3d::Constant(1e-4));
    box_a.extend(box_a.max() + Eigen::Vector3d::Constant(1e-4));
    std::vector<size_t> neighbours;
    for (size_t b = 0; b < scene.surfaces.size(); ++b) {
      if (b != a && box_a.intersects(boxes[b])) neighbours.push_back(b);
    }
    for (int edge = 0; edge < 4; ++edge) {
      const BoundaryCurve curve{false, corners[edge], corners[(edge + 1) % 4]};
      const Eigen::Vector3d edge_direction = (surface_a.PointAt(curve.b.x(), curve.b.y()) -
                                              surface_a.PointAt(curve.a.x(), curve.a.y()))
                                                 .normalized();
      SampleCurve(
          curve, options.point_spacing_m,
          [&](const Eigen::Vector2d& uv, const Eigen::Vector2d& normal) {
            // The curve runs counter-clockwise, so its left normal points into the quad.
            const Eigen::Vector3d position = surface_a.PointAt(uv.x(), uv.y());
            const Eigen::Vector3d into_a =
                (normal.x() * surface_a.u_axis + normal.y() * surface_a.v_axis);
            for (size_t b : neighbours) {
              const Surface& surface_b = scene.surfaces[b];
              const Eigen::Vector3d normal_b = surface_b.Normal();
              if (std::abs(normal_a.dot(normal_b)) > 1 - 1e-9) continue;
              if (!OnSurface(surface_b, position)) continue;
              // Emitted once: from the lower-index surface when the edge is on both outlines.
              if (b < a && OnOutline(surface_b, position)) return;
              // A's edge crosses B's plane there (it runs along B's normal: the corner of two
              // walls meeting a third at a right angle, sampled exactly where they meet): that is
              // not a crease of A with B.
              const Eigen::Vector3d across_b = normal_b.cross(edge_direction);
              if (across_b.squaredNorm() < 1e-12) continue;
              Eigen::Vector3d into_b = across_b.normalized();
              const bool plus_inside = InsideDomain(
                  surface_b, SurfaceCoordinates(surface_b, position + delta * into_b), 0);
              const bool minus_inside = InsideDomain(
                  surface_b, SurfaceCoordinates(surface_b, position - delta * into_b), 0);
              if (plus_inside && minus_inside) {
                // The edge crosses B's interior (a box standing on a table): the visible side of B
                // is the one in front of A.
                if (into_b.dot(normal_a) < 0) into_b = -into_b;
              } else if (minus_inside) {
                into_b = -into_b;
              } else if (!plus_inside) {
                continue;
              }
              const double irradiance_a = surface_a.GrayAt(uv + delta * normal);
              const double irradiance_b =
                  surface_b.GrayAt(SurfaceCoordinates(surface_b, position + delta * into_b));
              const double contrast = LogContrast(irradiance_a, irradiance_b, options.log_epsilon);
              if (contrast < options.min_contrast || contrast == 0) return;
              GroundTruthEdgePoint point;
              point.position = position;
              const bool b_brighter = irradiance_b > irradiance_a;
              point.gradient = b_brighter ? into_b : into_a.normalized();
              point.surface_index = static_cast<int>(b_brighter ? b : a);
              point.intensity_step = std::abs(irradiance_a - irradiance_b);
              point.log_contrast = contrast;
              point.kind =
                  into_b.dot(normal_a) > 0 ? EdgeKind::kConcaveCrease : EdgeKind::kConvexCrease;
              points.push_back(point);
              return;
            }
          });
    }
  }
  return points;
}

bool IsPointUnoccluded(const Scene& scene, const Eigen::Vector3d& camera_center,
                       const Eigen::Vector3d& point) {
  const Eigen::Vector3d direction = point - camera_center;
  const std::optional<RayHit> hit = CastRay(scene, camera_center, direction, 1e-9);
  return !hit || hit->distance >= 1 - 1e-6;
}

bool IsPointUnoccluded(const SurfaceIndex& index, const Eigen::Vector3d& camera_center,
                       const Eigen::Vector3d& point) {
  const Eigen::Vector3d direction = point - camera_center;
  const std::optional<RayHit> hit = index.CastRay(camera_center, direction, 1e-9);
  return !hit || hit->distance >= 1 - 1e-6;
}

Map BuildGroundTruthMap(const Scene& scene, const Camera& camera,
                        const std::vector<Rigid3d>& keyframe_world_from_cam,
                        const GroundTruthMapOptions& options) {
  camera.Check();
  for (size_t k = 0; k < keyframe_world_from_cam.size(); ++k) {
    if (!keyframe_world_from_cam[k].IsFinite()) {
      throw InvalidArgumentError("BuildGroundTruthMap: keyframe " + std::to_string(k) +
                                 " has a non-finite pose");
    }
  }
  const std::vector<GroundTruthEdgePoint> edges = SampleGroundTruthEdges(scene, options);

  const SurfaceIndex index(scene);
  // visible[k][i]: keyframe k sees edge point i.
  const size_t num_keyframes = keyframe_world_from_cam.size();
  std::vector<std::vector<uint8_t>> visible(num_keyframes, std::vector<uint8_t>(edges.size(), 0));
  for (size_t k = 0; k < num_keyframes; ++k) {
    const Rigid3d cam_from_world = keyframe_world_from_cam[k].Inverse();
    const Eigen::Vector3d center = keyframe_world_from_cam[k].translation;
    cv::parallel_for_(cv::Range(0, static_cast<int>(edges.size())), [&](const cv::Range& range) {
      for (int i = range.start; i < range.end; ++i) {
        Eigen::Vector2d pixel;
        if (!camera.Project(cam_from_world * edges[i].position, &pixel)) continue;
        if (!camera.IsInside(pixel, options.visibility_margin_px)) continue;
        if (IsPointUnoccluded(index, center, edges[i].position)) visible[k][i] = 1;
      }
    });
  }

  Map map;
  map.cameras.push_back(camera);
  std::vector<uint32_t> map_index(edges.size(), kNoKeyframe);
  for (size_t i = 0; i < edges.size(); ++i) {
    uint32_t source = kNoKeyframe;
    for (size_t k = 0; k < num_keyframes && source == kNoKeyframe; ++k) {
      if (visible[k][i]) source = static_cast<uint32_t>(k);
    }
    if (source == kNoKeyframe && options.drop_unseen_points) continue;
    map_index[i] = static_cast<uint32_t>(map.size());
    map.AddPoint(edges[i].position.cast<float>(), edges[i].gradient.cast<float>().normalized(),
                 0.0f, static_cast<float>(edges[i].intensity_step), source);
  }
  for (size_t k = 0; k < num_keyframes; ++k) {
    Keyframe keyframe;
    keyframe.cam_from_world = keyframe_world_from_cam[k].Inverse();
    keyframe.camera_index = 0;
    keyframe.t_ns = static_cast<int64_t>(k);
    for (size_t i = 0; i < edges.size(); ++i) {
      if (visible[k][i] && map_index[i] != kNoKeyframe)
        keyframe.visible_points.push_back(map_index[i]);
    }
    map.keyframes.push_back(std::move(keyframe));
  }
  map.provenance.tool = options.tool;
  map.provenance.tool_version = ToolVersion();
  map.provenance.created_utc = UtcNowIso8601();
  map.provenance.command_line = "BuildGroundTruthMap";
  map.provenance.inputs.push_back("scene:" + scene.name);
  map.Check();
  return map;
}

}  // namespace evloc::sim
