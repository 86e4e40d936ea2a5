#include "tools/sim/carpark.h"

#include <cmath>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "tools/sim/renderer.h"

namespace evloc::sim {
namespace {

int CountSurfaces(const Scene& scene, const std::string& prefix) {
  int count = 0;
  for (const Surface& surface : scene.surfaces) count += surface.name.rfind(prefix, 0) == 0;
  return count;
}

TEST(CarPark, IsDeterministicCoversTheSiteAndHoldsEveryKindOfObject) {
  const CarPark park = MakeCarPark();
  EXPECT_EQ(SceneToJson(park.scene), SceneToJson(MakeCarPark().scene));
  CarParkOptions other;
  other.seed = 2;
  EXPECT_NE(SceneToJson(park.scene), SceneToJson(MakeCarPark(other).scene));

  const Eigen::Vector3d size = park.scene.bounds.sizes();
  EXPECT_GE(size.x(), 200.0);
  EXPECT_GE(size.y(), 200.0);
  EXPECT_EQ(CountSurfaces(park.scene, "ground_"), 100);
  // 8 modules x 2 rows x 64 bays at 55 % occupancy: about 560 cars (body + cabin, 5 faces each).
  const int car_faces = CountSurfaces(park.scene, "car_");
  EXPECT_GT(car_faces, 400 * 10);
  EXPECT_LT(car_faces, 720 * 10);
  EXPECT_GE(CountSurfaces(park.scene, "building_"), 3 * 5);
  EXPECT_GE(CountSurfaces(park.scene, "tree_"), 40 * 10);
  EXPECT_EQ(CountSurfaces(park.scene, "lamp_"), static_cast<int>(park.lamps.size()) * 11);
  EXPECT_GE(park.lamps.size(), 40u);
  EXPECT_EQ(CountSurfaces(park.scene, "island_"), 8 * 5);
  EXPECT_EQ(CountSurfaces(park.scene, "wall_"), 3 * 5);
  EXPECT_EQ(park.lane_y.size(), 8u);
  // By day the lamps are off.
  EXPECT_TRUE(park.scene.point_lights.empty());
  EXPECT_EQ(park.scene.daylight, 1.0);
  EXPECT_NO_THROW(park.scene.Check());
}

// A camera centre on the route must be in free space: nothing within `clearance` around it at
// the camera heights used, and the ground (not a car roof or a kerb) right below it.
void ExpectRouteIsClear(const CarPark& park, const std::vector<Eigen::Vector2d>& route,
                        double height, const std::string& name) {
  const SurfaceIndex index(park.scene);
  int checked = 0;
  for (size_t i = 0; i < route.size(); i += 10) {  // every metre
    const Eigen::Vector3d centre(route[i].x(), route[i].y(), height);
    for (int k = 0; k < 8; ++k) {
      const double angle = k * M_PI / 4;
      const auto hit = index.CastRay(centre, Eigen::Vector3d(std::cos(angle), std::sin(angle), 0));
      ASSERT_TRUE(!hit || hit->distance > 0.8)
          << name << " point " << i << " (" << centre.transpose() << ") passes " << hit->distance
          << " m from " << park.scene.surfaces[hit->surface_index].name;
    }
    const auto below = index.CastRay(centre, -Eigen::Vector3d::UnitZ());
    ASSERT_TRUE(below.has_value());
    EXPECT_EQ(park.scene.surfaces[below->surface_index].name.rfind("ground_", 0), 0u)
        << name << " point " << i << " is above " << park.scene.surfaces[below->surface_index].name;
    ++checked;
  }
  EXPECT_GT(checked, 50);
}

// Marks on the asphalt add texture to the ground tiles only: every other surface, and the ground's
// paint, stay as without them (the marks draw from a random sequence of their own).
TEST(CarPark, GroundMarksTextureTheAsphaltAndChangeNothingElse) {
  const CarPark plain = MakeCarPark();
  CarParkOptions options;
  options.ground_marks_per_m2 = 0.5;
  const CarPark marked = MakeCarPark(options);
  ASSERT_EQ(marked.scene.surfaces.size(), plain.scene.surfaces.size());
  size_t plain_layers = 0;
  size_t marked_layers = 0;
  for (size_t i = 0; i < plain.scene.surfaces.size(); ++i) {
    const Surface& a = plain.scene.surfaces[i];
    const Surface& b = marked.scene.surfaces[i];
    ASSERT_EQ(a.name, b.name);
    if (a.name.rfind("ground_", 0) != 0) {
      EXPECT_EQ(a.texture.layers.size(), b.texture.layers.size()) << a.name;
      continue;
    }
    plain_layers += a.texture.layers.size();
    marked_layers += b.texture.layers.size();
    // The paint (lines, patches) is drawn over the marks, in the same order.
    ASSERT_GE(b.texture.layers.size(), a.texture.layers.size());
  }
  // 0.5 per m^2 over 200 m x 200 m: 20,000 marks (a few counted twice across tile borders).
  EXPECT_GE(marked_layers - plain_layers, 20'000u);
  EXPECT_LT(marked_layers - plain_layers, 21'000u);
  EXPECT_EQ(marked.drive_route, plain.drive_route);
  EXPECT_EQ(marked.survey_walk_route, plain.survey_walk_route);
}

TEST(CarPark, RoutesRunThroughFreeSpaceOverTheGround) {
  const CarPark park = MakeCarPark();
  // The serpentine through 8 lanes: 8 straights of ~165 m and 7 half turns.
  ASSERT_GT(park.drive_route.size(), 10000u);
  ExpectRouteIsClear(park, park.drive_route, 1.5, "drive");
  ExpectRouteIsClear(park, park.drive_route, 0.5, "drive (bumper height)");
  ExpectRouteIsClear(park, park.walk_route, 1.4, "walk");
  ExpectRouteIsClear(park, park.survey_walk_route, 1.4, "survey walk");
  // Consecutive route points are 0.1 m apart along the route (the chord across a bend of the
  // sampled half turns is shorter by a micrometre; the last piece may be shorter).
  for (size_t i = 1; i + 1 < park.drive_route.size(); ++i) {
    ASSERT_NEAR((park.drive_route[i] - park.drive_route[i - 1]).norm(), 0.1, 1e-5) << i;
  }
}

TEST(CarPark, RejectsBadOptions) {
  CarParkOptions options;
  options.modules = 0;
  EXPECT_THROW(MakeCarPark(options), InvalidArgumentError);
  options = {};
  options.occupancy = 1.5;
  EXPECT_THROW(MakeCarPark(options), InvalidArgumentError);
  options = {};
  options.ground_tile_m = 0;
  EXPECT_THROW(MakeCarPark(options), InvalidArgumentError);
  options = {};
  options.ground_marks_per_m2 = -1;
  EXPECT_THROW(MakeCarPark(options), InvalidArgumentError);
  options.ground_marks_per_m2 = std::nan("");
  EXPECT_THROW(MakeCarPark(options), InvalidArgumentError);
  EXPECT_THROW(ParseTimeOfDay("noon"), InvalidArgumentError);
  EXPECT_EQ(ParseTimeOfDay(TimeOfDayName(TimeOfDay::kDusk)), TimeOfDay::kDusk);
}

TEST(ResamplePolyline, KeepsTheEndsAndTheSpacing) {
  const auto points = ResamplePolyline(
      {Eigen::Vector2d(0, 0), Eigen::Vector2d(1.05, 0), Eigen::Vector2d(1.05, 1)}, 0.1);
  ASSERT_EQ(points.size(), 22u);  // 2.05 m: 0, 0.1, ..., 2.0 and the end
  EXPECT_TRUE(points.front().isApprox(Eigen::Vector2d(0, 0)));
  EXPECT_TRUE(points.back().isApprox(Eigen::Vector2d(1.05, 1)));
  EXPECT_NEAR(points[11].x(), 1.05, 1e-12);  // 1.1 m along: 0.05 m up the second piece
  EXPECT_NEAR(points[11].y(), 0.05, 1e-12);
  EXPECT_THROW(ResamplePolyline(points, 0), InvalidArgumentError);
}

TEST(SurfaceIndex, GivesTheSameNearestHitAsTheBruteForceCast) {
  const CarPark park = MakeCarPark();
  const Scene room = MakeDefaultRoom();
  for (const Scene* scene : {&park.scene, &room}) {
    const SurfaceIndex index(*scene);
    std::mt19937_64 random(5);
    std::uniform_real_distribution<double> unit(-1, 1);
    const Eigen::Vector3d centre = scene->bounds.center();
    const Eigen::Vector3d half = scene->bounds.sizes() / 2;
    int hits = 0;
    for (int i = 0; i < 3000; ++i) {
      const Eigen::Vector3d origin =
          centre + Eigen::Vector3d(unit(random) * half.x(), unit(random) * half.y(),
                                   (0.5 + 0.5 * unit(random)) * half.z());
      Eigen::Vector3d direction(unit(random), unit(random), unit(random));
      if (i % 3 == 0) direction.z() = 0;  // horizontal rays: axis-parallel slabs
      if (direction.norm() < 1e-3) continue;
      const auto expected = CastRay(*scene, origin, direction, 1e-9);
      const auto actual = index.CastRay(origin, direction, 1e-9);
      ASSERT_EQ(expected.has_value(), actual.has_value()) << scene->name << " ray " << i;
      if (!expected) continue;
      ++hits;
      ASSERT_EQ(expected->surface_index, actual->surface_index) << scene->name << " ray " << i;
      ASSERT_EQ(expected->distance, actual->distance);
    }
    EXPECT_GT(hits, 1000) << scene->name;
  }
}

TEST(TimeOfDay, NightIsDarkExceptUnderTheLampsAndDayIsEven) {
  const CarPark park = MakeCarPark();
  const Camera camera = Camera::Pinhole(64, 48, 40, 40, 31.5, 23.5);
  // Looking straight down from 4 m: at a lamp's foot (on its island) and at the ground halfway
  // between two lamps of one island and the next island's (a lane's bays).
  const PointLight& lamp = park.lamps[3];
  const Eigen::Vector3d under_lamp(lamp.position.x() + 1.5, lamp.position.y(), 4.0);
  const Eigen::Vector3d between(lamp.position.x() + 12.0, lamp.position.y() - 10.0, 4.0);
  const Eigen::Quaterniond down(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()));
  auto mean_irradiance = [&](const Scene& scene, const Eigen::Vector3d& where) {
    const Renderer renderer(scene, camera);
    cv::Mat gray;
    renderer.Render(Rigid3d(down, where), &gray);
    return cv::mean(gray)[0];
  };
  Scene night = park.scene;
  ApplyTimeOfDay(TimeOfDay::kNight, park.lamps, &night);
  EXPECT_EQ(night.point_lights.size(), park.lamps.size());
  const double day_lamp = mean_irradiance(park.scene, under_lamp);
  const double day_between = mean_irradiance(park.scene, between);
  const double night_lamp = mean_irradiance(night, under_lamp);
  const double night_between = mean_irradiance(night, between);
  // By day both views see asphalt, paint and grass in full daylight.
  EXPECT_GT(day_between, 0.05);
  EXPECT_GT(day_lamp, 0.05);
  // At night the lamp lights its foot to a good fraction of daylight; far from it the ground
  // is several times darker.
  EXPECT_GT(night_lamp, 0.3 * day_lamp);
  EXPECT_GT(night_lamp, 4 * night_between);
  EXPECT_LT(night_between, 0.4 * day_between);
  std::cout << "day " << day_lamp << " / " << day_between << ", night " << night_lamp << " / "
            << night_between << "\n";

  // The light factor itself: right under a lamp, daylight * shading plus I / h^2.
  const Surface& ground = night.surfaces.back();  // a ground tile
  const Eigen::Vector3d foot(lamp.position.x(), lamp.position.y(), 0);
  double expected = night.daylight * ground.shading;
  for (const PointLight& light : night.point_lights) {
    const Eigen::Vector3d to_light = light.position - foot;
    expected += light.intensity * to_light.z() / std::pow(to_light.norm(), 3);
  }
  EXPECT_NEAR(night.LightFactorAt(ground, foot, foot + Eigen::Vector3d(0, 0, 2)), expected, 1e-5);
  // Seen from below the ground (the back side), the lamps above do not light it.
  EXPECT_NEAR(night.LightFactorAt(ground, foot, foot - Eigen::Vector3d(0, 0, 2)),
              night.daylight * ground.shading, 1e-7);
}

TEST(SceneJson, PointLightsDaylightAndSkyRoundTripAndAreChecked) {
  CarPark park = MakeCarPark();
  Scene scene = MakeDefaultRoom();
  scene.point_lights = {park.lamps[0], park.lamps[1]};
  scene.daylight = 0.25;
  scene.sky = 0.5;
  const Scene parsed = ParseSceneJson(SceneToJson(scene), "scene.json");
  ASSERT_EQ(parsed.point_lights.size(), 2u);
  EXPECT_EQ(parsed.point_lights[1].position, park.lamps[1].position);
  EXPECT_EQ(parsed.point_lights[1].intensity, park.lamps[1].intensity);
  EXPECT_EQ(parsed.daylight, 0.25);
  EXPECT_EQ(parsed.sky, 0.5);
  const std::string quad =
      R"("camera_region": {"min": [0, 0, 0], "max": [1, 1, 1]}, "quads": [{"name": "q",
      "origin": [0, 0, 0], "u_axis": [1, 0, 0], "v_axis": [0, 1, 0], "width": 1, "height": 1,
      "texture": {"base": 0.5}}])";
  try {
    ParseSceneJson("{" + quad + R"(, "point_lights": [{"position": [0, 0, 3], "intensity": -1}]})",
                   "lamps.json");
    FAIL() << "a negative intensity was accepted";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("lamps.json: /point_lights/0/intensity"),
              std::string::npos)
        << error.what();
  }
  EXPECT_THROW(ParseSceneJson("{" + quad + R"(, "daylight": 2})", "d.json"), ParseError);
  EXPECT_THROW(ParseSceneJson("{" + quad + R"(, "sky": -0.1})", "s.json"), ParseError);
  EXPECT_THROW(ParseSceneJson("{" + quad + R"(, "point_lights": {}})", "p.json"), ParseError);
  EXPECT_THROW(
      ParseSceneJson("{" + quad + R"(, "point_lights": [{"position": [0, 0]}]})", "p.json"),
      ParseError);
}

}  // namespace
}  // namespace evloc::sim
