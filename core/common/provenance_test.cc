#include "core/common/provenance.h"

#include <chrono>
#include <ctime>
#include <regex>
#include <string>

#include <gtest/gtest.h>

namespace evloc {
namespace {

TEST(UtcNowIso8601, IsNowInUtcToTheSecond) {
  const auto before = std::chrono::system_clock::now();
  const std::string text = UtcNowIso8601();
  const auto after = std::chrono::system_clock::now();
  ASSERT_TRUE(std::regex_match(text, std::regex(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ)"))) << text;
  std::tm utc{};
  ASSERT_NE(strptime(text.c_str(), "%Y-%m-%dT%H:%M:%SZ", &utc), nullptr);
  const auto stamped = std::chrono::system_clock::from_time_t(timegm(&utc));
  EXPECT_LE(stamped, after);
  EXPECT_GT(stamped, before - std::chrono::seconds(1));
}

TEST(ToolVersion, IsTheProjectVersion) {
  EXPECT_TRUE(std::regex_match(ToolVersion(), std::regex(R"(\d+\.\d+\.\d+)"))) << ToolVersion();
}

}  // namespace
}  // namespace evloc
