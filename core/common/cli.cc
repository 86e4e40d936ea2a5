#include "core/common/cli.h"

#include <charconv>
#include <cmath>
#include <limits>

#include "core/common/error.h"

namespace evloc {

const std::string& TakeFlagValue(const std::vector<std::string>& arguments, size_t* index) {
  const std::string& flag = arguments[*index];
  if (*index + 1 >= arguments.size()) {
    throw InvalidArgumentError(flag.rfind("--", 0) == 0 ? flag + " needs a value"
                                                        : "unexpected argument '" + flag + "'");
  }
  return arguments[++*index];
}

double ParseDoubleFlag(std::string_view flag, std::string_view text) {
  double value = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || error != std::errc() || end != text.data() + text.size() ||
      !std::isfinite(value)) {
    throw InvalidArgumentError(std::string(flag) + " expects a number, got '" + std::string(text) +
                               "'");
  }
  return value;
}

int64_t ParseIntegerFlag(std::string_view flag, std::string_view text) {
  int64_t value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || error != std::errc() || end != text.data() + text.size()) {
    throw InvalidArgumentError(std::string(flag) + " expects an integer, got '" +
                               std::string(text) + "'");
  }
  return value;
}

int ParseIntFlag(std::string_view flag, std::string_view text) {
  const int64_t value = ParseIntegerFlag(flag, text);
  if (value < std::numeric_limits<int>::min() || value > std::numeric_limits<int>::max()) {
    throw InvalidArgumentError(std::string(flag) + " is out of range: '" + std::string(text) + "'");
  }
  return static_cast<int>(value);
}

void ParseSizeFlag(std::string_view flag, std::string_view text, int* width, int* height) {
  const size_t x = text.find('x');
  if (x == std::string_view::npos) {
    throw InvalidArgumentError(std::string(flag) + " expects WIDTHxHEIGHT, got '" +
                               std::string(text) + "'");
  }
  *width = ParseIntFlag(flag, text.substr(0, x));
  *height = ParseIntFlag(flag, text.substr(x + 1));
  if (*width <= 0 || *height <= 0) {
    throw InvalidArgumentError(std::string(flag) + " expects positive sizes, got '" +
                               std::string(text) + "'");
  }
}

bool ParseSwitchFlag(std::string_view flag, std::string_view text) {
  if (text == "on" || text == "true" || text == "1") return true;
  if (text == "off" || text == "false" || text == "0") return false;
  throw InvalidArgumentError(std::string(flag) + " expects on or off, got '" + std::string(text) +
                             "'");
}

}  // namespace evloc
