#include "core/common/cli.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <exception>
#include <iostream>
#include <limits>

namespace evloc {

int RunGuarded(std::string_view name, std::ostream& err, const std::function<int()>& body) {
  try {
    return body();
  } catch (const UsageError& error) {
    err << name << ": error: " << error.what() << "\nRun `" << name << " --help` for the usage.\n";
    return kExitUsage;
  } catch (const std::exception& error) {
    err << name << ": error: " << error.what() << "\n";
    return kExitFailure;
  } catch (...) {
    err << name << ": error: an unknown exception\n";
    return kExitFailure;
  }
}

int RunTool(std::string_view name, int argc, const char* const* argv,
            const std::function<int(const std::vector<std::string>& arguments)>& body) {
  const std::vector<std::string> arguments(argv + std::min(argc, 1), argv + argc);
  return RunGuarded(name, std::cerr, [&] { return body(arguments); });
}

const std::string& TakeFlagValue(const std::vector<std::string>& arguments, size_t* index) {
  const std::string& flag = arguments[*index];
  if (*index + 1 >= arguments.size()) {
    throw UsageError(flag.rfind("--", 0) == 0 ? flag + " needs a value"
                                              : "unexpected argument '" + flag + "'");
  }
  return arguments[++*index];
}

double ParseDoubleFlag(std::string_view flag, std::string_view text) {
  double value = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || error != std::errc() || end != text.data() + text.size() ||
      !std::isfinite(value)) {
    throw UsageError(std::string(flag) + " expects a number, got '" + std::string(text) + "'");
  }
  return value;
}

std::optional<double> ParseDoubleOrWordFlag(std::string_view flag, std::string_view text,
                                            std::string_view word) {
  if (text == word) return std::nullopt;
  return ParseDoubleFlag(flag, text);
}

namespace {

// Parses a whole base-10 number of type T; throws UsageError "FLAG expects WHAT, got 'TEXT'".
template <typename T>
T ParseWholeNumber(std::string_view flag, std::string_view text, std::string_view what) {
  T value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || error != std::errc() || end != text.data() + text.size()) {
    throw UsageError(std::string(flag) + " expects " + std::string(what) + ", got '" +
                     std::string(text) + "'");
  }
  return value;
}

}  // namespace

int64_t ParseIntegerFlag(std::string_view flag, std::string_view text) {
  return ParseWholeNumber<int64_t>(flag, text, "an integer");
}

uint64_t ParseUnsignedFlag(std::string_view flag, std::string_view text) {
  return ParseWholeNumber<uint64_t>(flag, text, "a non-negative integer");
}

uint64_t ParseByteSizeFlag(std::string_view flag, std::string_view text) {
  int shift = 0;
  std::string_view digits = text;
  if (!text.empty()) {
    switch (text.back()) {
      case 'K':
      case 'k':
        shift = 10;
        break;
      case 'M':
      case 'm':
        shift = 20;
        break;
      case 'G':
      case 'g':
        shift = 30;
        break;
      case 'T':
      case 't':
        shift = 40;
        break;
      default:
        break;
    }
    if (shift > 0) digits.remove_suffix(1);
  }
  const uint64_t value = ParseWholeNumber<uint64_t>(flag, digits, "a byte count (e.g. 2G, 512M)");
  constexpr uint64_t kLimit = uint64_t{1} << 50;
  if (value > (kLimit >> shift)) {
    throw UsageError(std::string(flag) + " is out of range (at most 1024T): '" + std::string(text) +
                     "'");
  }
  return value << shift;
}

int ParseIntFlag(std::string_view flag, std::string_view text) {
  const int64_t value = ParseIntegerFlag(flag, text);
  if (value < std::numeric_limits<int>::min() || value > std::numeric_limits<int>::max()) {
    throw UsageError(std::string(flag) + " is out of range: '" + std::string(text) + "'");
  }
  return static_cast<int>(value);
}

std::vector<double> ParseDoubleListFlag(std::string_view flag, std::string_view text) {
  std::vector<double> values;
  size_t begin = 0;
  while (true) {
    const size_t comma = text.find(',', begin);
    values.push_back(ParseDoubleFlag(flag, text.substr(begin, comma - begin)));
    if (comma == std::string_view::npos) return values;
    begin = comma + 1;
  }
}

std::pair<double, double> ParseDoublePairFlag(std::string_view flag, std::string_view text) {
  const std::vector<double> values = ParseDoubleListFlag(flag, text);
  if (values.size() != 2) {
    throw UsageError(std::string(flag) + " expects two numbers A,B, got '" + std::string(text) +
                     "'");
  }
  return {values[0], values[1]};
}

void ParseSizeFlag(std::string_view flag, std::string_view text, int* width, int* height) {
  const size_t x = text.find('x');
  if (x == std::string_view::npos) {
    throw UsageError(std::string(flag) + " expects WIDTHxHEIGHT, got '" + std::string(text) + "'");
  }
  *width = ParseIntFlag(flag, text.substr(0, x));
  *height = ParseIntFlag(flag, text.substr(x + 1));
  if (*width <= 0 || *height <= 0) {
    throw UsageError(std::string(flag) + " expects positive sizes, got '" + std::string(text) +
                     "'");
  }
}

bool ParseSwitchFlag(std::string_view flag, std::string_view text) {
  if (text == "on" || text == "true" || text == "1") return true;
  if (text == "off" || text == "false" || text == "0") return false;
  throw UsageError(std::string(flag) + " expects on or off, got '" + std::string(text) + "'");
}

bool ParseTwoWordFlag(std::string_view flag, std::string_view text, std::string_view no,
                      std::string_view yes) {
  if (text == yes) return true;
  if (text == no) return false;
  throw UsageError(std::string(flag) + " expects " + std::string(no) + " or " + std::string(yes) +
                   ", got '" + std::string(text) + "'");
}

}  // namespace evloc
