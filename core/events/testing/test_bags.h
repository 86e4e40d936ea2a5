// Test helper: small ROS1 bags written by Debian's python3-rosbag (an independent writer) with
// core/events/testing/write_test_bags.py, and the expected content it records.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/events/event.h"

namespace evloc::testing {

// The folder holding test_{none,bz2,lz4}.bag and expected_*.txt, written once per test process;
// std::nullopt when /usr/bin/python3 lacks rosbag, genpy or roslz4 (`*reason` says what to
// install) or the script fails (`*reason` holds its output).
std::optional<std::filesystem::path> TestBagsDir(std::string* reason);

// Reads expected_<name>.txt of the events (`t_ns x y p` per line).
EventBuffer ReadExpectedEvents(const std::filesystem::path& dir, const std::string& name);

// Reads the whitespace-separated lines of expected_<name>.txt.
std::vector<std::vector<std::string>> ReadExpectedLines(const std::filesystem::path& dir,
                                                        const std::string& name);

}  // namespace evloc::testing

// Skips the current test with the reason when the bags cannot be written; else declares `var`.
#define EVLOC_REQUIRE_TEST_BAGS(var)                                        \
  std::string var##_reason;                                                 \
  const auto var##_optional = ::evloc::testing::TestBagsDir(&var##_reason); \
  if (!var##_optional) GTEST_SKIP() << var##_reason;                        \
  const std::filesystem::path var = *var##_optional
