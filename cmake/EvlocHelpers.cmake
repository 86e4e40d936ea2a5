# Helpers shared by every module's CMakeLists.txt.

# evloc_add_test(NAME name SOURCES a_test.cc ... LIBS lib ... [LABELS label ...])
# One GoogleTest executable; each TEST becomes a ctest entry. Label "long" keeps a test out of
# `make test` (run with `make test-long`).
function(evloc_add_test)
  cmake_parse_arguments(ARG "" "NAME" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${ARG_NAME} ${ARG_SOURCES})
  target_link_libraries(${ARG_NAME} PRIVATE ${ARG_LIBS} evloc_testing GTest::gtest_main)
  set(props "")
  if(ARG_LABELS)
    set(props PROPERTIES LABELS "${ARG_LABELS}")
  endif()
  gtest_discover_tests(${ARG_NAME} DISCOVERY_MODE PRE_TEST DISCOVERY_TIMEOUT 60
    WORKING_DIRECTORY ${PROJECT_SOURCE_DIR} ${props})
endfunction()

# evloc_add_fuzzer(NAME name SOURCES a_fuzzer.cc LIBS lib ...)
# A libFuzzer target, built only with -DEVLOC_FUZZ=ON (see docs/reliability.md).
function(evloc_add_fuzzer)
  cmake_parse_arguments(ARG "" "NAME" "SOURCES;LIBS" ${ARGN})
  if(NOT EVLOC_FUZZ)
    return()
  endif()
  add_executable(${ARG_NAME} ${ARG_SOURCES})
  target_link_libraries(${ARG_NAME} PRIVATE ${ARG_LIBS})
  target_link_options(${ARG_NAME} PRIVATE -fsanitize=fuzzer)
  add_dependencies(evloc_fuzzers ${ARG_NAME})
endfunction()

# evloc_add_benchmark(NAME name SOURCES a_benchmark.cc LIBS lib ...)
function(evloc_add_benchmark)
  cmake_parse_arguments(ARG "" "NAME" "SOURCES;LIBS" ${ARGN})
  if(NOT EVLOC_BUILD_BENCH OR EVLOC_FUZZ)
    return()
  endif()
  find_package(benchmark REQUIRED)
  add_executable(${ARG_NAME} ${ARG_SOURCES})
  target_link_libraries(${ARG_NAME} PRIVATE ${ARG_LIBS} benchmark::benchmark)
endfunction()
