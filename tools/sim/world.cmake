# The simulator's world (included by tools/sim/CMakeLists.txt): scenes, the ray-cast renderer and
# the exact ground-truth map. See docs/sim-scene.md.
add_library(evloc_sim_world
  ${CMAKE_CURRENT_LIST_DIR}/scene.cc
  ${CMAKE_CURRENT_LIST_DIR}/scene_json.cc
  ${CMAKE_CURRENT_LIST_DIR}/carpark.cc
  ${CMAKE_CURRENT_LIST_DIR}/renderer.cc
  ${CMAKE_CURRENT_LIST_DIR}/ground_truth_map.cc)
target_include_directories(evloc_sim_world PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(evloc_sim_world
  PUBLIC evloc_geometry evloc_camera evloc_maps Eigen3::Eigen opencv_core
  PRIVATE evloc_common nlohmann_json::nlohmann_json)

evloc_add_test(NAME evloc_sim_world_test
  SOURCES ${CMAKE_CURRENT_LIST_DIR}/scene_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/renderer_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/ground_truth_map_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/carpark_test.cc
  LIBS evloc_sim_world evloc_common opencv_imgproc opencv_imgcodecs)

# Render-speed benchmark: prints the time per frame of the default room (docs/sim-scene.md).
add_executable(evloc_sim_render_benchmark ${CMAKE_CURRENT_LIST_DIR}/render_benchmark.cc)
target_link_libraries(evloc_sim_render_benchmark PRIVATE evloc_sim_world)

# libFuzzer target (built with -DEVLOC_FUZZ=ON, `make fuzz`); see docs/reliability.md.
evloc_add_fuzzer(NAME evloc_scene_json_fuzzer
  SOURCES ${CMAKE_CURRENT_LIST_DIR}/fuzz/scene_json_fuzzer.cc LIBS evloc_sim_world evloc_common)
