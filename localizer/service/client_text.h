// Text that crosses the trust boundary of the localizer service (docs/api.md, "Limits"): strings
// a client chose (client_name, map names) before they go into a log line, and error messages
// before they go back to a client (no server paths).
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>

namespace evloc::service {

// Longest client string kept in a log line, bytes (longer ones are cut and marked).
inline constexpr size_t kMaxLoggedClientStringBytes = 128;

// `text` made safe for one log line: printable ASCII is kept except the backslash, everything else
// (newlines, control bytes, non-ASCII bytes) becomes \xHH; cut after `max_bytes` input
// bytes with "...(N bytes)" appended. A client cannot forge log lines or flood the log with it.
std::string EscapeForLog(const std::string& text, size_t max_bytes = kMaxLoggedClientStringBytes);

// `message` without server paths, for a status a client receives: `maps_dir` (as given and
// absolute) followed by '/' is removed (a map file then reads NAME/map.evmap), and every other
// absolute path (a '/' at the start of the message or after a space, quote, parenthesis, '=' or
// ':') is replaced by its last component.
std::string ScrubServerPaths(const std::string& message, const std::filesystem::path& maps_dir);

}  // namespace evloc::service
