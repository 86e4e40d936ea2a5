// libFuzzer target: the JSON lines of the logging facade (core/common/log.h; docs/reliability.md).
// The input is a message, a field key and a field value separated by NUL bytes (any bytes,
// invalid UTF-8 included). Every rendered line is one valid JSON object on one line; its message,
// key and value read back as given when the input is valid UTF-8 (invalid bytes become U+FFFD).
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/common/log.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<std::string> parts(1);
  for (size_t i = 0; i < size; ++i) {
    if (data[i] == 0 && parts.size() < 3) {
      parts.emplace_back();
    } else {
      parts.back() += static_cast<char>(data[i]);
    }
  }
  parts.resize(3);
  const std::string line = evloc::RenderLogLine(
      evloc::LogFormat::kJson, parts[1], evloc::LogLevel::kWarning,
      int64_t{1'764'000'000'000'000'000} + static_cast<int64_t>(size), parts[0],
      {{parts[1], parts[2]}, {"n", static_cast<int64_t>(size)}}, size % 2 == 0 ? 0 : size);
  if (line.find('\n') != std::string::npos) std::abort();
  const nlohmann::json record = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
  if (!record.is_object() || record["level"] != "warning" || !record.contains("fields")) {
    std::abort();
  }
  if ((size % 2 == 1) != record.contains("session")) std::abort();
  const auto valid_utf8 = [](const std::string& text) {
    return evloc::JsonEscape(text).find("\\ufffd") == std::string::npos;
  };
  if (valid_utf8(parts[0]) && record["message"] != parts[0]) std::abort();
  if (valid_utf8(parts[1]) && valid_utf8(parts[2]) && record["fields"].size() == 2 &&
      parts[1] != "n" && record["fields"][parts[1]] != parts[2]) {
    std::abort();
  }
  return 0;
}
