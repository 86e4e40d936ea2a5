#include "tools/sim/scene.h"

#include <cmath>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "tools/sim/renderer.h"

namespace evloc::sim {
namespace {

TEST(Texture, LaterLayersCoverEarlierOnes) {
  Texture texture;
  texture.base = Gray(0.5f);
  texture.layers.push_back(TextureLayer::Rectangle({0, 0}, {1, 1}, Gray(0.2f)));
  texture.layers.push_back(TextureLayer::Disc({0.5, 0.5}, 0.1, Gray(0.9f)));
  EXPECT_FLOAT_EQ(texture.ColorAt({2, 2})[0], 0.5f);
  EXPECT_FLOAT_EQ(texture.ColorAt({0.1, 0.1})[0], 0.2f);
  EXPECT_FLOAT_EQ(texture.ColorAt({0.55, 0.5})[0], 0.9f);
  bool near = false;
  texture.ColorAt({0.5, 0.5}, 0.01, &near);
  EXPECT_FALSE(near);
  texture.ColorAt({0.595, 0.5}, 0.01, &near);
  EXPECT_TRUE(near);
  texture.ColorAt({0.995, 0.3}, 0.01, &near);
  EXPECT_TRUE(near);
}

TEST(Texture, StripesAndCheckerboardFollowTheirPeriod) {
  Texture texture;
  texture.base = Gray(1.0f);
  texture.layers.push_back(TextureLayer::Stripes({0, 0}, {1, 1}, 0.1, 0.03, 0, Gray(0.0f)));
  EXPECT_FLOAT_EQ(texture.ColorAt({0.21, 0.5})[0], 0.0f);  // inside stripe 2 [0.2, 0.23]
  EXPECT_FLOAT_EQ(texture.ColorAt({0.25, 0.5})[0], 1.0f);  // in the gap
  EXPECT_FLOAT_EQ(texture.ColorAt({0.21, 1.5})[0], 1.0f);  // outside the region
  Texture board;
  board.layers.push_back(TextureLayer::Checkerboard({0, 0}, {1, 1}, 0.25, Gray(0.1f), Gray(0.8f)));
  EXPECT_FLOAT_EQ(board.ColorAt({0.1, 0.1})[0], 0.1f);
  EXPECT_FLOAT_EQ(board.ColorAt({0.3, 0.1})[0], 0.8f);
  EXPECT_FLOAT_EQ(board.ColorAt({0.3, 0.3})[0], 0.1f);
}

TEST(Texture, RejectsDegenerateLayers) {
  EXPECT_THROW(TextureLayer::Disc({0, 0}, 0, Gray(0.5f)).Check("t"), InvalidArgumentError);
  EXPECT_THROW(TextureLayer::Rectangle({1, 0}, {0, 1}, Gray(0.5f)).Check("t"),
               InvalidArgumentError);
  EXPECT_THROW(TextureLayer::Stripes({0, 0}, {1, 1}, 0.1, 0.2, 0, Gray(0.5f)).Check("t"),
               InvalidArgumentError);
  // A non-convex "arrow" polygon.
  EXPECT_THROW(
      TextureLayer::Polygon({{0, 0}, {1, 0}, {0.5, 0.2}, {1, 1}, {0, 1}}, Gray(0.5f)).Check("t"),
      InvalidArgumentError);
  EXPECT_THROW(TextureLayer::Rectangle({0, 0}, {1, 1}, Gray(1.5f)).Check("t"),
               InvalidArgumentError);
}

TEST(Box, FacesPointOutwardsAndCloseTheVolume) {
  Scene scene;
  BoxSpec box;
  box.name = "b";
  box.center = Eigen::Vector3d(1, 2, 3);
  box.size = Eigen::Vector3d(0.4, 0.6, 0.8);
  box.yaw = 0.7;
  AddBox(box, &scene);
  ASSERT_EQ(scene.surfaces.size(), 6u);
  double area = 0;
  for (const Surface& face : scene.surfaces) {
    EXPECT_NO_THROW(face.Check());
    const Eigen::Vector3d face_center = face.PointAt(0.5 * face.width, 0.5 * face.height);
    EXPECT_GT(face.Normal().dot(face_center - box.center), 0.19) << face.name;
    area += face.width * face.height;
  }
  EXPECT_NEAR(area, 2 * (0.4 * 0.6 + 0.4 * 0.8 + 0.6 * 0.8), 1e-12);
  // Any ray from inside leaves through exactly one face at the expected distance along x.
  const auto hit = CastRay(scene, box.center, Eigen::Vector3d(std::cos(0.7), std::sin(0.7), 0));
  ASSERT_TRUE(hit.has_value());
  EXPECT_NEAR(hit->distance, 0.2, 1e-12);
  EXPECT_EQ(scene.surfaces[hit->surface_index].name, "b/+x");
}

TEST(DefaultRoom, IsValidClosedAndDeterministic) {
  const Scene room = MakeDefaultRoom();
  EXPECT_NO_THROW(room.Check());
  EXPECT_GT(room.surfaces.size(), 60u);
  EXPECT_NEAR(room.bounds.min().x(), -2, 1e-9);
  EXPECT_NEAR(room.bounds.max().z(), 2.5, 1e-9);
  EXPECT_TRUE(room.bounds.contains(room.camera_region));
  // From anywhere in the camera region every ray hits a surface within the room, and no surface
  // is closer than 10 cm (the region is free space).
  for (double fx : {0.0, 0.5, 1.0}) {
    for (double fz : {0.0, 1.0}) {
      const Eigen::Vector3d origin =
          room.camera_region.min() +
          Eigen::Vector3d(fx, 1 - fx, fz).cwiseProduct(room.camera_region.sizes());
      for (int i = 0; i < 200; ++i) {
        const double polar = std::acos(1 - 2 * (i + 0.5) / 200.0), azimuth = 2.399963 * i;
        const Eigen::Vector3d direction(std::sin(polar) * std::cos(azimuth),
                                        std::sin(polar) * std::sin(azimuth), std::cos(polar));
        const auto hit = CastRay(room, origin, direction);
        ASSERT_TRUE(hit.has_value()) << origin.transpose() << " / " << direction.transpose();
        EXPECT_GT(hit->distance, 0.1);
        EXPECT_LT(hit->distance, 6.5);
      }
    }
  }
  const Scene again = MakeDefaultRoom();
  EXPECT_EQ(SceneToJson(room), SceneToJson(again));
}

TEST(SceneJson, RoundTripReproducesTheScene) {
  const Scene room = MakeDefaultRoom();
  const std::filesystem::path path = std::filesystem::temp_directory_path() /
                                     ("evloc_scene_" + std::to_string(::getpid()) + ".json");
  SaveSceneJson(path, room);
  const Scene loaded = LoadSceneJson(path);
  std::filesystem::remove(path);
  ASSERT_EQ(loaded.surfaces.size(), room.surfaces.size());
  for (size_t i = 0; i < room.surfaces.size(); ++i) {
    const Surface& a = room.surfaces[i];
    const Surface& b = loaded.surfaces[i];
    EXPECT_EQ(a.name, b.name);
    EXPECT_LT((a.origin - b.origin).norm(), 1e-12);
    EXPECT_LT((a.u_axis - b.u_axis).norm(), 1e-12);
    EXPECT_LT((a.v_axis - b.v_axis).norm(), 1e-12);
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.shading, b.shading);
    ASSERT_EQ(a.texture.layers.size(), b.texture.layers.size());
    EXPECT_EQ(a.texture.base, b.texture.base);
    for (size_t j = 0; j < a.texture.layers.size(); ++j) {
      EXPECT_EQ(a.texture.layers[j].shape, b.texture.layers[j].shape);
      EXPECT_EQ(a.texture.layers[j].color, b.texture.layers[j].color);
      EXPECT_EQ(a.texture.layers[j].Bounds().min(), b.texture.layers[j].Bounds().min());
      EXPECT_EQ(a.texture.layers[j].Bounds().max(), b.texture.layers[j].Bounds().max());
    }
  }
  EXPECT_EQ(loaded.camera_region.min(), room.camera_region.min());
}

TEST(SceneJson, BoxesAndLinesParse) {
  const std::string text = R"({
    "name": "test", "camera_region": {"min": [-1, -1, 0.5], "max": [1, 1, 1.5]},
    "quads": [{"name": "floor", "origin": [-2, -2, 0], "u_axis": [1, 0, 0], "v_axis": [0, 2, 0],
               "width": 4, "height": 4,
               "texture": {"base": 0.4, "layers": [
                 {"shape": "line", "from": [1, 1], "to": [3, 1], "width": 0.01, "color": 0.1},
                 {"shape": "checkerboard", "min": [0, 2], "max": [1, 3], "square": 0.25,
                  "color": 0, "color2": [1, 0.5, 0.25]}]}}],
    "boxes": [{"name": "b", "center": [0, 0, 0.25], "size": [0.5, 0.5, 0.5], "yaw_deg": 90,
               "bottom_face": false, "texture": {"base": [0.2, 0.3, 0.4]},
               "face_textures": {"+z": {"base": 0.9}}}]})";
  const Scene scene = ParseSceneJson(text, "inline");
  ASSERT_EQ(scene.surfaces.size(), 6u);
  EXPECT_EQ(scene.surfaces[0].texture.layers.size(), 2u);
  EXPECT_LT((scene.surfaces[0].v_axis - Eigen::Vector3d::UnitY()).norm(), 1e-15);
  EXPECT_EQ(scene.surfaces[5].name, "b/+z");
  EXPECT_FLOAT_EQ(scene.surfaces[5].texture.base[0], 0.9f);
  EXPECT_NEAR(scene.surfaces[1].Normal().y(), 1.0, 1e-12);  // +x face after a 90 degree yaw
}

// Expects ParseSceneJson(text) to throw ParseError whose message contains every fragment.
void ExpectParseError(const std::string& text, const std::vector<std::string>& fragments) {
  try {
    ParseSceneJson(text, "bad.json");
    ADD_FAILURE() << "no error for " << text;
  } catch (const ParseError& error) {
    const std::string message = error.what();
    for (const std::string& fragment : fragments) {
      EXPECT_NE(message.find(fragment), std::string::npos) << message << " lacks " << fragment;
    }
  }
}

TEST(SceneJson, ErrorsNameWhatAndWhere) {
  const std::string region = R"("camera_region": {"min": [0, 0, 0], "max": [1, 1, 1]})";
  const std::string quad_start =
      R"({"name": "q", "origin": [0, 0, 0], "u_axis": [1, 0, 0], "texture": {"base": 0.5}, )";
  ExpectParseError(
      "{" + region + R"(, "quads": [)" + quad_start + R"("v_axis": [0, 1, 0], "height": 1}]})",
      {"bad.json", "/quads/0", "missing required field 'width'"});
  ExpectParseError("{" + region + R"(, "quads": [)" + quad_start +
                       R"("v_axis": [0, 1, 0], "width": "wide", "height": 1}]})",
                   {"/quads/0/width", "expected a number"});
  ExpectParseError("{" + region + R"(, "quads": [)" + quad_start +
                       R"("v_axis": [1, 1, 0], "width": 1, "height": 1}]})",
                   {"/quads/0", "degenerate quad", "orthogonal"});
  ExpectParseError("{" + region + R"(, "quads": [)" + quad_start +
                       R"("v_axis": [0, 1, 0], "width": 0, "height": 1}]})",
                   {"/quads/0", "degenerate quad"});
  ExpectParseError(R"({"quads": []})", {"missing required field 'camera_region'"});
  ExpectParseError("{" + region + "}", {"no quads and no boxes"});
  ExpectParseError("{" + region + R"(, "quads": [{"name": "q", "origin": [0, 0, 0],)" +
                       R"("u_axis": [1, 0, 0], "v_axis": [0, 1, 0], "width": 1, "height": 1,)" +
                       R"("texture": {"base": 0.5, "layers": [{"shape": "star"}]}}]})",
                   {"/quads/0/texture/layers/0/shape", "unknown shape 'star'"});
  ExpectParseError(
      "{" + region + R"(, "quads": [{"name": "q", "origin": [0, 0, 0],)" +
          R"("u_axis": [1, 0, 0], "v_axis": [0, 1, 0], "width": 1, "height": 1,)" +
          R"("texture": {"base": 0.5, "layers": [{"shape": "disc", "center": [0, 0],)" +
          R"("radius": -1, "color": 0.2}]}}]})",
      {"/quads/0/texture/layers/0", "positive radius"});
  ExpectParseError(R"({"camera_region": )", {"bad.json", "byte", "invalid JSON"});
  EXPECT_THROW(LoadSceneJson("/nonexistent/scene.json"), IoError);
}

}  // namespace
}  // namespace evloc::sim
