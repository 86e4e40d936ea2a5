// Helpers shared by the command-line tools: strict parsing of flag values, with errors that
// name the flag and the offending text.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace evloc {

// The value of the flag arguments[*index], i.e. the next argument, with *index moved onto it.
// Throws InvalidArgumentError "FLAG needs a value" when a "--" flag is the last argument, and
// "unexpected argument 'TEXT'" for a last argument that is no flag.
const std::string& TakeFlagValue(const std::vector<std::string>& arguments, size_t* index);

// Parses a finite floating-point number; the whole text must be consumed. Throws
// InvalidArgumentError "FLAG expects a number, got 'TEXT'".
double ParseDoubleFlag(std::string_view flag, std::string_view text);

// Parses a base-10 integer; the whole text must be consumed. Throws InvalidArgumentError.
int64_t ParseIntegerFlag(std::string_view flag, std::string_view text);

// Parses a base-10 integer that fits an int. Throws InvalidArgumentError.
int ParseIntFlag(std::string_view flag, std::string_view text);

// Parses a size "WIDTHxHEIGHT" of two positive integers. Throws InvalidArgumentError.
void ParseSizeFlag(std::string_view flag, std::string_view text, int* width, int* height);

// Parses "on"/"off" (also "true"/"false", "1"/"0"). Throws InvalidArgumentError.
bool ParseSwitchFlag(std::string_view flag, std::string_view text);

}  // namespace evloc
