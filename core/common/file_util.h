// Small file helpers shared by every module that writes files.
#pragma once

#include <filesystem>
#include <functional>
#include <ostream>
#include <string>
#include <string_view>

namespace evloc {

// Writes a file atomically: `write` fills a stream on a temporary file next to `path`, which is
// flushed, synced and renamed over `path` only if `write` returns without throwing. A crash or an
// error never leaves a half-written `path`. Throws IoError when the file cannot be written.
void WriteFileAtomically(const std::filesystem::path& path,
                         const std::function<void(std::ostream&)>& write);

// Same, for content already in memory.
void WriteFileAtomically(const std::filesystem::path& path, std::string_view content);

// Reads a whole (small) file into a string. Throws IoError when it cannot.
std::string ReadFileToString(const std::filesystem::path& path);

}  // namespace evloc
