#include "core/events/testing/test_bags.h"

#include <fstream>
#include <sstream>

#include "core/common/test_data.h"

namespace evloc::testing {
namespace {

constexpr char kPython[] = "/usr/bin/python3";

// Runs `script` (a writer in core/events/testing) once into a new temporary folder, after
// checking that /usr/bin/python3 imports `modules`; `packages` names what to install.
std::optional<std::filesystem::path> RunTestWriter(const std::string& script,
                                                   const std::string& modules,
                                                   const std::string& packages,
                                                   std::string* failure) {
  std::string output;
  if (RunShellCommand(std::string(kPython) + " -c 'import " + modules + "' 2>&1", &output) != 0) {
    *failure = std::string(kPython) + " lacks " + modules + " (Debian: " + packages +
               ", see scripts/install-deps.sh): " + output;
    return std::nullopt;
  }
  const std::filesystem::path folder = MakeTempDir(script.substr(0, script.find('.')));
  const std::string command = std::string(kPython) + " '" +
                              (SourceDir() / "core/events/testing" / script).string() + "' '" +
                              folder.string() + "' 2>&1";
  if (RunShellCommand(command, &output) != 0) {
    *failure = script + " failed: " + output;
    return std::nullopt;
  }
  return folder;
}

}  // namespace

std::optional<std::filesystem::path> TestBagsDir(std::string* reason) {
  static std::string failure;
  static const std::optional<std::filesystem::path> dir = RunTestWriter(
      "write_test_bags.py", "rosbag, genpy, roslz4", "python3-rosbag python3-roslz4", &failure);
  if (!dir && reason) *reason = failure;
  return dir;
}

std::optional<std::filesystem::path> TestAedat4Dir(std::string* reason) {
  static std::string failure;
  static const std::optional<std::filesystem::path> dir =
      RunTestWriter("write_test_aedat4.py", "flatbuffers, lz4.frame, zstandard, numpy",
                    "python3-flatbuffers python3-lz4 python3-zstandard python3-numpy", &failure);
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

std::string ReadBytes(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(file), {});
}

std::unique_ptr<std::istream> StreamOf(const std::string& bytes) {
  return std::make_unique<std::istringstream>(bytes);
}

EventBuffer ReadAllEvents(EventReader* reader, size_t batch) {
  EventBuffer events;
  while (reader->Read(batch, &events) > 0) {
  }
  return events;
}

}  // namespace evloc::testing
