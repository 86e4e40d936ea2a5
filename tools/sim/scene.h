// The simulator's world: textured planar quads (boxes are six quads) with procedural,
// piecewise-constant albedo textures whose region boundaries are analytic, so that every texture
// edge is known exactly. World frame: z up, metres. See docs/sim-scene.md.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace evloc::sim {

// Linear RGB albedo in [0, 1] per channel.
using Color = Eigen::Vector3f;

// The gray value of a linear RGB colour (Rec. 709 luminance weights).
float Luminance(const Color& color);

// A uniform gray colour.
inline Color Gray(float value) { return Color(value, value, value); }

// The shape of one texture layer, in the surface's (u, v) coordinates (metres).
enum class LayerShape {
  // Axis-aligned rectangle [min, max].
  kRectangle,
  // Disc of `radius` around `center`.
  kDisc,
  // Convex polygon through `vertices` (either winding).
  kPolygon,
  // Parallel stripes inside the rectangle [min, max]: stripe k covers
  // [min[axis] + k * period, min[axis] + k * period + stripe_width] along `axis` (0 = u, 1 = v),
  // clipped to the rectangle. Between the stripes the lower layers show through.
  kStripes,
  // Checkerboard inside the rectangle [min, max]: square (i, j) of side `square_size` counted from
  // `min` has `color` when i + j is even, `color2` otherwise (squares clipped to the rectangle).
  kCheckerboard,
};

// The name of a layer shape as used in scene JSON: "rectangle", "disc", "polygon", "stripes",
// "checkerboard".
std::string LayerShapeName(LayerShape shape);

// One piecewise-constant region of a texture. Only the fields of its shape are used.
struct TextureLayer {
  // Which shape this layer paints.
  LayerShape shape = LayerShape::kRectangle;
  // Colour painted inside the shape.
  Color color = Gray(0.5f);
  // Second colour (checkerboard odd squares).
  Color color2 = Gray(0.5f);
  // Lower corner of the rectangle / stripes / checkerboard region, metres.
  Eigen::Vector2d min = Eigen::Vector2d::Zero();
  // Upper corner of the rectangle / stripes / checkerboard region, metres.
  Eigen::Vector2d max = Eigen::Vector2d::Zero();
  // Disc centre, metres.
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  // Disc radius, metres.
  double radius = 0;
  // Convex polygon vertices, metres.
  std::vector<Eigen::Vector2d> vertices;
  // Stripe period along `axis`, metres.
  double period = 0;
  // Width of each stripe along `axis`, metres (0 < stripe_width < period).
  double stripe_width = 0;
  // Stripe axis: 0 = stripes repeat along u (their long sides parallel to v), 1 = along v.
  int axis = 0;
  // Checkerboard square side, metres.
  double square_size = 0;

  // A filled axis-aligned rectangle.
  static TextureLayer Rectangle(const Eigen::Vector2d& min, const Eigen::Vector2d& max,
                                const Color& color);
  // A filled disc.
  static TextureLayer Disc(const Eigen::Vector2d& center, double radius, const Color& color);
  // A filled convex polygon.
  static TextureLayer Polygon(std::vector<Eigen::Vector2d> vertices, const Color& color);
  // A thin straight line from `a` to `b` of the given width (a polygon).
  static TextureLayer Line(const Eigen::Vector2d& a, const Eigen::Vector2d& b, double width,
                           const Color& color);
  // Stripes in a rectangle (see LayerShape::kStripes).
  static TextureLayer Stripes(const Eigen::Vector2d& min, const Eigen::Vector2d& max, double period,
                              double stripe_width, int axis, const Color& color);
  // A checkerboard in a rectangle (see LayerShape::kCheckerboard).
  static TextureLayer Checkerboard(const Eigen::Vector2d& min, const Eigen::Vector2d& max,
                                   double square_size, const Color& color, const Color& color2);

  // The axis-aligned bounding box of what the layer may paint.
  Eigen::AlignedBox2d Bounds() const;
  // Throws InvalidArgumentError (prefixed by `where`) when the layer is degenerate: empty
  // rectangle, non-positive radius, non-convex or degenerate polygon, bad stripe period or width,
  // bad axis, non-positive square size, colours outside [0, 1] or non-finite values.
  void Check(const std::string& where) const;
};

// A procedural texture: a base colour and layers painted on top of it in order (later layers
// cover earlier ones).
struct Texture {
  // Colour where no layer paints.
  Color base = Gray(0.5f);
  // Layers, bottom first.
  std::vector<TextureLayer> layers;

  // The colour at (u, v).
  Color ColorAt(const Eigen::Vector2d& uv) const;
  // The colour at (u, v), and whether some region boundary passes within `radius` of (u, v)
  // (conservative: it may say true when no visible boundary is that close).
  Color ColorAt(const Eigen::Vector2d& uv, double radius, bool* near_boundary) const;
  // Throws InvalidArgumentError (prefixed by `where`) when a layer is invalid.
  void Check(const std::string& where) const;
};

// A texture prepared for fast repeated evaluation: layer bounds and polygon edge lines are
// precomputed and a uniform grid over the texture domain lists, per cell, the layers that may
// paint within `max_radius` of it. Gives the same results as Texture::ColorAt.
class IndexedTexture {
 public:
  // Indexes `texture` (which must outlive this object and stay unchanged) over the domain
  // [0, width] x [0, height] with square cells of `cell_size` metres; queries with a radius above
  // `max_radius` or outside the domain fall back to testing every layer.
  IndexedTexture(const Texture& texture, double width, double height, double cell_size = 0.05,
                 double max_radius = 0.02);
  // The colour at (u, v).
  Color ColorAt(const Eigen::Vector2d& uv) const;
  // The colour at (u, v) and whether a region boundary passes within `radius` (as
  // Texture::ColorAt).
  Color ColorAt(const Eigen::Vector2d& uv, double radius, bool* near_boundary) const;

 private:
  struct PreparedLayer {
    const TextureLayer* layer = nullptr;
    Eigen::AlignedBox2d bounds;
    // Polygons: outward unit normals and offsets of the edge lines (n . p <= offset inside).
    std::vector<Eigen::Vector3d> edge_lines;
  };
  Color Evaluate(const Eigen::Vector2d& uv, double radius, bool* near_boundary,
                 const std::vector<int>* cell) const;

  const Texture* texture_;
  std::vector<PreparedLayer> layers_;
  double cell_size_, max_radius_;
  int columns_ = 0, rows_ = 0;
  // Layer indices per cell, ascending.
  std::vector<std::vector<int>> cells_;
};

// A textured rectangle in the world: the points origin + u * u_axis + v * v_axis for u in
// [0, width], v in [0, height]. Rendered from both sides.
struct Surface {
  // Name for messages and JSON (e.g. "wall_north", "box1/+z").
  std::string name;
  // The corner at (u, v) = (0, 0), world metres.
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  // Unit direction of increasing u, world.
  Eigen::Vector3d u_axis = Eigen::Vector3d::UnitX();
  // Unit direction of increasing v, world; orthogonal to u_axis.
  Eigen::Vector3d v_axis = Eigen::Vector3d::UnitY();
  // Extent along u, metres.
  double width = 1;
  // Extent along v, metres.
  double height = 1;
  // Constant shading factor in (0, 1]: irradiance = albedo * shading.
  float shading = 1.0f;
  // Fraction of the light reflected as by a mirror, in [0, 1] (0: matte). Only the simulated
  // depth camera reads it: its projected pattern is lost where it sees such a surface near the
  // mirror direction (depth_sensor.h).
  float specular = 0.0f;
  // The albedo texture in (u, v) metres.
  Texture texture;

  // The front normal u_axis x v_axis (the side meant to be seen; box faces point outwards).
  Eigen::Vector3d Normal() const { return u_axis.cross(v_axis); }
  // The world point at (u, v).
  Eigen::Vector3d PointAt(double u, double v) const { return origin + u * u_axis + v * v_axis; }
  // The four corners, counter-clockwise in (u, v): (0,0), (w,0), (w,h), (0,h).
  std::array<Eigen::Vector3d, 4> Corners() const;
  // Linear gray irradiance at (u, v): Luminance(albedo) * shading.
  float GrayAt(const Eigen::Vector2d& uv) const { return Luminance(texture.ColorAt(uv)) * shading; }
  // Throws InvalidArgumentError naming the surface when it is degenerate (non-positive or
  // non-finite size, axes not unit or not orthogonal within 1e-6, shading outside (0, 1]) or its
  // texture is invalid.
  void Check() const;
};

// Directional lighting used to give each surface a constant shading.
struct Lighting {
  // Unit direction from the scene towards the light, world.
  Eigen::Vector3d towards_light = Eigen::Vector3d(0.3, -0.5, 0.81).normalized();
  // Shading of a surface facing away from the light, in (0, 1].
  double ambient = 0.55;

  // ambient + (1 - ambient) * max(0, normal . towards_light), for a unit front normal.
  float ShadingFor(const Eigen::Vector3d& normal) const;
};

// A point light (a street lamp): irradiance intensity * cos(incidence) / distance^2 on the side of
// a surface that faces it (no shadows: the light passes through other surfaces).
struct PointLight {
  // Position, world metres.
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  // Radiant intensity: the irradiance at 1 m on a surface facing the light, in the units of the
  // rendered irradiance (1 = white paper under the scene's full daylight).
  double intensity = 1;
};

// A textured scene.
struct Scene {
  // Name, for messages and provenance.
  std::string name;
  // All surfaces (boxes expanded into their faces).
  std::vector<Surface> surfaces;
  // Bounding box of all surfaces, world metres (UpdateBounds computes it).
  Eigen::AlignedBox3d bounds;
  // Where a camera may be placed and still see the scene from the inside, world metres.
  Eigen::AlignedBox3d camera_region;
  // The lighting used to shade boxes and quads without explicit shading.
  Lighting lighting;
  // Scale of the daylight (sun and sky, i.e. every surface's `shading`), in [0, 1]: 1 by day,
  // small at night. The rendered irradiance at a point is
  // min(1, albedo * (daylight * shading + sum of the point lights' irradiance)).
  double daylight = 1;
  // Irradiance of rays that hit nothing (the sky) at full daylight, in [0, 1]; rendered scaled by
  // `daylight`.
  double sky = 0;
  // Point lights (street lamps); none by default.
  std::vector<PointLight> point_lights;

  // Sets `bounds` to the bounding box of all surface corners.
  void UpdateBounds();
  // The light factor at `point` (world) of `surface`, seen from `viewer` (world; the lights
  // shine on the side of the surface facing the viewer only when they lie on that side too):
  // daylight * shading + the point lights' irradiance. Multiply by the albedo and clamp to 1.
  float LightFactorAt(const Surface& surface, const Eigen::Vector3d& point,
                      const Eigen::Vector3d& viewer) const;
  // Throws InvalidArgumentError when the scene has no surface, a surface is invalid, the
  // camera region is empty or non-finite, daylight or sky lie outside [0, 1], or a point light
  // is non-finite or has a negative intensity.
  void Check() const;
};

// A box: six quads. Local frame: centre `center`, rotated by `yaw` radians about world z; local
// faces are ordered +x, -x, +y, -y, +z, -z; each face's front normal points outwards.
struct BoxSpec {
  // Name; faces are named "<name>/+x" etc.
  std::string name;
  // Centre, world metres.
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  // Full extents along local x, y, z, metres.
  Eigen::Vector3d size = Eigen::Vector3d::Ones();
  // Rotation about world z, radians.
  double yaw = 0;
  // Per-face textures in the order +x, -x, +y, -y, +z, -z. Every face is seen from outside with
  // u to the right and v up: side faces have (0, 0) at their bottom-left corner and v = local z;
  // +z has u = local x, v = local y; -z has u = local x, v = -local y (docs/sim-scene.md).
  std::array<Texture, 6> face_textures;
  // Whether to emit the -z face (false for boxes resting on a surface, where it is never seen).
  bool bottom_face = true;
};

// A deterministic pseudo-random generator (64-bit LCG) for scene layout: the same seed gives the
// same numbers on every platform.
class LayoutRandom {
 public:
  explicit LayoutRandom(uint64_t seed) : state_(seed) {}
  // Uniform in [low, high).
  double Uniform(double low, double high) {
    state_ = state_ * 6364136223846793005ULL + 1442695040888963407ULL;
    const double unit = static_cast<double>(state_ >> 11) / static_cast<double>(1ULL << 53);
    return low + (high - low) * unit;
  }

 private:
  uint64_t state_;
};

// Appends the faces of `box` to `scene`, shaded by scene->lighting. Throws InvalidArgumentError
// for a non-positive or non-finite size.
void AddBox(const BoxSpec& box, Scene* scene);

// The default room, about 4 x 4 x 2.5 m (x in [-2, 2], y in [-2, 2], z in [0, 2.5]): walls with
// posters, stripes, a checkerboard and thin lines, a textured floor, a ceiling, a table with boxes
// on it (occlusions), shelves (repetitive structure), low-contrast blobs. Deterministic.
Scene MakeDefaultRoom();

// Reads a scene from JSON (schema: docs/sim-scene.md). Throws IoError when the file cannot be
// read, ParseError naming the file and the JSON location ("/quads/3/texture/layers/0/radius") when
// it is malformed or invalid.
Scene LoadSceneJson(const std::filesystem::path& path);

// Parses scene JSON text; `source` names the text in errors. Throws ParseError like LoadSceneJson.
Scene ParseSceneJson(const std::string& text, const std::string& source);

// Formats a scene as JSON (every surface written as a quad with explicit shading), so that
// ParseSceneJson(SceneToJson(scene)) reproduces the scene exactly.
std::string SceneToJson(const Scene& scene);

// Writes SceneToJson(scene) to `path` atomically. Throws IoError when it cannot.
void SaveSceneJson(const std::filesystem::path& path, const Scene& scene);

}  // namespace evloc::sim
