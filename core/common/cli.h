// Helpers shared by the command-line tools: the main() wrapper every evloc-* tool runs in
// (RunTool: one error line format, one set of exit codes, docs/conventions.md "Exit codes"), and
// strict parsing of flag values, with errors that name the flag and the offending text.
#pragma once

#include <cstdint>
#include <functional>
#include <iostream>
#include <optional>
#include <ostream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/common/error.h"

namespace evloc {

// Exit code of a tool that did what it was asked.
inline constexpr int kExitSuccess = 0;
// Exit code of a tool that failed while running (bad input file, I/O, any error but usage).
inline constexpr int kExitFailure = 1;
// Exit code of a tool given a bad command line (UsageError).
inline constexpr int kExitUsage = 2;

// A mistake on the command line: an unknown flag, a missing or malformed value, an option value
// outside its domain. RunTool reports it with a pointer to --help and exit code kExitUsage. It
// is an InvalidArgumentError, so code that validates values catches it as one.
class UsageError : public InvalidArgumentError {
 public:
  using InvalidArgumentError::InvalidArgumentError;
};

// Runs `body` and returns its exit code; an exception becomes one line on `err`,
// "NAME: error: MESSAGE", and an exit code: UsageError kExitUsage (followed by the line "Run
// `NAME --help` for the usage."), any other exception kExitFailure. Never throws.
int RunGuarded(std::string_view name, std::ostream& err, const std::function<int()>& body);

// The main() of an evloc-* tool named `name`: RunGuarded over `body` given the arguments after
// the program name, errors on std::cerr.
int RunTool(std::string_view name, int argc, const char* const* argv,
            const std::function<int(const std::vector<std::string>& arguments)>& body);

// Calls `parse(arguments)` and returns its result, rethrowing every evloc::Error as a
// UsageError with the same message: for command-line parsers all of whose errors (option
// Check() failures included) are mistakes on the command line.
template <typename Parse>
auto ParseCommandLine(const Parse& parse, const std::vector<std::string>& arguments)
    -> decltype(parse(arguments)) {
  try {
    return parse(arguments);
  } catch (const UsageError&) {
    throw;
  } catch (const Error& error) {
    throw UsageError(error.what());
  }
}

// The main() of a tool whose command line `parse` turns into a command with a `help` field:
// RunTool over parsing (every parser error a UsageError, ParseCommandLine), printing `usage()`
// on stdout when help was asked for (exit kExitSuccess), and otherwise `run(command)`, whose
// return value is the exit code.
template <typename Parse, typename Usage, typename Run>
int RunCommandTool(std::string_view name, int argc, const char* const* argv, const Parse& parse,
                   const Usage& usage, const Run& run) {
  return RunTool(name, argc, argv, [&](const std::vector<std::string>& arguments) -> int {
    const auto command = ParseCommandLine(parse, arguments);
    if (command.help) {
      std::cout << usage();
      return kExitSuccess;
    }
    return run(command);
  });
}

// The value of the flag arguments[*index], i.e. the next argument, with *index moved onto it.
// Throws UsageError "FLAG needs a value" when a "--" flag is the last argument, and
// "unexpected argument 'TEXT'" for a last argument that is no flag.
const std::string& TakeFlagValue(const std::vector<std::string>& arguments, size_t* index);

// Parses a finite floating-point number (no nan, no inf); the whole text must be consumed.
// Throws UsageError "FLAG expects a number, got 'TEXT'".
double ParseDoubleFlag(std::string_view flag, std::string_view text);

// Parses a finite number as ParseDoubleFlag does, or `word` for none ("--speed max": nullopt).
std::optional<double> ParseDoubleOrWordFlag(std::string_view flag, std::string_view text,
                                            std::string_view word);

// Parses a base-10 integer; the whole text must be consumed. Throws UsageError.
int64_t ParseIntegerFlag(std::string_view flag, std::string_view text);

// Parses a non-negative base-10 integer (no sign); the whole text must be consumed. Throws
// UsageError.
uint64_t ParseUnsignedFlag(std::string_view flag, std::string_view text);

// Parses a byte count: a non-negative integer with an optional binary suffix K, M, G or T (2^10,
// 2^20, 2^30, 2^40; "2G" is 2147483648), at most 2^50. Throws UsageError.
uint64_t ParseByteSizeFlag(std::string_view flag, std::string_view text);

// Parses a base-10 integer that fits an int. Throws UsageError.
int ParseIntFlag(std::string_view flag, std::string_view text);

// Parses "A,B", two finite numbers as ParseDoubleFlag does ("--motion-prior 2,0"). Throws
// UsageError.
std::pair<double, double> ParseDoublePairFlag(std::string_view flag, std::string_view text);

// Parses "A,B,...", one or more finite numbers as ParseDoubleFlag does ("--segments 0.5,1,2").
// Throws UsageError.
std::vector<double> ParseDoubleListFlag(std::string_view flag, std::string_view text);

// Parses a size "WIDTHxHEIGHT" of two positive integers. Throws UsageError.
void ParseSizeFlag(std::string_view flag, std::string_view text, int* width, int* height);

// Parses "on"/"off" (also "true"/"false", "1"/"0"). Throws UsageError.
bool ParseSwitchFlag(std::string_view flag, std::string_view text);

// Parses one of two words: false for `no`, true for `yes` (e.g. "rest" / "truth"). Throws
// UsageError naming both.
bool ParseTwoWordFlag(std::string_view flag, std::string_view text, std::string_view no,
                      std::string_view yes);

}  // namespace evloc
