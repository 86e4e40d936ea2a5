#include "tools/sim/carpark.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

// Layout constants (metres): a module is a bay row, a lane, a bay row and an island.
constexpr double kBayWidth = 2.5;
constexpr double kBayDepth = 5.0;
constexpr double kLaneWidth = 7.0;
constexpr double kIslandWidth = 3.0;
constexpr double kModuleDepth = 2 * kBayDepth + kLaneWidth + kIslandWidth;  // 20 m
constexpr double kSiteHalf = 100.0;
constexpr double kLineWidth = 0.12;
constexpr double kKerbHeight = 0.15;
constexpr double kLampHeight = 6.0;
// Night intensity of a lamp: irradiance 0.4 right under it (5.9 m below the light).
constexpr double kLampIntensity = 14.0;

const Color kAsphalt = Gray(0.10f);
const Color kPatch = Gray(0.075f);
const Color kPaint = Gray(0.75f);
const Color kGrass(0.10f, 0.22f, 0.07f);
const Color kKerbStone = Gray(0.42f);

TextureLayer Shifted(TextureLayer layer, const Vector2d& offset) {
  layer.min += offset;
  layer.max += offset;
  layer.center += offset;
  for (Vector2d& vertex : layer.vertices) vertex += offset;
  return layer;
}

// An arrow on the ground pointing along +x (direction +1) or -x (-1), centred at `center`.
void AddArrow(const Vector2d& center, int direction, std::vector<TextureLayer>* layers) {
  const double d = direction;
  layers->push_back(TextureLayer::Rectangle(center + Vector2d(-1.5, -0.15),
                                            center + Vector2d(1.5, 0.15), kPaint));
  // The shaft's end under the head is covered by the triangle.
  layers->push_back(
      TextureLayer::Polygon({center + Vector2d(d * 1.3, -0.6), center + Vector2d(d * 2.6, 0.0),
                             center + Vector2d(d * 1.3, 0.6)},
                            kPaint));
}

// A box resting on the ground (no bottom face).
BoxSpec GroundBox(const std::string& name, const Vector3d& min, const Vector3d& max, double yaw,
                  const Texture& texture) {
  BoxSpec box;
  box.name = name;
  box.center = 0.5 * (min + max);
  box.size = max - min;
  box.yaw = yaw;
  box.bottom_face = false;
  box.face_textures.fill(texture);
  return box;
}

Color PickCarColor(LayoutRandom* random) {
  static const Color kColors[] = {Gray(0.8f),
                                  Gray(0.55f),
                                  Gray(0.05f),
                                  Color(0.6f, 0.06f, 0.05f),
                                  Color(0.08f, 0.15f, 0.45f),
                                  Gray(0.3f),
                                  Color(0.7f, 0.65f, 0.5f)};
  const int index = std::min(6, static_cast<int>(random->Uniform(0, 7)));
  return kColors[index];
}

// A parked car: a body (with wheels, lights and a number plate painted on it) and a cabin with
// windows on top. `center` is on the ground; the car's length lies along `yaw` (world).
void AddCar(const std::string& name, const Vector2d& center, double yaw, LayoutRandom* random,
            Scene* scene) {
  const double length = random->Uniform(4.0, 4.7), width = random->Uniform(1.7, 1.9);
  const double body_height = random->Uniform(0.75, 0.9);
  const Color paint = PickCarColor(random);
  const Color dark = Gray(0.03f), glass = Gray(0.06f), light = Gray(0.85f);
  BoxSpec body;
  body.name = name + "/body";
  body.center = Vector3d(center.x(), center.y(), body_height / 2);
  body.size = Vector3d(length, width, body_height);
  body.yaw = yaw;
  body.bottom_face = false;
  Texture plain;
  plain.base = paint;
  body.face_textures.fill(plain);
  // Side faces (+y, -y): u along the length, v up; wheels as discs, a sill stripe.
  for (int face : {2, 3}) {
    Texture& side = body.face_textures[face];
    side.layers.push_back(
        TextureLayer::Rectangle(Vector2d(0, 0), Vector2d(length, 0.12), Gray(0.08f)));
    for (double u : {0.8, length - 0.8}) {
      side.layers.push_back(TextureLayer::Disc(Vector2d(u, 0.32), 0.32, dark));
      side.layers.push_back(TextureLayer::Disc(Vector2d(u, 0.32), 0.16, Gray(0.45f)));
    }
  }
  // Front (+x) and back (-x): u along the width, v up; lights and a plate.
  for (int face : {0, 1}) {
    Texture& end = body.face_textures[face];
    const Color lamp = face == 0 ? light : Color(0.55f, 0.05f, 0.03f);
    end.layers.push_back(TextureLayer::Rectangle(Vector2d(0.12, body_height - 0.3),
                                                 Vector2d(0.45, body_height - 0.14), lamp));
    end.layers.push_back(TextureLayer::Rectangle(Vector2d(width - 0.45, body_height - 0.3),
                                                 Vector2d(width - 0.12, body_height - 0.14), lamp));
    end.layers.push_back(TextureLayer::Rectangle(Vector2d(width / 2 - 0.26, 0.2),
                                                 Vector2d(width / 2 + 0.26, 0.31), Gray(0.9f)));
  }
  AddBox(body, scene);

  const double cabin_length = length * random->Uniform(0.48, 0.56);
  const double cabin_height = random->Uniform(0.5, 0.6);
  BoxSpec cabin;
  cabin.name = name + "/cabin";
  const Vector2d offset = Vector2d(std::cos(yaw), std::sin(yaw)) * (-0.1 * length);
  cabin.center =
      Vector3d(center.x() + offset.x(), center.y() + offset.y(), body_height + cabin_height / 2);
  cabin.size = Vector3d(cabin_length, width - 0.12, cabin_height);
  cabin.yaw = yaw;
  cabin.bottom_face = false;
  cabin.face_textures.fill(plain);
  for (int face : {2, 3}) {
    Texture& side = cabin.face_textures[face];
    const double pillar = 0.12, middle = cabin_length * random->Uniform(0.45, 0.55);
    side.layers.push_back(TextureLayer::Rectangle(
        Vector2d(pillar, 0.08), Vector2d(middle - pillar / 2, cabin_height - 0.06), glass));
    side.layers.push_back(
        TextureLayer::Rectangle(Vector2d(middle + pillar / 2, 0.08),
                                Vector2d(cabin_length - pillar, cabin_height - 0.06), glass));
  }
  for (int face : {0, 1}) {
    cabin.face_textures[face].layers.push_back(TextureLayer::Rectangle(
        Vector2d(0.1, 0.06), Vector2d(width - 0.22, cabin_height - 0.06), glass));
  }
  AddBox(cabin, scene);
}

void AddLampPost(const std::string& name, const Vector2d& base, double ground_z, Scene* scene,
                 std::vector<PointLight>* lamps) {
  Texture metal;
  metal.base = Gray(0.45f);
  AddBox(GroundBox(name + "/pole", Vector3d(base.x() - 0.08, base.y() - 0.08, ground_z),
                   Vector3d(base.x() + 0.08, base.y() + 0.08, ground_z + kLampHeight), 0, metal),
         scene);
  BoxSpec head = GroundBox(name + "/head", Vector3d(base.x() - 0.45, base.y() - 0.18, 0),
                           Vector3d(base.x() + 0.45, base.y() + 0.18, 0.18), 0, metal);
  head.center.z() = ground_z + kLampHeight + 0.09;
  head.bottom_face = true;
  head.face_textures[5].base = Gray(0.25f);
  head.face_textures[5].layers.push_back(
      TextureLayer::Rectangle(Vector2d(0.1, 0.06), Vector2d(0.8, 0.3), Gray(0.95f)));
  AddBox(head, scene);
  PointLight lamp;
  lamp.position = Vector3d(base.x(), base.y(), ground_z + kLampHeight - 0.1);
  lamp.intensity = kLampIntensity;
  lamps->push_back(lamp);
}

void AddTree(const std::string& name, const Vector2d& base, double ground_z, LayoutRandom* random,
             Scene* scene) {
  Texture bark;
  bark.base = Color(0.25f, 0.17f, 0.10f);
  const double trunk = random->Uniform(2.0, 2.6);
  AddBox(GroundBox(name + "/trunk", Vector3d(base.x() - 0.17, base.y() - 0.17, ground_z),
                   Vector3d(base.x() + 0.17, base.y() + 0.17, ground_z + trunk), 0, bark),
         scene);
  const double side = random->Uniform(2.6, 3.4), height = random->Uniform(2.4, 3.2);
  BoxSpec crown;
  crown.name = name + "/crown";
  crown.center = Vector3d(base.x(), base.y(), ground_z + trunk + height / 2);
  crown.size = Vector3d(side, side, height);
  crown.yaw = random->Uniform(0, M_PI / 2);
  crown.bottom_face = true;
  for (int face = 0; face < 6; ++face) {
    Texture& leaves = crown.face_textures[face];
    leaves.base = Color(0.08f, 0.2f, 0.06f);
    // Leaf clusters: lighter discs spread over the face.
    const double extent_v = face < 4 ? height : side;
    for (int k = 0; k < 6; ++k) {
      const Vector2d centre(random->Uniform(0.4, side - 0.4), random->Uniform(0.4, extent_v - 0.4));
      leaves.layers.push_back(
          TextureLayer::Disc(centre, random->Uniform(0.15, 0.35), Color(0.16f, 0.36f, 0.10f)));
    }
  }
  AddBox(crown, scene);
}

// A building: a box with windows on every side face and doors on the south face.
void AddBuilding(const std::string& name, const Vector3d& min, const Vector3d& max,
                 LayoutRandom* random, Scene* scene) {
  static const Color kFacades[] = {Color(0.45f, 0.25f, 0.18f), Gray(0.55f),
                                   Color(0.62f, 0.58f, 0.48f), Gray(0.35f)};
  const Color facade = kFacades[std::min(3, static_cast<int>(random->Uniform(0, 4)))];
  BoxSpec box = GroundBox(name, min, max, 0, Texture{});
  const Vector3d size = max - min;
  const double storey = 3.5;
  const int storeys = static_cast<int>(size.z() / storey);
  const double window_w = random->Uniform(1.0, 1.6), spacing = random->Uniform(2.6, 3.4);
  for (int face = 0; face < 4; ++face) {
    Texture& texture = box.face_textures[face];
    texture.base = facade;
    const double face_width = face < 2 ? size.y() : size.x();
    // A plinth and a cornice.
    texture.layers.push_back(
        TextureLayer::Rectangle(Vector2d(0, 0), Vector2d(face_width, 0.5), facade * 0.6f));
    texture.layers.push_back(TextureLayer::Rectangle(Vector2d(0, size.z() - 0.4),
                                                     Vector2d(face_width, size.z()), Gray(0.8f)));
    const int columns = static_cast<int>((face_width - 2) / spacing);
    const double start = (face_width - (columns - 1) * spacing) / 2;
    for (int floor = 0; floor < storeys; ++floor) {
      for (int c = 0; c < columns; ++c) {
        const double u = start + c * spacing;
        const bool door = face == 3 && floor == 0 && c % 5 == 2;
        if (door) {
          texture.layers.push_back(TextureLayer::Rectangle(
              Vector2d(u - 0.75, 0.0), Vector2d(u + 0.75, 2.3), Color(0.3f, 0.2f, 0.12f)));
          texture.layers.push_back(TextureLayer::Rectangle(Vector2d(u - 0.05, 0.0),
                                                           Vector2d(u + 0.05, 2.2), Gray(0.1f)));
          continue;
        }
        const double v0 = floor * storey + 1.0;
        texture.layers.push_back(
            TextureLayer::Rectangle(Vector2d(u - window_w / 2 - 0.08, v0 - 0.08),
                                    Vector2d(u + window_w / 2 + 0.08, v0 + 1.58), Gray(0.85f)));
        texture.layers.push_back(TextureLayer::Rectangle(Vector2d(u - window_w / 2, v0),
                                                         Vector2d(u + window_w / 2, v0 + 1.5),
                                                         Color(0.08f, 0.1f, 0.13f)));
      }
    }
  }
  box.face_textures[4].base = Gray(0.3f);
  AddBox(box, scene);
}

// Appends a half circle of radius `radius` from `from` (heading along `heading` = +-x) turning
// north, ending `2 radius` north of it, sampled every 0.1 m.
void AppendHalfTurn(const Vector2d& from, int heading, double radius,
                    std::vector<Eigen::Vector2d>* route) {
  const Vector2d centre = from + Vector2d(0, radius);
  const int steps = static_cast<int>(std::ceil(M_PI * radius / 0.1));
  for (int k = 1; k <= steps; ++k) {
    const double angle = -M_PI / 2 + M_PI * k / steps;  // from south of the centre via the end
    route->push_back(centre + radius * Vector2d(heading * std::cos(angle), std::sin(angle)));
  }
}

}  // namespace

void CarParkOptions::Check() const {
  if (modules < 1 || bays_per_row < 4) {
    throw InvalidArgumentError("CarParkOptions: needs at least 1 module and 4 bays per row");
  }
  if (!(occupancy >= 0 && occupancy <= 1)) {
    throw InvalidArgumentError("CarParkOptions.occupancy must lie within [0, 1]");
  }
  if (!(ground_tile_m > 0) || !std::isfinite(ground_tile_m)) {
    throw InvalidArgumentError("CarParkOptions.ground_tile_m must be positive");
  }
  if (!(ground_marks_per_m2 >= 0 && ground_marks_per_m2 <= 20)) {
    throw InvalidArgumentError("the ground marks per square metre must lie within [0, 20]");
  }
}

std::vector<Eigen::Vector2d> ResamplePolyline(const std::vector<Eigen::Vector2d>& points,
                                              double spacing) {
  if (!(spacing > 0)) throw InvalidArgumentError("ResamplePolyline: spacing must be positive");
  std::vector<Eigen::Vector2d> out;
  if (points.empty()) return out;
  out.push_back(points.front());
  double carried = 0;  // length since the last output point
  for (size_t i = 1; i < points.size(); ++i) {
    const Vector2d a = points[i - 1], b = points[i];
    const double length = (b - a).norm();
    double s = spacing - carried;
    while (s <= length) {
      out.push_back(a + (b - a) * (s / length));
      s += spacing;
    }
    carried = length - (s - spacing);
  }
  if ((out.back() - points.back()).norm() > 1e-9) out.push_back(points.back());
  return out;
}

CarPark MakeCarPark(const CarParkOptions& options) {
  options.Check();
  LayoutRandom random(options.seed * 7919 + 17);
  CarPark park;
  Scene& scene = park.scene;
  scene.name = "carpark";
  scene.sky = 0.8;
  const double bays_length = options.bays_per_row * kBayWidth;
  park.bays_min_x = -bays_length / 2;
  park.bays_max_x = bays_length / 2;
  const double south = -kSiteHalf + 12;  // first module's south edge

  std::vector<TextureLayer> paint;  // world (x, y) coordinates
  // Repair patches in the asphalt (low contrast).
  for (int k = 0; k < 60; ++k) {
    const Vector2d corner(random.Uniform(-kSiteHalf + 2, kSiteHalf - 8),
                          random.Uniform(-kSiteHalf + 2, kSiteHalf - 8));
    paint.push_back(TextureLayer::Rectangle(
        corner, corner + Vector2d(random.Uniform(0.8, 4), random.Uniform(0.8, 3)), kPatch));
  }
  // Marks on the asphalt (opt-in), from their own random sequence.
  if (options.ground_marks_per_m2 > 0) {
    LayoutRandom marks(options.seed * 104729 + 31);
    const double side = 2 * kSiteHalf;
    const int count = static_cast<int>(std::lround(options.ground_marks_per_m2 * side * side));
    for (int k = 0; k < count; ++k) {
      const Vector2d centre(marks.Uniform(-kSiteHalf + 0.5, kSiteHalf - 0.5),
                            marks.Uniform(-kSiteHalf + 0.5, kSiteHalf - 0.5));
      const float grey = static_cast<float>(marks.Uniform(0.05, 0.17));
      const double size = marks.Uniform(0.05, 0.5);
      if (marks.Uniform(0, 1) < 0.6) {
        paint.push_back(TextureLayer::Disc(centre, size / 2, Gray(grey)));
      } else {
        const Vector2d half(size / 2, size * marks.Uniform(0.2, 0.6));
        paint.push_back(TextureLayer::Rectangle(centre - half, centre + half, Gray(grey)));
      }
    }
  }
  std::vector<BoxSpec> islands;
  for (int m = 0; m < options.modules; ++m) {
    const double y0 = south + m * kModuleDepth;
    const double lane_y = y0 + kBayDepth + kLaneWidth / 2;
    park.lane_y.push_back(lane_y);
    for (int row = 0; row < 2; ++row) {
      const double row_y0 = row == 0 ? y0 : y0 + kBayDepth + kLaneWidth;
      // Bay separator lines, and the line at the back of each row.
      for (int k = 0; k <= options.bays_per_row; ++k) {
        const double x = park.bays_min_x + k * kBayWidth;
        paint.push_back(TextureLayer::Rectangle(Vector2d(x - kLineWidth / 2, row_y0),
                                                Vector2d(x + kLineWidth / 2, row_y0 + kBayDepth),
                                                kPaint));
      }
      const double end_y = row == 0 ? row_y0 + kBayDepth : row_y0;
      paint.push_back(TextureLayer::Rectangle(Vector2d(park.bays_min_x, end_y - kLineWidth / 2),
                                              Vector2d(park.bays_max_x, end_y + kLineWidth / 2),
                                              kPaint));
      // Parked cars.
      for (int k = 0; k < options.bays_per_row; ++k) {
        if (random.Uniform(0, 1) >= options.occupancy) continue;
        const Vector2d centre(park.bays_min_x + (k + 0.5) * kBayWidth + random.Uniform(-0.2, 0.2),
                              row_y0 + kBayDepth / 2 + random.Uniform(-0.1, 0.1));
        const double yaw =
            (random.Uniform(0, 1) < 0.5 ? M_PI / 2 : -M_PI / 2) + random.Uniform(-0.04, 0.04);
        AddCar("car_" + std::to_string(m) + "_" + std::to_string(row) + "_" + std::to_string(k),
               centre, yaw, &random, &scene);
      }
    }
    // Lane: dashed centre line and arrows in the driving direction of the serpentine route.
    const int direction = m % 2 == 0 ? 1 : -1;
    for (double x = park.bays_min_x + 2; x + 3 <= park.bays_max_x - 2; x += 6) {
      paint.push_back(TextureLayer::Rectangle(Vector2d(x, lane_y - kLineWidth / 2),
                                              Vector2d(x + 3, lane_y + kLineWidth / 2), kPaint));
    }
    for (double x = park.bays_min_x + 15; x < park.bays_max_x - 10; x += 40) {
      AddArrow(Vector2d(x, lane_y - direction * 1.75), direction, &paint);
      AddArrow(Vector2d(x + 20, lane_y + direction * 1.75), -direction, &paint);
    }
    // Island north of the module (not after the last one: the buildings' forecourt is there).
    const double island_y0 = y0 + 2 * kBayDepth + kLaneWidth;
    Texture island;
    island.base = kGrass;
    BoxSpec island_box =
        GroundBox("island_" + std::to_string(m), Vector3d(park.bays_min_x, island_y0, 0),
                  Vector3d(park.bays_max_x, island_y0 + kIslandWidth, kKerbHeight), 0, island);
    island_box.face_textures.fill(Texture{kKerbStone, {}});
    island_box.face_textures[4].base = kGrass;
    island_box.face_textures[4].layers = {
        TextureLayer::Rectangle(Vector2d(0, 0), Vector2d(bays_length, 0.25), kKerbStone),
        TextureLayer::Rectangle(Vector2d(0, kIslandWidth - 0.25),
                                Vector2d(bays_length, kIslandWidth), kKerbStone)};
    islands.push_back(island_box);
    const double island_y = island_y0 + kIslandWidth / 2;
    for (double x = park.bays_min_x + 8; x < park.bays_max_x - 4; x += 24) {
      AddLampPost("lamp_" + std::to_string(m) + "_" + std::to_string(static_cast<int>(x)),
                  Vector2d(x, island_y), kKerbHeight, &scene, &park.lamps);
      if (x + 12 < park.bays_max_x - 3) {
        AddTree("tree_" + std::to_string(m) + "_" + std::to_string(static_cast<int>(x)),
                Vector2d(x + 12, island_y), kKerbHeight, &random, &scene);
      }
    }
  }
  for (const BoxSpec& island : islands) AddBox(island, &scene);

  // Zebra crossings across every lane at both ends of the bays, and a boundary wall (pillars and a
  // coping) along the south, east and west edges: what a driver sees at a lane end.
  for (double lane_y : park.lane_y) {
    for (double x0 : {park.bays_min_x - 4.5, park.bays_max_x + 0.5}) {
      paint.push_back(TextureLayer::Stripes(Vector2d(x0, lane_y - kLaneWidth / 2),
                                            Vector2d(x0 + 4, lane_y + kLaneWidth / 2), 1.0, 0.5, 1,
                                            kPaint));
    }
  }
  const double wall_height = 1.6, wall_thickness = 0.3;
  Texture wall;
  wall.base = Color(0.5f, 0.32f, 0.24f);
  // A coping band along the top (no brick courses: a fine repetitive pattern facing the
  // direction of travel makes the distance to the wall ambiguous, docs/sim-scene.md).
  wall.layers.push_back(TextureLayer::Rectangle(Vector2d(0, wall_height - 0.15),
                                                Vector2d(2 * kSiteHalf, wall_height),
                                                Color(0.7f, 0.65f, 0.6f)));
  for (double u = 0; u < 2 * kSiteHalf; u += 4) {
    wall.layers.push_back(
        TextureLayer::Rectangle(Vector2d(u, 0), Vector2d(u + 0.4, wall_height), Gray(0.6f)));
  }
  wall.layers.push_back(
      TextureLayer::Rectangle(Vector2d(0, 0), Vector2d(2 * kSiteHalf, 0.3), Gray(0.35f)));
  const double inner = kSiteHalf - 0.5;
  AddBox(GroundBox("wall_south", Vector3d(-inner, -inner, 0),
                   Vector3d(inner, -inner + wall_thickness, wall_height), 0, wall),
         &scene);
  AddBox(GroundBox("wall_east", Vector3d(inner - wall_thickness, -inner + wall_thickness, 0),
                   Vector3d(inner, south + options.modules * kModuleDepth, wall_height), 0, wall),
         &scene);
  AddBox(GroundBox(
             "wall_west", Vector3d(-inner, -inner + wall_thickness, 0),
             Vector3d(-inner + wall_thickness, south + options.modules * kModuleDepth, wall_height),
             0, wall),
         &scene);

  // Buildings along the north edge, trees along the south, east and west edges.
  const double north = south + options.modules * kModuleDepth + 6;
  for (double x = -kSiteHalf + 5; x + 20 <= kSiteHalf - 5;) {
    const double width = random.Uniform(28, 42);
    const double right = std::min(x + width, kSiteHalf - 5);
    const double height = 3.5 * std::floor(random.Uniform(3, 5)) + 0.6;
    AddBuilding("building_" + std::to_string(static_cast<int>(x)), Vector3d(x, north, 0),
                Vector3d(right, north + random.Uniform(12, 16), height), &random, &scene);
    x = right + random.Uniform(5, 9);
  }
  for (double t = -kSiteHalf + 4; t < kSiteHalf - 4; t += 10) {
    AddTree("tree_s_" + std::to_string(static_cast<int>(t)), Vector2d(t, -kSiteHalf + 3.5), 0,
            &random, &scene);
    if (t < north - 4) {
      AddTree("tree_e_" + std::to_string(static_cast<int>(t)), Vector2d(kSiteHalf - 3.2, t), 0,
              &random, &scene);
      AddTree("tree_w_" + std::to_string(static_cast<int>(t)), Vector2d(-kSiteHalf + 3.2, t), 0,
              &random, &scene);
    }
  }

  // The ground: square asphalt tiles, each with the paint that overlaps it.
  const int tiles = static_cast<int>(std::ceil(2 * kSiteHalf / options.ground_tile_m));
  const double tile = 2 * kSiteHalf / tiles;
  for (int j = 0; j < tiles; ++j) {
    for (int i = 0; i < tiles; ++i) {
      Surface ground;
      ground.name = "ground_" + std::to_string(i) + "_" + std::to_string(j);
      ground.origin = Vector3d(-kSiteHalf + i * tile, -kSiteHalf + j * tile, 0);
      ground.u_axis = Vector3d::UnitX();
      ground.v_axis = Vector3d::UnitY();
      ground.width = tile;
      ground.height = tile;
      ground.shading = scene.lighting.ShadingFor(Vector3d::UnitZ());
      ground.texture.base = kAsphalt;
      const Eigen::AlignedBox2d domain(ground.origin.head<2>(),
                                       ground.origin.head<2>() + Vector2d(tile, tile));
      for (const TextureLayer& layer : paint) {
        if (layer.Bounds().intersects(domain)) {
          ground.texture.layers.push_back(Shifted(layer, -ground.origin.head<2>()));
        }
      }
      scene.surfaces.push_back(std::move(ground));
    }
  }
  scene.UpdateBounds();
  scene.camera_region = Eigen::AlignedBox3d(Vector3d(park.bays_min_x + 5, park.lane_y[0] - 2, 1.0),
                                            Vector3d(park.bays_max_x - 5, park.lane_y[0] + 2, 3.0));

  // The serpentine vehicle route through every lane, keeping to the right half of each lane.
  std::vector<Vector2d> route;
  for (size_t m = 0; m < park.lane_y.size(); ++m) {
    const int heading = m % 2 == 0 ? 1 : -1;
    const double start_x = heading * (park.bays_min_x - 5), end_x = heading * (park.bays_max_x);
    const Vector2d start(m == 0 ? start_x : -end_x, park.lane_y[m] - 1.75 * heading);
    const Vector2d end(end_x, park.lane_y[m] - 1.75 * heading);
    route.push_back(start);
    route.push_back(end);
    if (m + 1 < park.lane_y.size()) {
      AppendHalfTurn(end, heading, (kModuleDepth + 2 * 1.75 * heading) / 2, &route);
      route.pop_back();
    }
  }
  park.drive_route = ResamplePolyline(route, 0.1);

  // The pedestrian keeps 1 m off the south bays of lane 0, walking east.
  const double walk_y = park.lane_y[0] - kLaneWidth / 2 + 1.0;
  park.walk_route =
      ResamplePolyline({Vector2d(park.bays_min_x, walk_y), Vector2d(park.bays_max_x, walk_y)}, 0.1);
  // Survey loops: per lane, east along its south edge and back west along its north edge.
  std::vector<Vector2d> loops;
  for (double lane_y : park.lane_y) {
    const double y_south = lane_y - kLaneWidth / 2 + 1.2, y_north = lane_y + kLaneWidth / 2 - 1.2;
    loops.push_back(Vector2d(park.bays_min_x - 2, y_south));
    loops.push_back(Vector2d(park.bays_max_x + 2, y_south));
    loops.push_back(Vector2d(park.bays_max_x + 2, y_north));
    loops.push_back(Vector2d(park.bays_min_x - 2, y_north));
    loops.push_back(Vector2d(park.bays_min_x - 2, y_south));
  }
  park.survey_walk_route = ResamplePolyline(loops, 0.1);
  return park;
}

std::string TimeOfDayName(TimeOfDay time) {
  switch (time) {
    case TimeOfDay::kDay:
      return "day";
    case TimeOfDay::kDusk:
      return "dusk";
    case TimeOfDay::kNight:
      return "night";
  }
  return "day";
}

TimeOfDay ParseTimeOfDay(const std::string& name) {
  if (name == "day") return TimeOfDay::kDay;
  if (name == "dusk") return TimeOfDay::kDusk;
  if (name == "night") return TimeOfDay::kNight;
  throw InvalidArgumentError("Unknown time of day '" + name + "'; expected day, dusk or night.");
}

void ApplyTimeOfDay(TimeOfDay time, const std::vector<PointLight>& lamps, Scene* scene) {
  switch (time) {
    case TimeOfDay::kDay:
      scene->daylight = 1.0;
      scene->sky = 0.8;
      scene->point_lights.clear();
      return;
    case TimeOfDay::kDusk:
      scene->daylight = 0.15;
      scene->sky = 0.8;
      break;
    case TimeOfDay::kNight:
      scene->daylight = 0.01;
      scene->sky = 0.2;
      break;
  }
  scene->point_lights = lamps;
}

}  // namespace evloc::sim
