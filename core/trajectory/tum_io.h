// TUM trajectory files: one pose per line, `t tx ty tz qx qy qz qw`, t in seconds, the pose
// world_from_cam (translation in metres, unit quaternion). Timestamps are parsed exactly into
// integer nanoseconds, so they survive read -> write -> read bit for bit.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "core/trajectory/trajectory.h"

namespace evloc {

// Reads a TUM trajectory file. Accepted: `#` comment lines, blank lines, one column-header line
// starting with the word `timestamp` before the first pose (some copies drop its `#`), fields
// separated by spaces, tabs or commas, Windows line ends. The quaternion is normalised.
// Throws IoError when the file cannot be read, and ParseError naming the file and line for a
// wrong field count, a non-numeric, NaN or infinite field, a zero-norm quaternion, or a time
// not after the previous one (a duplicate time names both lines).
Trajectory ReadTumTrajectory(const std::filesystem::path& path);

// Same, for text already in memory; `source_name` names the text in error messages.
Trajectory ParseTumTrajectory(std::string_view text, const std::string& source_name);

// Writes `trajectory` atomically as a TUM file: a `#` header line, then one line per pose with
// the time as FormatNanosecondsAsSeconds() and every double in its shortest exact (round-trip)
// form. Throws IoError when the file cannot be written.
void WriteTumTrajectory(const std::filesystem::path& path, const Trajectory& trajectory);

// The TUM text WriteTumTrajectory() writes.
std::string FormatTumTrajectory(const Trajectory& trajectory);

// Parses a decimal number of seconds ("1305031102.175304", "-0.5", "12") exactly into integer
// nanoseconds, without going through a double. Digits beyond the ninth decimal are rounded to
// the nearest nanosecond (halves away from zero). Throws InvalidArgumentError for anything else
// (exponents, NaN, empty text, a value outside the int64 nanosecond range).
int64_t ParseSecondsAsNanoseconds(std::string_view text);

// Formats nanoseconds as seconds with exactly nine decimals ("1305031102.175304000"); the
// inverse of ParseSecondsAsNanoseconds() for every int64 value.
std::string FormatNanosecondsAsSeconds(int64_t t_ns);

}  // namespace evloc
