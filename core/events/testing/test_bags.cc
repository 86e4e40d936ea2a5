#include "core/events/testing/test_bags.h"

#include <fstream>
#include <sstream>

#include "core/common/test_data.h"

namespace evloc::testing {
namespace {

constexpr char kPython[] = "/usr/bin/python3";

}  // namespace

std::optional<std::filesystem::path> TestBagsDir(std::string* reason) {
  static std::optional<std::filesystem::path> dir;
  static std::string failure;
  static bool done = false;
  if (!done) {
    done = true;
    std::string output;
    if (RunShellCommand(std::string(kPython) + " -c 'import rosbag, genpy, roslz4' 2>&1",
                        &output) != 0) {
      failure = std::string(kPython) +
                " lacks rosbag, genpy or roslz4 (Debian: python3-rosbag python3-roslz4, see "
                "scripts/install-deps.sh): " +
                output;
    } else {
      const std::filesystem::path folder = MakeTempDir("bags");
      const std::string command =
          std::string(kPython) + " '" +
          (SourceDir() / "core/events/testing/write_test_bags.py").string() + "' '" +
          folder.string() + "' 2>&1";
      if (RunShellCommand(command, &output) != 0) {
        failure = "write_test_bags.py failed: " + output;
      } else {
        dir = folder;
      }
    }
  }
  if (!dir && reason) *reason = failure;
  return dir;
}

std::vector<std::vector<std::string>> ReadExpectedLines(const std::filesystem::path& dir,
                                                        const std::string& name) {
  std::ifstream file(dir / ("expected_" + name + ".txt"));
  std::vector<std::vector<std::string>> lines;
  std::string line;
  while (std::getline(file, line)) {
    std::istringstream fields(line);
    std::vector<std::string> words;
    std::string word;
    while (fields >> word) words.push_back(word);
    if (!words.empty()) lines.push_back(words);
  }
  return lines;
}

EventBuffer ReadExpectedEvents(const std::filesystem::path& dir, const std::string& name) {
  EventBuffer events;
  for (const auto& words : ReadExpectedLines(dir, name)) {
    events.push_back({std::stoll(words.at(0)), static_cast<uint16_t>(std::stoi(words.at(1))),
                      static_cast<uint16_t>(std::stoi(words.at(2))),
                      static_cast<int8_t>(std::stoi(words.at(3)))});
  }
  return events;
}

}  // namespace evloc::testing
