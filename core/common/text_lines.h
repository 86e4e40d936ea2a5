// The one loop over the data lines of a line-based text format (lists, cameras.txt, ...).
#pragma once

#include <cstdint>
#include <sstream>
#include <string>
#include <string_view>

namespace evloc {

// Calls `visit(line_number, line)` for each data line of `text`: its 1-based number and the line
// without a trailing '\r' (CRLF files). Blank lines and lines whose first character other than
// spaces and tabs is '#' (comments) are skipped.
template <typename Visit>
void ForEachDataLine(std::string_view text, const Visit& visit) {
  std::istringstream lines{std::string(text)};
  std::string line;
  int64_t line_number = 0;
  while (std::getline(lines, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const size_t first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    visit(line_number, line);
  }
}

}  // namespace evloc
