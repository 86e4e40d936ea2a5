// libFuzzer target: the CLI11 adapter of the tools (core/common/cli_app.h; docs/reliability.md).
// The input is a command line, arguments separated by NUL bytes (at most 64), parsed by a
// command line with every kind of flag and a subcommand. UsageError is the only exception;
// parsed numbers are finite; parsing the same arguments again gives the same options; the help
// text never throws and keeps to 100 columns.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include "core/common/cli_app.h"

namespace {

struct Options {
  std::filesystem::path path;
  double number = 0;
  std::optional<double> optional_number;
  int count = 0;
  int64_t offset = 0;
  uint64_t seed = 0;
  std::optional<double> speed = 1.0;
  std::string sub_text;
  bool flag = false;
  bool sub_flag = false;

  bool operator==(const Options&) const = default;
};

// Parses `arguments`; false on a UsageError. Aborts on any other exception.
bool Parse(const std::vector<std::string>& arguments, Options* options, std::string* help) {
  evloc::CommandLine line("evloc-fuzz", "--path PATH [options]", "Fuzzes the adapter.");
  line.Add("--path", "PATH", "a path", &options->path)
      .Add("--number", "X", "a number", &options->number)
      .Add("--optional", "X", "an optional number", &options->optional_number)
      .Add("--count", "N", "an int", &options->count)
      .Add("--offset", "N", "an integer", &options->offset)
      .Add("--seed", "N", "an unsigned integer", &options->seed)
      .Add("--speed", "S|max", "a number or max",
           [options](const std::string& flag, const std::string& value) {
             options->speed = evloc::ParseDoubleOrWordFlag(flag, value, "max");
           })
      .Switch("--flag", "a switch", &options->flag);
  evloc::CommandLine& sub = line.Subcommand("sub", "[options]", "A subcommand.");
  sub.Add("--text,--alias", "T", "text", &options->sub_text)
      .Switch("--sub-flag", "a switch", &options->sub_flag);
  try {
    line.Parse(arguments);
  } catch (const evloc::UsageError&) {
    return false;
  } catch (...) {
    std::abort();
  }
  *help = line.Help(/*expand_subcommands=*/true);
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<std::string> arguments(1);
  for (size_t i = 0; i < size && arguments.size() <= 64; ++i) {
    if (data[i] == 0) {
      arguments.emplace_back();
    } else {
      arguments.back() += static_cast<char>(data[i]);
    }
  }
  if (size == 0) arguments.clear();
  Options options;
  std::string help;
  if (!Parse(arguments, &options, &help)) return 0;
  if (!std::isfinite(options.number) ||
      (options.optional_number && !std::isfinite(*options.optional_number)) ||
      (options.speed && !std::isfinite(*options.speed))) {
    std::abort();  // A number the strict parsers should have refused.
  }
  Options again;
  std::string help_again;
  if (!Parse(arguments, &again, &help_again) || !(again == options) || help_again != help) {
    std::abort();  // Parsing is not deterministic.
  }
  for (size_t start = 0, end = 0; start < help.size(); start = end + 1) {
    end = help.find('\n', start);
    if (end == std::string::npos) end = help.size();
    if (end - start > 100) std::abort();
  }
  return 0;
}
