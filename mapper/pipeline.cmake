# evloc_mapper_pipeline: `evloc-mapper build` (docs/mapper.md): COLMAP runs and TXT models,
# keyframe selection, semi-dense edge depth, merging, the pipeline and its command line.
# Included from mapper/CMakeLists.txt.
find_package(PCL 1.13 REQUIRED COMPONENTS common kdtree filters)
find_package(SQLite3 REQUIRED)
find_package(exiv2 CONFIG REQUIRED)
find_package(Ceres REQUIRED)

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
  ${CMAKE_CURRENT_LIST_DIR}/relocalization_data.cc
  ${CMAKE_CURRENT_LIST_DIR}/georeference.cc
  ${CMAKE_CURRENT_LIST_DIR}/map_builder.cc
  ${CMAKE_CURRENT_LIST_DIR}/chunked_build.cc
  ${CMAKE_CURRENT_LIST_DIR}/build_command.cc)
target_include_directories(evloc_mapper_pipeline PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(evloc_mapper_pipeline
  PUBLIC evloc_maps evloc_geo evloc_camera evloc_geometry evloc_common evloc_features opencv_core opencv_imgproc
         opencv_imgcodecs
  PRIVATE evloc_dataset evloc_trajectory nlohmann_json::nlohmann_json SQLite::SQLite3
          Threads::Threads opencv_calib3d exiv2lib Ceres::ceres ${PCL_LIBRARIES})
# PCL headers are included by map_merge.cc only; SYSTEM keeps their warnings out.
target_include_directories(evloc_mapper_pipeline SYSTEM PRIVATE ${PCL_INCLUDE_DIRS})
target_compile_definitions(evloc_mapper_pipeline PRIVATE ${PCL_DEFINITIONS})

evloc_add_test(NAME evloc_mapper_pipeline_test
  SOURCES ${CMAKE_CURRENT_LIST_DIR}/colmap_model_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/keyframe_selection_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/semidense_depth_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/map_merge_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/pose_alignment_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/build_command_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/build_workspace_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/feature_matching_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/relocalization_data_test.cc
          ${CMAKE_CURRENT_LIST_DIR}/chunked_build_test.cc
  LIBS evloc_mapper_pipeline evloc_map_accuracy evloc_trajectory SQLite::SQLite3)

evloc_add_test(NAME evloc_mapper_accuracy_test
  SOURCES ${CMAKE_CURRENT_LIST_DIR}/map_builder_accuracy_test.cc
  LIBS evloc_mapper_pipeline evloc_map_accuracy
  LABELS long)

evloc_add_fuzzer(NAME evloc_chunk_poses_fuzzer SOURCES ${CMAKE_CURRENT_LIST_DIR}/fuzz/chunk_poses_fuzzer.cc
  LIBS evloc_mapper_pipeline)
evloc_add_fuzzer(NAME evloc_chunk_plan_fuzzer SOURCES ${CMAKE_CURRENT_LIST_DIR}/fuzz/chunk_plan_fuzzer.cc
  LIBS evloc_mapper_pipeline)
