// Number and name helpers shared by the calibration readers and writers of core/camera (internal
// to the module: not part of its API).
#pragma once

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <string>
#include <string_view>
#include <system_error>

namespace evloc::camera_text {

// Parses a whole string as a double (finite or not); false when anything is left over.
inline bool ParseDouble(std::string_view text, double* value) {
  const char* begin = text.data();
  const char* end = text.data() + text.size();
  const auto [pointer, error] = std::from_chars(begin, end, *value);
  return error == std::errc() && pointer == end;
}

// The shortest decimal text that reads back as exactly `value`.
inline std::string FormatDouble(double value) {
  std::array<char, 64> buffer;
  const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  return std::string(buffer.data(), result.ptr);
}

// `text` in lower case (ASCII).
inline std::string ToLower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

}  // namespace evloc::camera_text
