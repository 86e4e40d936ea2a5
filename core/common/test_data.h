// Test helpers: where the real recorded data lives, and the source tree.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

namespace evloc::testing {

// The shared real-data folder: $EVLOC_DATA_DIR if set, else <source>/../shared/data, when it
// exists; std::nullopt otherwise. Tests that need it call GTEST_SKIP() with the reason
// returned by MissingDataReason().
std::optional<std::filesystem::path> SharedDataDir();

// Path of `relative` inside the shared data folder, if the folder and the file exist.
std::optional<std::filesystem::path> SharedDataFile(const std::string& relative);

// A visible skip reason naming what is missing and how to provide it.
std::string MissingDataReason(const std::string& relative);

// The project's source directory (for files committed under tests/data).
std::filesystem::path SourceDir();

// Runs `command` with /bin/sh, appends its standard output to `*output` and returns its exit
// status as pclose() gives it (0 on success, -1 when it could not be started).
int RunShellCommand(const std::string& command, std::string* output);

// A fresh, empty temporary directory unique to the calling test; removed by the caller if wanted.
std::filesystem::path MakeTempDir(const std::string& prefix);

}  // namespace evloc::testing

// Skips the current test with a visible reason when a shared data file is absent; otherwise
// declares `var` as its path.
#define EVLOC_REQUIRE_SHARED_DATA(var, relative)                          \
  const auto var##_optional = ::evloc::testing::SharedDataFile(relative); \
  if (!var##_optional) {                                                  \
    GTEST_SKIP() << ::evloc::testing::MissingDataReason(relative);        \
  }                                                                       \
  const std::filesystem::path var = *var##_optional
