#include "localizer/service/client_text.h"

#include <cstdio>
#include <system_error>
#include <vector>

namespace evloc::service {
namespace {

// Removes every occurrence of `prefix` from `text`.
void RemoveAll(const std::string& prefix, std::string* text) {
  if (prefix.empty()) return;
  for (size_t at = text->find(prefix); at != std::string::npos; at = text->find(prefix, at)) {
    text->erase(at, prefix.size());
  }
}

bool StartsPath(const std::string& text, size_t at) {
  if (text[at] != '/') return false;
  if (at == 0) return true;
  const char before = text[at - 1];
  return before == ' ' || before == '\'' || before == '"' || before == '(' || before == '=' ||
         before == ':' || before == '`';
}

bool EndsPath(char c) {
  return c == ' ' || c == '\'' || c == '"' || c == ')' || c == ',' || c == ';' || c == '`' ||
         c == '\n';
}

}  // namespace

std::string EscapeForLog(const std::string& text, size_t max_bytes) {
  std::string escaped;
  const size_t kept = std::min(text.size(), max_bytes);
  escaped.reserve(kept);
  for (size_t i = 0; i < kept; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x20 && c < 0x7f && c != '\\') {
      escaped += static_cast<char>(c);
    } else {
      char hex[8];
      std::snprintf(hex, sizeof(hex), "\\x%02x", c);
      escaped += hex;
    }
  }
  if (kept < text.size()) escaped += "...(" + std::to_string(text.size()) + " bytes)";
  return escaped;
}

std::string ScrubServerPaths(const std::string& message, const std::filesystem::path& maps_dir) {
  std::string text = message;
  if (!maps_dir.empty()) {
    std::vector<std::string> prefixes{maps_dir.lexically_normal().string()};
    std::error_code error;
    const std::filesystem::path absolute = std::filesystem::absolute(maps_dir, error);
    if (!error) prefixes.push_back(absolute.lexically_normal().string());
    const std::filesystem::path canonical = std::filesystem::weakly_canonical(maps_dir, error);
    if (!error) prefixes.push_back(canonical.string());
    prefixes.push_back(maps_dir.string());
    for (std::string prefix : prefixes) {
      while (prefix.size() > 1 && prefix.back() == '/') prefix.pop_back();
      if (prefix.empty() || prefix == "/") continue;
      RemoveAll(prefix + "/", &text);
    }
  }
  std::string scrubbed;
  scrubbed.reserve(text.size());
  for (size_t i = 0; i < text.size();) {
    if (!StartsPath(text, i)) {
      scrubbed += text[i++];
      continue;
    }
    size_t end = i;
    while (end < text.size() && !EndsPath(text[end])) ++end;
    // A lone '/' or one followed by a space is not a path (e.g. "a / b").
    std::string path = text.substr(i, end - i);
    while (path.size() > 1 && (path.back() == '.' || path.back() == '/')) {
      path.pop_back();
      --end;
    }
    const size_t last = path.find_last_of('/');
    scrubbed += path.size() > 1 ? path.substr(last + 1) : path;
    i = end;
  }
  return scrubbed;
}

}  // namespace evloc::service
