#include "core/common/test_data.h"

#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>

namespace evloc::testing {

std::filesystem::path SourceDir() { return EVLOC_SOURCE_DIR; }

int RunShellCommand(const std::string& command, std::string* output) {
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return -1;
  char buffer[4096];
  size_t count = 0;
  while ((count = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) output->append(buffer, count);
  return ::pclose(pipe);
}

std::optional<std::filesystem::path> SharedDataDir() {
  if (const char* from_environment = std::getenv("EVLOC_DATA_DIR")) {
    if (std::filesystem::is_directory(from_environment)) {
      return std::filesystem::path(from_environment);
    }
    return std::nullopt;
  }
  const std::filesystem::path beside_source = SourceDir() / ".." / "shared" / "data";
  if (std::filesystem::is_directory(beside_source)) {
    return std::filesystem::weakly_canonical(beside_source);
  }
  return std::nullopt;
}

std::optional<std::filesystem::path> SharedDataFile(const std::string& relative) {
  const auto directory = SharedDataDir();
  if (!directory) return std::nullopt;
  const std::filesystem::path file = *directory / relative;
  if (!std::filesystem::exists(file)) return std::nullopt;
  return file;
}

std::string MissingDataReason(const std::string& relative) {
  return "shared data '" + relative +
         "' is absent: set EVLOC_DATA_DIR or place the data in ../shared/data beside the "
         "source tree to run this test";
}

std::filesystem::path MakeTempDir(const std::string& prefix) {
  static std::atomic<int> counter{0};
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() /
      (prefix + "-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
  std::filesystem::remove_all(directory);
  std::filesystem::create_directories(directory);
  return directory;
}

}  // namespace evloc::testing
