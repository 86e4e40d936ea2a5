# evloc_mapper_pipeline: `evloc-mapper build` (docs/mapper.md): COLMAP runs and TXT models,
# keyframe selection, semi-dense edge depth, merging, the pipeline and its command line.
# Included from mapper/CMakeLists.txt.
find_package(PCL 1.13 REQUIRED COMPONENTS common kdtree filters)
find_package(SQLite3 REQUIRED)

add_library(evloc_mapper_pipeline
  ${CMAKE_CURRENT_LIST_DIR}/colmap_model.cc
  ${CMAKE_CURRENT_LIST_DIR}/colmap_database.cc
  ${CMAKE_CURRENT_LIST_DIR}/colmap_runner.cc
  ${CMAKE_CURRENT_LIST_DIR}/feature_matching.cc
  ${CMAKE_CURRENT_LIST_DIR}/keyframe_selection.cc
  ${CMAKE_CURRENT_LIST_DIR}/semidense_depth.cc
  ${CMAKE_CURRENT_LIST_DIR}/map_merge.cc
  ${CMAKE_CURRENT_LIST_DIR}/pose_alignment.cc
  ${CMAKE_CURRENT_LIST_DIR}/build_inputs.cc
  ${CMAKE_CURRENT_LIST_DIR}/build_workspace.cc
  ${CMAKE_CURRENT_LIST_DIR}/build_sparse.cc
  ${CMAKE_CURRENT_LIST_DIR}/build_stages.cc
  ${CMAKE_CURRENT_LIST_DIR}/build_report.cc
  ${CMAKE_CURRENT_LIST_DIR}/map_preview.cc
  ${CMAKE_CURRENT_LIST_DIR}/map_builder.cc
  ${CMAKE_CURRENT_LIST_DIR}/build_command.cc)
target_include_directories(evloc_mapper_pipeline PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(evloc_mapper_pipeline
  PUBLIC evloc_maps evloc_camera evloc_geometry evloc_common opencv_core opencv_imgproc opencv_imgcodecs
  PRIVATE evloc_trajectory nlohmann_json::nlohmann_json SQLite::SQLite3 Threads::Threads
          opencv_calib3d ${PCL_LIBRARIES})
target_compile_definitions(evloc_mapper_pipeline PRIVATE EVLOC_VERSION="${PROJECT_VERSION}")
# PCL headers are included by map_merge.cc only; SYSTEM keeps their warnings out.
target_include_directories(evloc_mapper_pipeline SYSTEM PRIVATE ${PCL_INCLUDE_DIRS})
target_compile_definitions(evloc_mapper_pipeline PRIVATE ${PCL_DEFINITIONS})

# Accuracy of a map against an exact synthetic scene (scripts/accuracy/mapper_synthetic.sh).
add_library(evloc_mapper_accuracy ${CMAKE_CURRENT_LIST_DIR}/map_accuracy.cc)
target_include_directories(evloc_mapper_accuracy PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(evloc_mapper_accuracy
  PUBLIC evloc_maps evloc_camera evloc_geometry evloc_common opencv_core
  PRIVATE evloc_trajectory evloc_sim_world nlohmann_json::nlohmann_json opencv_imgproc
          opencv_imgcodecs ${PCL_LIBRARIES})
target_include_directories(evloc_mapper_accuracy SYSTEM PRIVATE ${PCL_INCLUDE_DIRS})
target_compile_definitions(evloc_mapper_accuracy PRIVATE ${PCL_DEFINITIONS})
add_executable(evloc-mapper-accuracy ${CMAKE_CURRENT_LIST_DIR}/map_accuracy_main.cc)
target_link_libraries(evloc-mapper-accuracy PRIVATE evloc_mapper_accuracy evloc_trajectory
  opencv_imgcodecs nlohmann_json::nlohmann_json)

evloc_add_test(NAME evloc_mapper_pipeline_test
  SOURCES ${CMAKE_CURRENT_LIST_DIR}/colmap_model_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/keyframe_selection_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/semidense_depth_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/map_merge_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/pose_alignment_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/build_command_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/build_workspace_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/feature_matching_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/map_accuracy_test.cc
  LIBS evloc_mapper_pipeline evloc_mapper_accuracy evloc_trajectory SQLite::SQLite3)

evloc_add_test(NAME evloc_mapper_accuracy_test
  SOURCES ${CMAKE_CURRENT_LIST_DIR}/map_builder_accuracy_test.cc
  LIBS evloc_mapper_pipeline evloc_mapper_accuracy
  LABELS long)

# The short synthetic-room check of the default suite: render 30 frames (no events), map with the
# known poses, measure against the exact scene (about 40 s of CPU).
evloc_add_test(NAME evloc_mapper_synthetic_test
  SOURCES ${CMAKE_CURRENT_LIST_DIR}/synthetic_room_test.cc
  LIBS evloc_mapper_pipeline evloc_mapper_accuracy evloc_sim evloc_sim_world opencv_imgcodecs)
