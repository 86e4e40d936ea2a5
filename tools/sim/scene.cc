#include "tools/sim/scene.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

bool IsFinite2(const Eigen::Vector2d& v) { return std::isfinite(v.x()) && std::isfinite(v.y()); }

bool IsValidColor(const Color& color) {
  for (int c = 0; c < 3; ++c) {
    if (!std::isfinite(color[c]) || color[c] < 0.0f || color[c] > 1.0f) return false;
  }
  return true;
}

// Whether `p` lies in [min, max] and whether it lies within `radius` of its outline.
void RectangleTest(const Eigen::Vector2d& min, const Eigen::Vector2d& max, const Eigen::Vector2d& p,
                   double radius, bool* inside, bool* near) {
  *inside = p.x() >= min.x() && p.x() <= max.x() && p.y() >= min.y() && p.y() <= max.y();
  const bool in_expanded = p.x() > min.x() - radius && p.x() < max.x() + radius &&
                           p.y() > min.y() - radius && p.y() < max.y() + radius;
  const bool in_shrunk = p.x() > min.x() + radius && p.x() < max.x() - radius &&
                         p.y() > min.y() + radius && p.y() < max.y() - radius;
  *near = in_expanded && !in_shrunk;
}

// Distance from x to the nearest multiple of `period` (x >= 0 not required).
double DistanceToGrid(double x, double period) {
  const double f = x - std::floor(x / period) * period;
  return std::min(f, period - f);
}

// Signed area of a polygon (positive when counter-clockwise).
double SignedArea(const std::vector<Eigen::Vector2d>& vertices) {
  double area = 0;
  for (size_t i = 0; i < vertices.size(); ++i) {
    const Eigen::Vector2d& a = vertices[i];
    const Eigen::Vector2d& b = vertices[(i + 1) % vertices.size()];
    area += a.x() * b.y() - a.y() * b.x();
  }
  return 0.5 * area;
}

// For a convex polygon, the largest signed distance of p to an edge line (positive outside).
double PolygonMaxEdgeDistance(const std::vector<Eigen::Vector2d>& vertices,
                              const Eigen::Vector2d& p) {
  const double orientation = SignedArea(vertices) > 0 ? 1.0 : -1.0;
  double max_distance = -std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < vertices.size(); ++i) {
    const Eigen::Vector2d& a = vertices[i];
    const Eigen::Vector2d& b = vertices[(i + 1) % vertices.size()];
    const Eigen::Vector2d edge = b - a;
    // Outward normal of a counter-clockwise polygon is (edge.y, -edge.x).
    const Eigen::Vector2d outward =
        orientation * Eigen::Vector2d(edge.y(), -edge.x()) / edge.norm();
    max_distance = std::max(max_distance, outward.dot(p - a));
  }
  return max_distance;
}

// Whether layer paints p, and whether p lies within `radius` of one of the layer's boundaries.
// Returns the painted colour through `color` when it paints.
bool LayerTest(const TextureLayer& layer, const Eigen::Vector2d& p, double radius, bool* near,
               Color* color, const std::vector<Eigen::Vector3d>* edge_lines = nullptr) {
  bool inside = false;
  *near = false;
  switch (layer.shape) {
    case LayerShape::kRectangle:
      RectangleTest(layer.min, layer.max, p, radius, &inside, near);
      *color = layer.color;
      return inside;
    case LayerShape::kDisc: {
      const double distance = (p - layer.center).norm();
      *near = std::abs(distance - layer.radius) < radius;
      *color = layer.color;
      return distance <= layer.radius;
    }
    case LayerShape::kPolygon: {
      double distance;
      if (edge_lines != nullptr) {
        distance = -std::numeric_limits<double>::infinity();
        for (const Eigen::Vector3d& line : *edge_lines) {
          distance = std::max(distance, line.x() * p.x() + line.y() * p.y() - line.z());
        }
      } else {
        distance = PolygonMaxEdgeDistance(layer.vertices, p);
      }
      *near = std::abs(distance) < radius;
      *color = layer.color;
      return distance <= 0;
    }
    case LayerShape::kStripes: {
      RectangleTest(layer.min, layer.max, p, radius, &inside, near);
      const int axis = layer.axis;
      const double x = p[axis] - layer.min[axis];
      const double f = x - std::floor(x / layer.period) * layer.period;
      const bool in_region_or_near = inside || *near;
      if (in_region_or_near &&
          (std::min(f, layer.period - f) < radius || std::abs(f - layer.stripe_width) < radius)) {
        *near = true;
      }
      *color = layer.color;
      return inside && f <= layer.stripe_width;
    }
    case LayerShape::kCheckerboard: {
      RectangleTest(layer.min, layer.max, p, radius, &inside, near);
      if ((inside || *near) &&
          (DistanceToGrid(p.x() - layer.min.x(), layer.square_size) < radius ||
           DistanceToGrid(p.y() - layer.min.y(), layer.square_size) < radius)) {
        *near = true;
      }
      const int64_t i =
          static_cast<int64_t>(std::floor((p.x() - layer.min.x()) / layer.square_size));
      const int64_t j =
          static_cast<int64_t>(std::floor((p.y() - layer.min.y()) / layer.square_size));
      *color = ((i + j) % 2 == 0) ? layer.color : layer.color2;
      return inside;
    }
  }
  return false;
}

}  // namespace

float Luminance(const Color& color) {
  return 0.2126f * color[0] + 0.7152f * color[1] + 0.0722f * color[2];
}

std::string LayerShapeName(LayerShape shape) {
  switch (shape) {
    case LayerShape::kRectangle:
      return "rectangle";
    case LayerShape::kDisc:
      return "disc";
    case LayerShape::kPolygon:
      return "polygon";
    case LayerShape::kStripes:
      return "stripes";
    case LayerShape::kCheckerboard:
      return "checkerboard";
  }
  return "unknown";
}

TextureLayer TextureLayer::Rectangle(const Eigen::Vector2d& min, const Eigen::Vector2d& max,
                                     const Color& color) {
  TextureLayer layer;
  layer.shape = LayerShape::kRectangle;
  layer.min = min;
  layer.max = max;
  layer.color = color;
  return layer;
}

TextureLayer TextureLayer::Disc(const Eigen::Vector2d& center, double radius, const Color& color) {
  TextureLayer layer;
  layer.shape = LayerShape::kDisc;
  layer.center = center;
  layer.radius = radius;
  layer.color = color;
  return layer;
}

TextureLayer TextureLayer::Polygon(std::vector<Eigen::Vector2d> vertices, const Color& color) {
  TextureLayer layer;
  layer.shape = LayerShape::kPolygon;
  layer.vertices = std::move(vertices);
  layer.color = color;
  return layer;
}

TextureLayer TextureLayer::Line(const Eigen::Vector2d& a, const Eigen::Vector2d& b, double width,
                                const Color& color) {
  const Eigen::Vector2d direction = (b - a).normalized();
  const Eigen::Vector2d side = 0.5 * width * Eigen::Vector2d(-direction.y(), direction.x());
  return Polygon({a - side, b - side, b + side, a + side}, color);
}

TextureLayer TextureLayer::Stripes(const Eigen::Vector2d& min, const Eigen::Vector2d& max,
                                   double period, double stripe_width, int axis,
                                   const Color& color) {
  TextureLayer layer;
  layer.shape = LayerShape::kStripes;
  layer.min = min;
  layer.max = max;
  layer.period = period;
  layer.stripe_width = stripe_width;
  layer.axis = axis;
  layer.color = color;
  return layer;
}

TextureLayer TextureLayer::Checkerboard(const Eigen::Vector2d& min, const Eigen::Vector2d& max,
                                        double square_size, const Color& color,
                                        const Color& color2) {
  TextureLayer layer;
  layer.shape = LayerShape::kCheckerboard;
  layer.min = min;
  layer.max = max;
  layer.square_size = square_size;
  layer.color = color;
  layer.color2 = color2;
  return layer;
}

Eigen::AlignedBox2d TextureLayer::Bounds() const {
  switch (shape) {
    case LayerShape::kRectangle:
    case LayerShape::kStripes:
    case LayerShape::kCheckerboard:
      return Eigen::AlignedBox2d(min, max);
    case LayerShape::kDisc:
      return Eigen::AlignedBox2d(center - Eigen::Vector2d::Constant(radius),
                                 center + Eigen::Vector2d::Constant(radius));
    case LayerShape::kPolygon: {
      Eigen::AlignedBox2d box;
      for (const Eigen::Vector2d& vertex : vertices) box.extend(vertex);
      return box;
    }
  }
  return Eigen::AlignedBox2d();
}

void TextureLayer::Check(const std::string& where) const {
  const std::string prefix = where + " (" + LayerShapeName(shape) + "): ";
  if (!IsValidColor(color) || !IsValidColor(color2)) {
    throw InvalidArgumentError(prefix + "colours must be finite and within [0, 1]");
  }
  const bool needs_rectangle = shape == LayerShape::kRectangle || shape == LayerShape::kStripes ||
                               shape == LayerShape::kCheckerboard;
  if (needs_rectangle) {
    if (!IsFinite2(min) || !IsFinite2(max) || !(min.x() < max.x()) || !(min.y() < max.y())) {
      throw InvalidArgumentError(prefix + "min must be finite and strictly below max on both axes");
    }
  }
  switch (shape) {
    case LayerShape::kRectangle:
      break;
    case LayerShape::kDisc:
      if (!IsFinite2(center) || !std::isfinite(radius) || radius <= 0) {
        throw InvalidArgumentError(prefix + "needs a finite centre and a positive radius");
      }
      break;
    case LayerShape::kPolygon: {
      if (vertices.size() < 3) throw InvalidArgumentError(prefix + "needs at least 3 vertices");
      for (const Eigen::Vector2d& vertex : vertices) {
        if (!IsFinite2(vertex)) throw InvalidArgumentError(prefix + "has a non-finite vertex");
      }
      const double area = SignedArea(vertices);
      if (!(std::abs(area) > 1e-12)) throw InvalidArgumentError(prefix + "has zero area");
      const double sign = area > 0 ? 1.0 : -1.0;
      for (size_t i = 0; i < vertices.size(); ++i) {
        const Eigen::Vector2d& a = vertices[i];
        const Eigen::Vector2d& b = vertices[(i + 1) % vertices.size()];
        const Eigen::Vector2d& c = vertices[(i + 2) % vertices.size()];
        const Eigen::Vector2d ab = b - a;
        const Eigen::Vector2d bc = c - b;
        if ((b - a).norm() <= 1e-12) throw InvalidArgumentError(prefix + "has repeated vertices");
        if (sign * (ab.x() * bc.y() - ab.y() * bc.x()) < 0) {
          throw InvalidArgumentError(prefix + "is not convex at vertex " + std::to_string(i + 1));
        }
      }
      break;
    }
    case LayerShape::kStripes:
      if (!std::isfinite(period) || period <= 0 || !std::isfinite(stripe_width) ||
          stripe_width <= 0 || stripe_width >= period) {
        throw InvalidArgumentError(prefix + "needs period > 0 and 0 < width < period");
      }
      if (axis != 0 && axis != 1)
        throw InvalidArgumentError(prefix + "axis must be 0 (u) or 1 (v)");
      break;
    case LayerShape::kCheckerboard:
      if (!std::isfinite(square_size) || square_size <= 0) {
        throw InvalidArgumentError(prefix + "needs a positive square size");
      }
      break;
  }
}

Color Texture::ColorAt(const Eigen::Vector2d& uv) const {
  bool near = false;
  return ColorAt(uv, 0.0, &near);
}

Color Texture::ColorAt(const Eigen::Vector2d& uv, double radius, bool* near_boundary) const {
  *near_boundary = false;
  for (auto layer = layers.rbegin(); layer != layers.rend(); ++layer) {
    // Cheap rejection by the bounding box expanded by the radius.
    const Eigen::AlignedBox2d bounds = layer->Bounds();
    if (uv.x() < bounds.min().x() - radius || uv.x() > bounds.max().x() + radius ||
        uv.y() < bounds.min().y() - radius || uv.y() > bounds.max().y() + radius) {
      continue;
    }
    bool near = false;
    Color color;
    const bool inside = LayerTest(*layer, uv, radius, &near, &color);
    if (near) *near_boundary = true;
    // A point inside a layer and farther than `radius` from its boundary has its whole
    // footprint inside it: the layers below cannot matter.
    if (inside) return color;
  }
  return base;
}

void Texture::Check(const std::string& where) const {
  if (!IsValidColor(base)) {
    throw InvalidArgumentError(where + ": base colour must be finite and within [0, 1]");
  }
  for (size_t i = 0; i < layers.size(); ++i) {
    layers[i].Check(where + " layer " + std::to_string(i));
  }
}

IndexedTexture::IndexedTexture(const Texture& texture, double width, double height,
                               double cell_size, double max_radius)
    : texture_(&texture), cell_size_(cell_size), max_radius_(max_radius) {
  for (const TextureLayer& layer : texture.layers) {
    PreparedLayer prepared;
    prepared.layer = &layer;
    prepared.bounds = layer.Bounds();
    if (layer.shape == LayerShape::kPolygon) {
      const double orientation = SignedArea(layer.vertices) > 0 ? 1.0 : -1.0;
      for (size_t i = 0; i < layer.vertices.size(); ++i) {
        const Eigen::Vector2d& a = layer.vertices[i];
        const Eigen::Vector2d edge = layer.vertices[(i + 1) % layer.vertices.size()] - a;
        const Eigen::Vector2d outward =
            orientation * Eigen::Vector2d(edge.y(), -edge.x()) / edge.norm();
        prepared.edge_lines.emplace_back(outward.x(), outward.y(), outward.dot(a));
      }
    }
    layers_.push_back(std::move(prepared));
  }
  columns_ = std::max(1, static_cast<int>(std::ceil(width / cell_size_)));
  rows_ = std::max(1, static_cast<int>(std::ceil(height / cell_size_)));
  cells_.resize(static_cast<size_t>(columns_) * rows_);
  for (int i = 0; i < static_cast<int>(layers_.size()); ++i) {
    const Eigen::AlignedBox2d& box = layers_[i].bounds;
    const int c0 =
        std::max(0, static_cast<int>(std::floor((box.min().x() - max_radius_) / cell_size_)));
    const int c1 = std::min(
        columns_ - 1, static_cast<int>(std::floor((box.max().x() + max_radius_) / cell_size_)));
    const int r0 =
        std::max(0, static_cast<int>(std::floor((box.min().y() - max_radius_) / cell_size_)));
    const int r1 = std::min(
        rows_ - 1, static_cast<int>(std::floor((box.max().y() + max_radius_) / cell_size_)));
    for (int r = r0; r <= r1; ++r) {
      for (int c = c0; c <= c1; ++c) cells_[static_cast<size_t>(r) * columns_ + c].push_back(i);
    }
  }
}

Color IndexedTexture::ColorAt(const Eigen::Vector2d& uv) const {
  bool near = false;
  return ColorAt(uv, 0.0, &near);
}

Color IndexedTexture::ColorAt(const Eigen::Vector2d& uv, double radius, bool* near_boundary) const {
  const int column = static_cast<int>(std::floor(uv.x() / cell_size_));
  const int row = static_cast<int>(std::floor(uv.y() / cell_size_));
  const bool indexed =
      radius <= max_radius_ && column >= 0 && row >= 0 && column < columns_ && row < rows_;
  return Evaluate(uv, radius, near_boundary,
                  indexed ? &cells_[static_cast<size_t>(row) * columns_ + column] : nullptr);
}

Color IndexedTexture::Evaluate(const Eigen::Vector2d& uv, double radius, bool* near_boundary,
                               const std::vector<int>* cell) const {
  *near_boundary = false;
  const int count =
      cell != nullptr ? static_cast<int>(cell->size()) : static_cast<int>(layers_.size());
  for (int k = count - 1; k >= 0; --k) {
    const PreparedLayer& prepared = layers_[cell != nullptr ? (*cell)[k] : k];
    const Eigen::AlignedBox2d& bounds = prepared.bounds;
    if (uv.x() < bounds.min().x() - radius || uv.x() > bounds.max().x() + radius ||
        uv.y() < bounds.min().y() - radius || uv.y() > bounds.max().y() + radius) {
      continue;
    }
    bool near = false;
    Color color;
    const bool inside = LayerTest(*prepared.layer, uv, radius, &near, &color, &prepared.edge_lines);
    if (near) *near_boundary = true;
    if (inside) return color;
  }
  return texture_->base;
}

std::array<Eigen::Vector3d, 4> Surface::Corners() const {
  return {PointAt(0, 0), PointAt(width, 0), PointAt(width, height), PointAt(0, height)};
}

void Surface::Check() const {
  const std::string where = "surface '" + name + "'";
  if (!origin.allFinite() || !u_axis.allFinite() || !v_axis.allFinite()) {
    throw InvalidArgumentError(where + " has a non-finite origin or axis");
  }
  if (!std::isfinite(width) || !std::isfinite(height) || width <= 0 || height <= 0) {
    throw InvalidArgumentError(where + " is degenerate: width and height must be positive");
  }
  if (std::abs(u_axis.norm() - 1) > 1e-6 || std::abs(v_axis.norm() - 1) > 1e-6) {
    throw InvalidArgumentError(where + " has axes that are not unit vectors");
  }
  if (std::abs(u_axis.dot(v_axis)) > 1e-6) {
    throw InvalidArgumentError(where + " is degenerate: its u and v axes are not orthogonal");
  }
  if (!std::isfinite(shading) || shading <= 0 || shading > 1) {
    throw InvalidArgumentError(where + " has shading outside (0, 1]");
  }
  if (!std::isfinite(specular) || specular < 0 || specular > 1) {
    throw InvalidArgumentError(where + " has specular outside [0, 1]");
  }
  texture.Check(where + " texture");
}

float Lighting::ShadingFor(const Eigen::Vector3d& normal) const {
  return static_cast<float>(ambient + (1 - ambient) * std::max(0.0, normal.dot(towards_light)));
}

void Scene::UpdateBounds() {
  bounds.setEmpty();
  for (const Surface& surface : surfaces) {
    for (const Eigen::Vector3d& corner : surface.Corners()) bounds.extend(corner);
  }
}

float Scene::LightFactorAt(const Surface& surface, const Eigen::Vector3d& point,
                           const Eigen::Vector3d& viewer) const {
  double factor = daylight * surface.shading;
  if (point_lights.empty()) return static_cast<float>(factor);
  Eigen::Vector3d normal = surface.Normal();
  if (normal.dot(viewer - point) < 0) normal = -normal;
  for (const PointLight& light : point_lights) {
    const Eigen::Vector3d to_light = light.position - point;
    const double cosine_times_distance = normal.dot(to_light);
    if (cosine_times_distance <= 0) continue;
    const double distance_squared = std::max(to_light.squaredNorm(), 1e-6);
    factor +=
        light.intensity * cosine_times_distance / (distance_squared * std::sqrt(distance_squared));
  }
  return static_cast<float>(factor);
}

void Scene::Check() const {
  if (surfaces.empty()) throw InvalidArgumentError("scene '" + name + "' has no surface");
  if (!(daylight >= 0 && daylight <= 1) || !(sky >= 0 && sky <= 1)) {
    throw InvalidArgumentError("scene '" + name + "': daylight and sky must lie within [0, 1]");
  }
  for (size_t i = 0; i < point_lights.size(); ++i) {
    if (!point_lights[i].position.allFinite() || !std::isfinite(point_lights[i].intensity) ||
        point_lights[i].intensity < 0) {
      throw InvalidArgumentError("scene '" + name + "': point light " + std::to_string(i) +
                                 " needs a finite position and an intensity >= 0");
    }
  }
  for (const Surface& surface : surfaces) surface.Check();
  if (camera_region.isEmpty() || !camera_region.min().allFinite() ||
      !camera_region.max().allFinite()) {
    throw InvalidArgumentError("scene '" + name + "' has an empty or non-finite camera region");
  }
  if (!lighting.towards_light.allFinite() || std::abs(lighting.towards_light.norm() - 1) > 1e-6 ||
      !std::isfinite(lighting.ambient) || lighting.ambient <= 0 || lighting.ambient > 1) {
    throw InvalidArgumentError("scene '" + name +
                               "' lighting needs a unit light direction and ambient in (0, 1]");
  }
}

void AddBox(const BoxSpec& box, Scene* scene) {
  if (!box.center.allFinite() || !box.size.allFinite() || !std::isfinite(box.yaw) ||
      (box.size.array() <= 0).any()) {
    throw InvalidArgumentError("box '" + box.name +
                               "' needs a finite centre and yaw and a positive size");
  }
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(box.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d h = 0.5 * box.size;
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY(),
                        z = Eigen::Vector3d::UnitZ();
  struct Face {
    const char* suffix;
    Eigen::Vector3d origin, u, v;
    double width, height;
  };
  // Local origins (bottom-left corner seen from outside), u and v axes of each face.
  const Face faces[6] = {
      {"+x", Eigen::Vector3d(h.x(), -h.y(), -h.z()), y, z, box.size.y(), box.size.z()},
      {"-x", Eigen::Vector3d(-h.x(), h.y(), -h.z()), -y, z, box.size.y(), box.size.z()},
      {"+y", Eigen::Vector3d(h.x(), h.y(), -h.z()), -x, z, box.size.x(), box.size.z()},
      {"-y", Eigen::Vector3d(-h.x(), -h.y(), -h.z()), x, z, box.size.x(), box.size.z()},
      {"+z", Eigen::Vector3d(-h.x(), -h.y(), h.z()), x, y, box.size.x(), box.size.y()},
      {"-z", Eigen::Vector3d(-h.x(), h.y(), -h.z()), x, -y, box.size.x(), box.size.y()},
  };
  for (int i = 0; i < 6; ++i) {
    if (i == 5 && !box.bottom_face) continue;
    Surface surface;
    surface.name = box.name + "/" + faces[i].suffix;
    surface.origin = box.center + rotation * faces[i].origin;
    surface.u_axis = rotation * faces[i].u;
    surface.v_axis = rotation * faces[i].v;
    surface.width = faces[i].width;
    surface.height = faces[i].height;
    surface.shading = scene->lighting.ShadingFor(surface.Normal());
    surface.texture = box.face_textures[i];
    scene->surfaces.push_back(std::move(surface));
  }
}

namespace {

// Appends a poster: a frame, a background and text-like rows of word blocks.
void AddPoster(const Eigen::Vector2d& min, const Eigen::Vector2d& max, const Color& paper,
               const Color& ink, uint64_t seed, Texture* texture) {
  const Eigen::Vector2d border(0.02, 0.02);
  texture->layers.push_back(TextureLayer::Rectangle(min - border, max + border, Gray(0.12f)));
  texture->layers.push_back(TextureLayer::Rectangle(min, max, paper));
  LayoutRandom random(seed);
  const double line_height = 0.035, word_height = 0.018, margin = 0.05;
  // Title block, then lines of words from the top down (v up: start near max.y).
  texture->layers.push_back(TextureLayer::Rectangle(
      Eigen::Vector2d(min.x() + margin, max.y() - margin - 0.05),
      Eigen::Vector2d(min.x() + margin + 0.6 * (max.x() - min.x() - 2 * margin), max.y() - margin),
      ink));
  for (double top = max.y() - margin - 0.05 - line_height; top - word_height > min.y() + margin;
       top -= line_height) {
    double u = min.x() + margin;
    const double line_end = max.x() - margin - random.Uniform(0, 0.2) * (max.x() - min.x());
    while (true) {
      const double word = random.Uniform(0.02, 0.09);
      if (u + word > line_end) break;
      texture->layers.push_back(TextureLayer::Rectangle(Eigen::Vector2d(u, top - word_height),
                                                        Eigen::Vector2d(u + word, top), ink));
      u += word + random.Uniform(0.012, 0.02);
    }
  }
}

Surface MakeWall(const std::string& name, const Eigen::Vector3d& origin, const Eigen::Vector3d& u,
                 const Eigen::Vector3d& v, double width, double height, float shading,
                 Texture texture) {
  Surface surface;
  surface.name = name;
  surface.origin = origin;
  surface.u_axis = u;
  surface.v_axis = v;
  surface.width = width;
  surface.height = height;
  surface.shading = shading;
  surface.texture = std::move(texture);
  return surface;
}

std::array<Texture, 6> AllFaces(const Texture& texture) {
  std::array<Texture, 6> faces;
  faces.fill(texture);
  return faces;
}

}  // namespace

Scene MakeDefaultRoom() {
  Scene scene;
  scene.name = "default_room";
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY(),
                        z = Eigen::Vector3d::UnitZ();
  const double room_height = 2.5;

  // North wall (y = +2), seen from inside: u = +x, v = +z. Poster with text, a calibration
  // checkerboard, a thin horizontal rail and a thin diagonal line.
  {
    Texture texture;
    texture.base = Gray(0.62f);
    texture.layers.push_back(
        TextureLayer::Rectangle(Eigen::Vector2d(0, 0.9), Eigen::Vector2d(4, 0.912), Gray(0.15f)));
    AddPoster(Eigen::Vector2d(0.35, 1.05), Eigen::Vector2d(1.45, 1.8), Gray(0.9f), Gray(0.08f), 11,
              &texture);
    texture.layers.push_back(TextureLayer::Rectangle(Eigen::Vector2d(2.05, 1.0),
                                                     Eigen::Vector2d(2.95, 1.7), Gray(0.92f)));
    texture.layers.push_back(TextureLayer::Checkerboard(
        Eigen::Vector2d(2.1, 1.05), Eigen::Vector2d(2.9, 1.65), 0.1, Gray(0.05f), Gray(0.92f)));
    texture.layers.push_back(TextureLayer::Line(Eigen::Vector2d(3.1, 0.3),
                                                Eigen::Vector2d(3.8, 1.9), 0.008, Gray(0.1f)));
    texture.layers.push_back(
        TextureLayer::Disc(Eigen::Vector2d(3.55, 2.1), 0.15, Color(0.85f, 0.3f, 0.2f)));
    scene.surfaces.push_back(MakeWall("wall_north", Eigen::Vector3d(-2, 2, 0), x, z, 4, room_height,
                                      0.9f, std::move(texture)));
  }
  // East wall (x = +2): u = -y, v = +z. Repetitive vertical stripes and a door with a knob.
  {
    Texture texture;
    texture.base = Color(0.66f, 0.62f, 0.55f);
    texture.layers.push_back(TextureLayer::Stripes(Eigen::Vector2d(0.3, 0.25),
                                                   Eigen::Vector2d(2.3, 2.25), 0.12, 0.05, 0,
                                                   Color(0.3f, 0.33f, 0.45f)));
    texture.layers.push_back(TextureLayer::Rectangle(
        Eigen::Vector2d(2.7, 0), Eigen::Vector2d(3.6, 2.05), Color(0.35f, 0.22f, 0.12f)));
    texture.layers.push_back(TextureLayer::Rectangle(
        Eigen::Vector2d(2.8, 1.1), Eigen::Vector2d(3.5, 1.95), Color(0.42f, 0.27f, 0.15f)));
    texture.layers.push_back(TextureLayer::Disc(Eigen::Vector2d(3.45, 1.0), 0.03, Gray(0.85f)));
    scene.surfaces.push_back(MakeWall("wall_east", Eigen::Vector3d(2, 2, 0), -y, z, 4, room_height,
                                      0.75f, std::move(texture)));
  }
  // South wall (y = -2): u = -x, v = +z. Weak texture: low-contrast blobs, a picture with
  // coloured shapes, a thin-line grid.
  {
    Texture texture;
    texture.base = Gray(0.5f);
    const double blob_albedo[] = {0.55, 0.58, 0.45, 0.62, 0.53, 0.42};
    for (int i = 0; i < 6; ++i) {
      texture.layers.push_back(
          TextureLayer::Disc(Eigen::Vector2d(0.4 + 0.5 * i, 0.5 + 0.25 * (i % 3)),
                             0.12 + 0.03 * (i % 2), Gray(static_cast<float>(blob_albedo[i]))));
    }
    texture.layers.push_back(
        TextureLayer::Rectangle(Eigen::Vector2d(1.2, 1.1), Eigen::Vector2d(2.6, 2.0), Gray(0.12f)));
    texture.layers.push_back(TextureLayer::Rectangle(
        Eigen::Vector2d(1.23, 1.13), Eigen::Vector2d(2.57, 1.97), Color(0.55f, 0.75f, 0.9f)));
    texture.layers.push_back(TextureLayer::Polygon(
        {Eigen::Vector2d(1.3, 1.15), Eigen::Vector2d(1.9, 1.15), Eigen::Vector2d(1.6, 1.7)},
        Color(0.25f, 0.45f, 0.2f)));
    texture.layers.push_back(TextureLayer::Polygon(
        {Eigen::Vector2d(1.7, 1.15), Eigen::Vector2d(2.5, 1.15), Eigen::Vector2d(2.15, 1.8)},
        Color(0.18f, 0.35f, 0.15f)));
    texture.layers.push_back(
        TextureLayer::Disc(Eigen::Vector2d(2.35, 1.8), 0.08, Color(0.98f, 0.9f, 0.4f)));
    for (int i = 0; i < 5; ++i) {
      const double u = 2.9 + 0.15 * i;
      texture.layers.push_back(TextureLayer::Rectangle(
          Eigen::Vector2d(u, 0.8), Eigen::Vector2d(u + 0.006, 1.6), Gray(0.2f)));
      const double v = 0.8 + 0.2 * i;
      texture.layers.push_back(TextureLayer::Rectangle(
          Eigen::Vector2d(2.9, v), Eigen::Vector2d(3.606, v + 0.006), Gray(0.2f)));
    }
    scene.surfaces.push_back(MakeWall("wall_south", Eigen::Vector3d(2, -2, 0), -x, z, 4,
                                      room_height, 0.8f, std::move(texture)));
  }
  // West wall (x = -2): u = +y, v = +z. A whiteboard with thin hand-drawn lines and horizontal
  // stripes; shelves stand in front of it.
  {
    Texture texture;
    texture.base = Color(0.7f, 0.68f, 0.6f);
    texture.layers.push_back(TextureLayer::Rectangle(Eigen::Vector2d(1.25, 0.95),
                                                     Eigen::Vector2d(2.95, 1.95), Gray(0.3f)));
    texture.layers.push_back(TextureLayer::Rectangle(Eigen::Vector2d(1.28, 0.98),
                                                     Eigen::Vector2d(2.92, 1.92), Gray(0.93f)));
    LayoutRandom random(7);
    for (int i = 0; i < 12; ++i) {
      const Eigen::Vector2d a(random.Uniform(1.35, 2.6), random.Uniform(1.05, 1.85));
      const Eigen::Vector2d b =
          a + Eigen::Vector2d(random.Uniform(0.05, 0.3), random.Uniform(-0.06, 0.06));
      texture.layers.push_back(TextureLayer::Line(a, b, 0.005, Color(0.1f, 0.15f, 0.5f)));
    }
    texture.layers.push_back(TextureLayer::Stripes(
        Eigen::Vector2d(3.1, 0.2), Eigen::Vector2d(3.9, 2.2), 0.1, 0.03, 1, Gray(0.25f)));
    scene.surfaces.push_back(MakeWall("wall_west", Eigen::Vector3d(-2, -2, 0), y, z, 4, room_height,
                                      0.7f, std::move(texture)));
  }
  // Floor (z = 0): u = +x, v = +y. Low-contrast 0.5 m tiles and a rug with a striped border.
  {
    Texture texture;
    texture.layers.push_back(TextureLayer::Checkerboard(
        Eigen::Vector2d(0, 0), Eigen::Vector2d(4, 4), 0.5, Gray(0.36f), Gray(0.46f)));
    texture.layers.push_back(TextureLayer::Rectangle(
        Eigen::Vector2d(0.9, 0.7), Eigen::Vector2d(2.9, 2.1), Color(0.55f, 0.12f, 0.1f)));
    texture.layers.push_back(TextureLayer::Stripes(Eigen::Vector2d(1.0, 0.8),
                                                   Eigen::Vector2d(2.8, 2.0), 0.2, 0.04, 0,
                                                   Color(0.85f, 0.75f, 0.45f)));
    texture.layers.push_back(TextureLayer::Rectangle(
        Eigen::Vector2d(1.2, 1.0), Eigen::Vector2d(2.6, 1.8), Color(0.2f, 0.2f, 0.35f)));
    scene.surfaces.push_back(
        MakeWall("floor", Eigen::Vector3d(-2, -2, 0), x, y, 4, 4, 1.0f, std::move(texture)));
  }
  // Ceiling (z = 2.5): u = +x, v = -y. Two light panels.
  {
    Texture texture;
    texture.base = Gray(0.75f);
    texture.layers.push_back(
        TextureLayer::Rectangle(Eigen::Vector2d(0.8, 1.4), Eigen::Vector2d(1.4, 2.6), Gray(1.0f)));
    texture.layers.push_back(
        TextureLayer::Rectangle(Eigen::Vector2d(2.6, 1.4), Eigen::Vector2d(3.2, 2.6), Gray(1.0f)));
    scene.surfaces.push_back(MakeWall("ceiling", Eigen::Vector3d(-2, 2, room_height), x, -y, 4, 4,
                                      0.6f, std::move(texture)));
  }

  // Table: a top and four legs.
  const Eigen::Vector3d table_center(0.3, 0.6, 0.73);
  const Eigen::Vector3d table_size(1.4, 0.8, 0.04);
  {
    Texture wood;
    wood.base = Color(0.5f, 0.36f, 0.22f);
    Texture top = wood;
    for (int i = 0; i < 6; ++i) {
      top.layers.push_back(TextureLayer::Line(Eigen::Vector2d(0.02, 0.08 + 0.12 * i),
                                              Eigen::Vector2d(1.38, 0.1 + 0.12 * i), 0.004,
                                              Color(0.33f, 0.22f, 0.12f)));
    }
    AddPoster(Eigen::Vector2d(0.9, 0.1), Eigen::Vector2d(1.2, 0.52), Gray(0.95f), Gray(0.1f), 23,
              &top);
    BoxSpec table;
    table.name = "table_top";
    table.center = table_center;
    table.size = table_size;
    table.face_textures = AllFaces(wood);
    table.face_textures[4] = top;
    AddBox(table, &scene);
    // A varnished top: glossy for the simulated depth camera (its pattern is lost near the
    // mirror direction), invisible to the event and frame cameras.
    for (Surface& surface : scene.surfaces) {
      if (surface.name == "table_top/+z") surface.specular = 0.8f;
    }
    const double leg_height = table_center.z() - 0.5 * table_size.z();
    for (int i = 0; i < 4; ++i) {
      BoxSpec leg;
      leg.name = "table_leg" + std::to_string(i);
      leg.center = Eigen::Vector3d(table_center.x() + ((i & 1) ? 0.62 : -0.62),
                                   table_center.y() + ((i & 2) ? 0.32 : -0.32), 0.5 * leg_height);
      leg.size = Eigen::Vector3d(0.05, 0.05, leg_height);
      leg.face_textures = AllFaces(Texture{Gray(0.15f), {}});
      leg.bottom_face = false;
      AddBox(leg, &scene);
    }
  }
  const double table_surface = table_center.z() + 0.5 * table_size.z();
  // Boxes on the table.
  {
    Texture cardboard;
    cardboard.base = Color(0.72f, 0.55f, 0.35f);
    Texture logo = cardboard;
    logo.layers.push_back(TextureLayer::Disc(Eigen::Vector2d(0.1, 0.15), 0.06, Gray(0.1f)));
    logo.layers.push_back(TextureLayer::Stripes(
        Eigen::Vector2d(0.0, 0.02), Eigen::Vector2d(0.2, 0.07), 0.03, 0.015, 0, Gray(0.95f)));
    BoxSpec box;
    box.name = "box_a";
    box.center = Eigen::Vector3d(0.0, 0.45, table_surface + 0.125);
    box.size = Eigen::Vector3d(0.3, 0.2, 0.25);
    box.yaw = 0.3;
    box.face_textures = AllFaces(cardboard);
    box.face_textures[3] = logo;  // -y face
    box.face_textures[0] = logo;  // +x face
    box.bottom_face = false;
    AddBox(box, &scene);

    Texture checker;
    checker.base = Gray(0.9f);
    checker.layers.push_back(TextureLayer::Checkerboard(
        Eigen::Vector2d(0.02, 0.02), Eigen::Vector2d(0.18, 0.33), 0.04, Gray(0.08f), Gray(0.9f)));
    BoxSpec tall;
    tall.name = "box_b";
    tall.center = Eigen::Vector3d(0.55, 0.7, table_surface + 0.175);
    tall.size = Eigen::Vector3d(0.2, 0.2, 0.35);
    tall.yaw = -0.25;
    tall.face_textures = AllFaces(Texture{Color(0.2f, 0.35f, 0.6f), {}});
    tall.face_textures[3] = checker;
    tall.face_textures[1] = checker;
    tall.bottom_face = false;
    AddBox(tall, &scene);

    BoxSpec small;
    small.name = "box_c";
    small.center = Eigen::Vector3d(0.8, 0.35, table_surface + 0.05);
    small.size = Eigen::Vector3d(0.15, 0.1, 0.1);
    small.yaw = 0.8;
    small.face_textures = AllFaces(Texture{Color(0.85f, 0.8f, 0.2f), {}});
    small.bottom_face = false;
    AddBox(small, &scene);
  }
  // A crate on the floor.
  {
    Texture slats;
    slats.base = Color(0.6f, 0.45f, 0.28f);
    slats.layers.push_back(TextureLayer::Stripes(Eigen::Vector2d(0, 0), Eigen::Vector2d(0.6, 0.5),
                                                 0.125, 0.01, 1, Color(0.25f, 0.18f, 0.1f)));
    BoxSpec crate;
    crate.name = "crate";
    crate.center = Eigen::Vector3d(-1.2, -1.25, 0.25);
    crate.size = Eigen::Vector3d(0.6, 0.5, 0.5);
    crate.yaw = 0.5;
    crate.face_textures = AllFaces(slats);
    crate.bottom_face = false;
    AddBox(crate, &scene);
  }
  // Shelves against the west wall: two side panels, five planks, books (repetitive).
  {
    Texture panel{Gray(0.85f), {}};
    const double shelf_x = -1.8, depth = 0.35;
    for (int i = 0; i < 2; ++i) {
      BoxSpec side;
      side.name = "shelf_side" + std::to_string(i);
      side.center = Eigen::Vector3d(shelf_x, -1.0 + 1.04 * i, 0.8);
      side.size = Eigen::Vector3d(depth, 0.02, 1.6);
      side.face_textures = AllFaces(panel);
      side.bottom_face = false;
      AddBox(side, &scene);
    }
    const double plank_heights[] = {0.3, 0.65, 1.0, 1.35, 1.6};
    for (int i = 0; i < 5; ++i) {
      BoxSpec plank;
      plank.name = "shelf_plank" + std::to_string(i);
      plank.center = Eigen::Vector3d(shelf_x, -0.48, plank_heights[i]);
      plank.size = Eigen::Vector3d(depth, 1.02, 0.02);
      plank.face_textures = AllFaces(panel);
      AddBox(plank, &scene);
    }
    const Color book_colors[] = {Color(0.6f, 0.1f, 0.1f), Color(0.1f, 0.2f, 0.55f),
                                 Color(0.15f, 0.45f, 0.2f), Color(0.9f, 0.85f, 0.7f)};
    for (int shelf = 0; shelf < 3; ++shelf) {
      for (int i = 0; i < 4; ++i) {
        BoxSpec book;
        book.name = "book" + std::to_string(shelf) + "_" + std::to_string(i);
        const double book_height = 0.2 + 0.03 * ((i + shelf) % 3);
        book.center = Eigen::Vector3d(shelf_x + 0.03, -0.85 + 0.09 * i + 0.25 * shelf,
                                      plank_heights[shelf] + 0.01 + 0.5 * book_height);
        book.size = Eigen::Vector3d(0.22, 0.06, book_height);
        book.face_textures = AllFaces(Texture{book_colors[(i + shelf) % 4], {}});
        book.bottom_face = false;
        AddBox(book, &scene);
      }
    }
  }
  scene.UpdateBounds();
  // Free space from which the room is seen: above the crate, beside the table and the shelves.
  scene.camera_region =
      Eigen::AlignedBox3d(Eigen::Vector3d(-1.2, -1.6, 1.0), Eigen::Vector3d(1.6, -0.1, 1.9));
  return scene;
}

}  // namespace evloc::sim
