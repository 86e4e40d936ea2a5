// Test helper: small ROS1 bags written by Debian's python3-rosbag (an independent writer) with
// core/events/testing/write_test_bags.py, small AEDAT4 files written with Debian's
// python3-flatbuffers, python3-lz4 and python3-zstandard by write_test_aedat4.py, and the
// expected content they record.
#pragma once

#include <filesystem>
#include <istream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/events/event.h"
#include "core/events/event_reader.h"

namespace evloc::testing {

// The folder holding test_{none,bz2,lz4}.bag and expected_*.txt, written once per test process;
// std::nullopt when /usr/bin/python3 lacks rosbag, genpy or roslz4 (`*reason` says what to
// install) or the script fails (`*reason` holds its output).
std::optional<std::filesystem::path> TestBagsDir(std::string* reason);

// The folder holding test_{none,lz4,lz4-high,zstd,zstd-high,no_table}.aedat4 and expected_*.txt
// (write_test_aedat4.py), written once per test process; std::nullopt with `*reason` as above.
std::optional<std::filesystem::path> TestAedat4Dir(std::string* reason);

// Reads expected_<name>.txt of the events (`t_ns x y p` per line).
EventBuffer ReadExpectedEvents(const std::filesystem::path& dir, const std::string& name);

// Reads the whitespace-separated lines of expected_<name>.txt.
std::vector<std::vector<std::string>> ReadExpectedLines(const std::filesystem::path& dir,
                                                        const std::string& name);

// The bytes of a file.
std::string ReadBytes(const std::filesystem::path& path);

// A seekable stream over `bytes` (a cut or corrupted copy of a test file).
std::unique_ptr<std::istream> StreamOf(const std::string& bytes);

// Every event of `reader`, read `batch` at a time.
EventBuffer ReadAllEvents(EventReader* reader, size_t batch);

}  // namespace evloc::testing

// Skips the current test with the reason when the bags cannot be written; else declares `var`.
#define EVLOC_REQUIRE_TEST_BAGS(var)                                        \
  std::string var##_reason;                                                 \
  const auto var##_optional = ::evloc::testing::TestBagsDir(&var##_reason); \
  if (!var##_optional) GTEST_SKIP() << var##_reason;                        \
  const std::filesystem::path var = *var##_optional

// Skips the current test with the reason when the AEDAT4 files cannot be written; else declares
// `var`.
#define EVLOC_REQUIRE_TEST_AEDAT4(var)                                        \
  std::string var##_reason;                                                   \
  const auto var##_optional = ::evloc::testing::TestAedat4Dir(&var##_reason); \
  if (!var##_optional) GTEST_SKIP() << var##_reason;                          \
  const std::filesystem::path var = *var##_optional
