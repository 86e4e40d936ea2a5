#include "core/trajectory/tum_io.h"

#include <array>
#include <charconv>
#include <cmath>
#include <limits>
#include <vector>

#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc {
namespace {

constexpr int64_t kNanosecondsPerSecond = 1'000'000'000;
constexpr int kFieldsPerLine = 8;

// Splits a line into fields separated by spaces, tabs or commas.
std::vector<std::string_view> SplitFields(std::string_view line) {
  std::vector<std::string_view> fields;
  size_t position = 0;
  const auto is_separator = [](char c) { return c == ' ' || c == '\t' || c == ','; };
  while (position < line.size()) {
    while (position < line.size() && is_separator(line[position])) ++position;
    const size_t begin = position;
    while (position < line.size() && !is_separator(line[position])) ++position;
    if (position > begin) fields.push_back(line.substr(begin, position - begin));
  }
  return fields;
}

// Parses a finite double from the whole of `text`, or throws InvalidArgumentError.
double ParseFiniteDouble(std::string_view text) {
  double value = 0.0;
  const char* begin = text.data();
  const char* end = text.data() + text.size();
  if (!text.empty() && *begin == '+') ++begin;
  const auto [pointer, error] = std::from_chars(begin, end, value);
  if (error != std::errc() || pointer != end) {
    throw InvalidArgumentError("'" + std::string(text) + "' is not a number");
  }
  if (!std::isfinite(value)) {
    throw InvalidArgumentError("'" + std::string(text) + "' is not a finite number");
  }
  return value;
}

// Appends the shortest decimal form of `value` that reads back to the same double.
void AppendShortest(std::string& out, double value) {
  std::array<char, 64> buffer;
  const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  out.append(buffer.data(), result.ptr);
}

}  // namespace

int64_t ParseSecondsAsNanoseconds(std::string_view text) {
  const auto fail = [&](const std::string& why) {
    return InvalidArgumentError("time '" + std::string(text) + "' " + why +
                                "; expected decimal seconds such as 1305031102.175304");
  };
  size_t position = 0;
  bool negative = false;
  if (position < text.size() && (text[position] == '-' || text[position] == '+')) {
    negative = text[position] == '-';
    ++position;
  }
  // Accumulate the magnitude as a non-positive number so that INT64_MIN is representable.
  constexpr int64_t kMin = std::numeric_limits<int64_t>::min();
  int64_t whole_seconds_negated = 0;
  size_t digit_count = 0;
  for (; position < text.size() && text[position] >= '0' && text[position] <= '9'; ++position) {
    const int digit = text[position] - '0';
    if (whole_seconds_negated < (kMin + digit) / 10) throw fail("is out of range");
    whole_seconds_negated = whole_seconds_negated * 10 - digit;
    ++digit_count;
  }
  int64_t fraction_ns = 0;
  bool round_up = false;
  if (position < text.size() && text[position] == '.') {
    ++position;
    int fraction_digits = 0;
    for (; position < text.size() && text[position] >= '0' && text[position] <= '9'; ++position) {
      const int digit = text[position] - '0';
      if (fraction_digits < 9) {
        fraction_ns = fraction_ns * 10 + digit;
      } else if (fraction_digits == 9) {
        round_up = digit >= 5;
      }
      ++fraction_digits;
      ++digit_count;
    }
    for (int i = fraction_digits; i < 9; ++i) fraction_ns *= 10;
  }
  if (digit_count == 0) throw fail("has no digits");
  if (position != text.size()) throw fail("is not a plain decimal number");
  if (round_up) ++fraction_ns;
  // total_negated = -(whole * 1e9 + fraction), checked for overflow.
  if (whole_seconds_negated < kMin / kNanosecondsPerSecond) throw fail("is out of range");
  int64_t total_negated = whole_seconds_negated * kNanosecondsPerSecond;
  if (total_negated < kMin + fraction_ns) throw fail("is out of range");
  total_negated -= fraction_ns;
  if (negative) return total_negated;
  if (total_negated == kMin) throw fail("is out of range");
  return -total_negated;
}

std::string FormatNanosecondsAsSeconds(int64_t t_ns) {
  // Work on the magnitude as unsigned so that INT64_MIN is formatted correctly.
  const bool negative = t_ns < 0;
  const uint64_t magnitude =
      negative ? static_cast<uint64_t>(-(t_ns + 1)) + 1 : static_cast<uint64_t>(t_ns);
  const uint64_t seconds = magnitude / kNanosecondsPerSecond;
  const uint64_t nanoseconds = magnitude % kNanosecondsPerSecond;
  std::string fraction = std::to_string(nanoseconds);
  fraction.insert(0, 9 - fraction.size(), '0');
  return (negative ? "-" : "") + std::to_string(seconds) + "." + fraction;
}

Trajectory ParseTumTrajectory(std::string_view text, const std::string& source_name) {
  Trajectory trajectory;
  int64_t previous_line = 0;
  int64_t line_number = 0;
  size_t line_begin = 0;
  while (line_begin < text.size()) {
    size_t line_end = text.find('\n', line_begin);
    if (line_end == std::string_view::npos) line_end = text.size();
    std::string_view line = text.substr(line_begin, line_end - line_begin);
    line_begin = line_end + 1;
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);

    const std::vector<std::string_view> fields = SplitFields(line);
    if (fields.empty() || fields.front().front() == '#') continue;
    if (trajectory.empty() && fields.front() == "timestamp") continue;  // Column header.
    if (fields.size() != kFieldsPerLine) {
      throw ParseError::AtLine(
          source_name, line_number,
          "expected 8 fields 't tx ty tz qx qy qz qw', found " + std::to_string(fields.size()));
    }
    TimedPose pose;
    std::array<double, 7> values;
    try {
      pose.t_ns = ParseSecondsAsNanoseconds(fields[0]);
      for (int i = 0; i < 7; ++i) values[i] = ParseFiniteDouble(fields[i + 1]);
    } catch (const InvalidArgumentError& error) {
      throw ParseError::AtLine(source_name, line_number, error.what());
    }
    const Eigen::Quaterniond rotation(values[6], values[3], values[4], values[5]);
    if (!(rotation.norm() > 1e-9)) {
      throw ParseError::AtLine(source_name, line_number,
                               "quaternion (qx qy qz qw) has zero norm; it must be a rotation");
    }
    pose.world_from_cam =
        Rigid3d(rotation.normalized(), Eigen::Vector3d(values[0], values[1], values[2]));
    if (!trajectory.empty() && pose.t_ns <= trajectory.end_ns()) {
      const std::string previous = FormatNanosecondsAsSeconds(trajectory.end_ns());
      const std::string what = pose.t_ns == trajectory.end_ns()
                                   ? "duplicate time " + previous + " s (also on line " +
                                         std::to_string(previous_line) + ")"
                                   : "time " + FormatNanosecondsAsSeconds(pose.t_ns) +
                                         " s is before " + previous + " s on line " +
                                         std::to_string(previous_line) +
                                         "; poses must be in increasing time order";
      throw ParseError::AtLine(source_name, line_number, what);
    }
    trajectory.Append(pose);
    previous_line = line_number;
  }
  return trajectory;
}

Trajectory ReadTumTrajectory(const std::filesystem::path& path) {
  return ParseTumTrajectory(ReadFileToString(path), path.string());
}

std::string FormatTumTrajectory(const Trajectory& trajectory) {
  std::string out = "# timestamp tx ty tz qx qy qz qw (world_from_cam, seconds, metres)\n";
  for (const TimedPose& pose : trajectory.poses()) {
    out += FormatNanosecondsAsSeconds(pose.t_ns);
    const Eigen::Vector3d& t = pose.world_from_cam.translation;
    const Eigen::Quaterniond& q = pose.world_from_cam.rotation;
    for (const double value : {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()}) {
      out += ' ';
      AppendShortest(out, value);
    }
    out += '\n';
  }
  return out;
}

void WriteTumTrajectory(const std::filesystem::path& path, const Trajectory& trajectory) {
  WriteFileAtomically(path, FormatTumTrajectory(trajectory));
}

}  // namespace evloc
