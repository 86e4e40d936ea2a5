// Scene JSON reading and writing (schema: docs/sim-scene.md, "Scene JSON").
#include <cmath>
#include <string>
#include <utility>

#include <nlohmann/json.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "tools/sim/scene.h"

namespace evloc::sim {
namespace {

using Json = nlohmann::json;

constexpr double kPi = 3.14159265358979323846;

// Reads typed values from a parsed document; errors name the source and the JSON pointer.
class JsonReader {
 public:
  explicit JsonReader(std::string source) : source_(std::move(source)) {}

  [[noreturn]] void Fail(const std::string& path, const std::string& what) const {
    throw ParseError(source_, path.empty() ? "/" : path, what);
  }

  const Json& Require(const Json& object, const std::string& key, const std::string& path) const {
    if (!object.is_object()) Fail(path, "expected an object");
    const auto it = object.find(key);
    if (it == object.end()) Fail(path, "missing required field '" + key + "'");
    return *it;
  }

  double Number(const Json& value, const std::string& path) const {
    if (!value.is_number()) Fail(path, "expected a number, got " + std::string(value.type_name()));
    const double number = value.get<double>();
    if (!std::isfinite(number)) Fail(path, "expected a finite number");
    return number;
  }

  double NumberField(const Json& object, const std::string& key, const std::string& path) const {
    return Number(Require(object, key, path), path + "/" + key);
  }

  std::string String(const Json& value, const std::string& path) const {
    if (!value.is_string()) Fail(path, "expected a string, got " + std::string(value.type_name()));
    return value.get<std::string>();
  }

  bool Bool(const Json& value, const std::string& path) const {
    if (!value.is_boolean())
      Fail(path, "expected true or false, got " + std::string(value.type_name()));
    return value.get<bool>();
  }

  template <int N>
  Eigen::Matrix<double, N, 1> Vector(const Json& value, const std::string& path) const {
    if (!value.is_array() || value.size() != N) {
      Fail(path, "expected an array of " + std::to_string(N) + " numbers");
    }
    Eigen::Matrix<double, N, 1> vector;
    for (int i = 0; i < N; ++i) vector[i] = Number(value[i], path + "/" + std::to_string(i));
    return vector;
  }

  template <int N>
  Eigen::Matrix<double, N, 1> VectorField(const Json& object, const std::string& key,
                                          const std::string& path) const {
    return Vector<N>(Require(object, key, path), path + "/" + key);
  }

  // A colour: a gray number or [r, g, b], each in [0, 1].
  Color ColorValue(const Json& value, const std::string& path) const {
    Color color;
    if (value.is_number()) {
      color = Gray(static_cast<float>(Number(value, path)));
    } else if (value.is_array() && value.size() == 3) {
      color = Vector<3>(value, path).cast<float>();
    } else {
      Fail(path, "expected a colour: a gray number or [r, g, b]");
    }
    if ((color.array() < 0.0f).any() || (color.array() > 1.0f).any()) {
      Fail(path, "colour components must lie within [0, 1]");
    }
    return color;
  }

  Color ColorField(const Json& object, const std::string& key, const std::string& path) const {
    return ColorValue(Require(object, key, path), path + "/" + key);
  }

  TextureLayer Layer(const Json& value, const std::string& path) const {
    const std::string shape = String(Require(value, "shape", path), path + "/shape");
    TextureLayer layer;
    if (shape == "rectangle") {
      layer = TextureLayer::Rectangle(VectorField<2>(value, "min", path),
                                      VectorField<2>(value, "max", path),
                                      ColorField(value, "color", path));
    } else if (shape == "disc") {
      layer =
          TextureLayer::Disc(VectorField<2>(value, "center", path),
                             NumberField(value, "radius", path), ColorField(value, "color", path));
    } else if (shape == "polygon") {
      const Json& vertices = Require(value, "vertices", path);
      if (!vertices.is_array()) Fail(path + "/vertices", "expected an array of [u, v] vertices");
      std::vector<Eigen::Vector2d> points;
      for (size_t i = 0; i < vertices.size(); ++i) {
        points.push_back(Vector<2>(vertices[i], path + "/vertices/" + std::to_string(i)));
      }
      layer = TextureLayer::Polygon(std::move(points), ColorField(value, "color", path));
    } else if (shape == "line") {
      const Eigen::Vector2d from = VectorField<2>(value, "from", path);
      const Eigen::Vector2d to = VectorField<2>(value, "to", path);
      const double width = NumberField(value, "width", path);
      if (!((to - from).norm() > 0) || !(width > 0)) {
        Fail(path, "a line needs distinct end points and a positive width");
      }
      layer = TextureLayer::Line(from, to, width, ColorField(value, "color", path));
    } else if (shape == "stripes") {
      const std::string axis = String(Require(value, "axis", path), path + "/axis");
      if (axis != "u" && axis != "v") Fail(path + "/axis", "expected \"u\" or \"v\"");
      layer = TextureLayer::Stripes(
          VectorField<2>(value, "min", path), VectorField<2>(value, "max", path),
          NumberField(value, "period", path), NumberField(value, "width", path),
          axis == "u" ? 0 : 1, ColorField(value, "color", path));
    } else if (shape == "checkerboard") {
      layer = TextureLayer::Checkerboard(
          VectorField<2>(value, "min", path), VectorField<2>(value, "max", path),
          NumberField(value, "square", path), ColorField(value, "color", path),
          ColorField(value, "color2", path));
    } else {
      Fail(path + "/shape", "unknown shape '" + shape +
                                "' (expected rectangle, disc, polygon, line, stripes or "
                                "checkerboard)");
    }
    try {
      layer.Check("layer");
    } catch (const InvalidArgumentError& error) {
      Fail(path, error.what());
    }
    return layer;
  }

  Texture TextureValue(const Json& value, const std::string& path) const {
    if (!value.is_object()) Fail(path, "expected a texture object");
    Texture texture;
    texture.base = ColorField(value, "base", path);
    if (const auto layers = value.find("layers"); layers != value.end()) {
      if (!layers->is_array()) Fail(path + "/layers", "expected an array of layers");
      for (size_t i = 0; i < layers->size(); ++i) {
        texture.layers.push_back(Layer((*layers)[i], path + "/layers/" + std::to_string(i)));
      }
    }
    return texture;
  }

  Eigen::AlignedBox3d Box(const Json& value, const std::string& path) const {
    const Eigen::Vector3d min = VectorField<3>(value, "min", path);
    const Eigen::Vector3d max = VectorField<3>(value, "max", path);
    if ((min.array() >= max.array()).any()) Fail(path, "min must be below max on every axis");
    return Eigen::AlignedBox3d(min, max);
  }

 private:
  std::string source_;
};

Json ColorToJson(const Color& color) {
  if (color[0] == color[1] && color[1] == color[2]) return color[0];
  return Json::array({color[0], color[1], color[2]});
}

template <typename Vector>
Json VectorToJson(const Vector& vector) {
  Json array = Json::array();
  for (int i = 0; i < vector.size(); ++i) array.push_back(vector[i]);
  return array;
}

Json LayerToJson(const TextureLayer& layer) {
  Json json;
  json["shape"] = LayerShapeName(layer.shape);
  json["color"] = ColorToJson(layer.color);
  switch (layer.shape) {
    case LayerShape::kRectangle:
      json["min"] = VectorToJson(layer.min);
      json["max"] = VectorToJson(layer.max);
      break;
    case LayerShape::kDisc:
      json["center"] = VectorToJson(layer.center);
      json["radius"] = layer.radius;
      break;
    case LayerShape::kPolygon: {
      Json vertices = Json::array();
      for (const Eigen::Vector2d& vertex : layer.vertices) vertices.push_back(VectorToJson(vertex));
      json["vertices"] = vertices;
      break;
    }
    case LayerShape::kStripes:
      json["min"] = VectorToJson(layer.min);
      json["max"] = VectorToJson(layer.max);
      json["period"] = layer.period;
      json["width"] = layer.stripe_width;
      json["axis"] = layer.axis == 0 ? "u" : "v";
      break;
    case LayerShape::kCheckerboard:
      json["min"] = VectorToJson(layer.min);
      json["max"] = VectorToJson(layer.max);
      json["square"] = layer.square_size;
      json["color2"] = ColorToJson(layer.color2);
      break;
  }
  return json;
}

Json TextureToJson(const Texture& texture) {
  Json json;
  json["base"] = ColorToJson(texture.base);
  json["layers"] = Json::array();
  for (const TextureLayer& layer : texture.layers) json["layers"].push_back(LayerToJson(layer));
  return json;
}

}  // namespace

Scene ParseSceneJson(const std::string& text, const std::string& source) {
  Json document;
  try {
    document = Json::parse(text);
  } catch (const Json::parse_error& error) {
    throw ParseError::AtByte(source, error.byte, std::string("invalid JSON: ") + error.what());
  }
  const JsonReader reader(source);
  if (!document.is_object()) reader.Fail("", "expected a scene object");
  Scene scene;
  if (const auto name = document.find("name"); name != document.end()) {
    scene.name = reader.String(*name, "/name");
  }
  if (const auto lighting = document.find("lighting"); lighting != document.end()) {
    const Eigen::Vector3d towards = reader.VectorField<3>(*lighting, "towards_light", "/lighting");
    if (!(towards.norm() > 0)) reader.Fail("/lighting/towards_light", "must be a non-zero vector");
    scene.lighting.towards_light = towards.normalized();
    scene.lighting.ambient = reader.NumberField(*lighting, "ambient", "/lighting");
    if (!(scene.lighting.ambient > 0 && scene.lighting.ambient <= 1)) {
      reader.Fail("/lighting/ambient", "must lie within (0, 1]");
    }
  }
  scene.camera_region = reader.Box(reader.Require(document, "camera_region", ""), "/camera_region");
  if (const auto daylight = document.find("daylight"); daylight != document.end()) {
    scene.daylight = reader.Number(*daylight, "/daylight");
    if (!(scene.daylight >= 0 && scene.daylight <= 1))
      reader.Fail("/daylight", "must lie within [0, 1]");
  }
  if (const auto sky = document.find("sky"); sky != document.end()) {
    scene.sky = reader.Number(*sky, "/sky");
    if (!(scene.sky >= 0 && scene.sky <= 1)) reader.Fail("/sky", "must lie within [0, 1]");
  }
  if (const auto lights = document.find("point_lights"); lights != document.end()) {
    if (!lights->is_array()) reader.Fail("/point_lights", "expected an array of point lights");
    for (size_t i = 0; i < lights->size(); ++i) {
      const std::string path = "/point_lights/" + std::to_string(i);
      PointLight light;
      light.position = reader.VectorField<3>((*lights)[i], "position", path);
      light.intensity = reader.NumberField((*lights)[i], "intensity", path);
      if (!(light.intensity >= 0)) reader.Fail(path + "/intensity", "must be >= 0");
      scene.point_lights.push_back(light);
    }
  }

  if (const auto quads = document.find("quads"); quads != document.end()) {
    if (!quads->is_array()) reader.Fail("/quads", "expected an array of quads");
    for (size_t i = 0; i < quads->size(); ++i) {
      const std::string path = "/quads/" + std::to_string(i);
      const Json& quad = (*quads)[i];
      Surface surface;
      surface.name = reader.String(reader.Require(quad, "name", path), path + "/name");
      surface.origin = reader.VectorField<3>(quad, "origin", path);
      const Eigen::Vector3d u = reader.VectorField<3>(quad, "u_axis", path);
      const Eigen::Vector3d v = reader.VectorField<3>(quad, "v_axis", path);
      surface.width = reader.NumberField(quad, "width", path);
      surface.height = reader.NumberField(quad, "height", path);
      if (!(u.norm() > 0) || !(v.norm() > 0)) {
        reader.Fail(path, "degenerate quad: u_axis and v_axis must be non-zero");
      }
      surface.u_axis = u.normalized();
      surface.v_axis = v.normalized();
      if (std::abs(surface.u_axis.dot(surface.v_axis)) > 1e-6) {
        reader.Fail(path, "degenerate quad: u_axis and v_axis must be orthogonal");
      }
      if (!(surface.width > 0) || !(surface.height > 0)) {
        reader.Fail(path, "degenerate quad: width and height must be positive");
      }
      if (const auto shading = quad.find("shading"); shading != quad.end()) {
        surface.shading = static_cast<float>(reader.Number(*shading, path + "/shading"));
      } else {
        surface.shading = scene.lighting.ShadingFor(surface.Normal());
      }
      if (const auto specular = quad.find("specular"); specular != quad.end()) {
        surface.specular = static_cast<float>(reader.Number(*specular, path + "/specular"));
      }
      surface.texture =
          reader.TextureValue(reader.Require(quad, "texture", path), path + "/texture");
      try {
        surface.Check();
      } catch (const InvalidArgumentError& error) {
        reader.Fail(path, error.what());
      }
      scene.surfaces.push_back(std::move(surface));
    }
  }
  if (const auto boxes = document.find("boxes"); boxes != document.end()) {
    if (!boxes->is_array()) reader.Fail("/boxes", "expected an array of boxes");
    static const char* kFaceNames[6] = {"+x", "-x", "+y", "-y", "+z", "-z"};
    for (size_t i = 0; i < boxes->size(); ++i) {
      const std::string path = "/boxes/" + std::to_string(i);
      const Json& value = (*boxes)[i];
      BoxSpec box;
      box.name = reader.String(reader.Require(value, "name", path), path + "/name");
      box.center = reader.VectorField<3>(value, "center", path);
      box.size = reader.VectorField<3>(value, "size", path);
      if ((box.size.array() <= 0).any())
        reader.Fail(path + "/size", "must be positive on every axis");
      if (const auto yaw = value.find("yaw_deg"); yaw != value.end()) {
        box.yaw = reader.Number(*yaw, path + "/yaw_deg") * kPi / 180.0;
      }
      if (const auto bottom = value.find("bottom_face"); bottom != value.end()) {
        box.bottom_face = reader.Bool(*bottom, path + "/bottom_face");
      }
      box.face_textures.fill(
          reader.TextureValue(reader.Require(value, "texture", path), path + "/texture"));
      if (const auto faces = value.find("face_textures"); faces != value.end()) {
        if (!faces->is_object()) reader.Fail(path + "/face_textures", "expected an object");
        for (const auto& [key, texture] : faces->items()) {
          int face = -1;
          for (int f = 0; f < 6; ++f) {
            if (key == kFaceNames[f]) face = f;
          }
          if (face < 0) {
            reader.Fail(path + "/face_textures/" + key,
                        "unknown face (expected +x, -x, +y, -y, +z or -z)");
          }
          box.face_textures[face] = reader.TextureValue(texture, path + "/face_textures/" + key);
        }
      }
      AddBox(box, &scene);
    }
  }
  if (scene.surfaces.empty()) reader.Fail("", "the scene has no quads and no boxes");
  scene.UpdateBounds();
  return scene;
}

Scene LoadSceneJson(const std::filesystem::path& path) {
  return ParseSceneJson(ReadFileToString(path), path.string());
}

std::string SceneToJson(const Scene& scene) {
  Json document;
  document["name"] = scene.name;
  document["lighting"] = {{"towards_light", VectorToJson(scene.lighting.towards_light)},
                          {"ambient", scene.lighting.ambient}};
  document["camera_region"] = {{"min", VectorToJson(scene.camera_region.min())},
                               {"max", VectorToJson(scene.camera_region.max())}};
  document["daylight"] = scene.daylight;
  document["sky"] = scene.sky;
  document["point_lights"] = Json::array();
  for (const PointLight& light : scene.point_lights) {
    document["point_lights"].push_back(
        {{"position", VectorToJson(light.position)}, {"intensity", light.intensity}});
  }
  document["quads"] = Json::array();
  for (const Surface& surface : scene.surfaces) {
    Json quad;
    quad["name"] = surface.name;
    quad["origin"] = VectorToJson(surface.origin);
    quad["u_axis"] = VectorToJson(surface.u_axis);
    quad["v_axis"] = VectorToJson(surface.v_axis);
    quad["width"] = surface.width;
    quad["height"] = surface.height;
    quad["shading"] = surface.shading;
    if (surface.specular != 0.0f) quad["specular"] = surface.specular;
    quad["texture"] = TextureToJson(surface.texture);
    document["quads"].push_back(std::move(quad));
  }
  return document.dump(1) + "\n";
}

void SaveSceneJson(const std::filesystem::path& path, const Scene& scene) {
  WriteFileAtomically(path, SceneToJson(scene));
}

}  // namespace evloc::sim
