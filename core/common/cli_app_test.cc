// The CLI11 adapter: strict values with cli.h's wording, unknown arguments and missing values as
// UsageErrors, command-line order, subcommands, and the generated help.
#include "core/common/cli_app.h"

#include <gtest/gtest.h>

namespace evloc {
namespace {

// The message of the UsageError that parsing `arguments` throws ("" when none).
std::string UsageErrorOf(CommandLine& line, const std::vector<std::string>& arguments) {
  try {
    line.Parse(arguments);
  } catch (const UsageError& error) {
    return error.what();
  }
  return "";
}

struct Options {
  std::filesystem::path input;
  double rate = 300;
  int64_t offset = 0;
  uint64_t seed = 1;
  int count = 2;
  std::optional<double> duration;
  std::string mode = "fast";
  bool force = false;
};

// A command line over `options`.
std::unique_ptr<CommandLine> MakeLine(Options* options) {
  auto line = std::make_unique<CommandLine>("evloc-test", "--input PATH [options]",
                                            "Tests the adapter of core/common/cli_app.h.");
  line->Add("--input", "PATH", "the input (required)", &options->input)
      .Add("--rate", "HZ", "step rate (default 300)", &options->rate)
      .Add("--offset", "N", "an offset", &options->offset)
      .Add("--seed", "N", "the seed", &options->seed)
      .Add("--count", "N", "a count", &options->count)
      .Add("--duration", "S", "seconds", &options->duration)
      .Add("--mode", "NAME", "slow | fast",
           [options](const std::string&, const std::string& value) {
             if (value != "slow" && value != "fast") {
               throw InvalidArgumentError("unknown mode '" + value + "'; expected slow or fast");
             }
             options->mode = value;
           })
      .Group("Output")
      .Switch("--force", "replace an existing output", &options->force)
      .Footer("Exit codes: 0 success, 2 bad command line.");
  return line;
}

TEST(CommandLine, ParsesEveryKindOfFlagInCommandLineOrder) {
  Options options;
  auto line = MakeLine(&options);
  line->Parse({"--input", "a.txt", "--rate", "200.5", "--offset", "-7", "--seed", "9", "--count",
               "3", "--duration", "1e-3", "--mode", "slow", "--force", "--rate", "100"});
  EXPECT_FALSE(line->help_requested());
  EXPECT_EQ(options.input, "a.txt");
  EXPECT_EQ(options.rate, 100);  // The later repeat wins.
  EXPECT_EQ(options.offset, -7);
  EXPECT_EQ(options.seed, 9u);
  EXPECT_EQ(options.count, 3);
  EXPECT_EQ(options.duration, 1e-3);
  EXPECT_EQ(options.mode, "slow");
  EXPECT_TRUE(options.force);
  EXPECT_EQ(line->Count("--rate"), 1u);  // Each repeat replaces the last (TakeLast).
  EXPECT_EQ(line->Count("--offset"), 1u);
  EXPECT_EQ(line->Count("--force"), 1u);
  EXPECT_EQ(line->Count("--duration"), 1u);
  line->Parse({"--input=b.txt"});  // CLI11's --flag=value works too.
  EXPECT_EQ(options.input, "b.txt");
  EXPECT_EQ(line->Count("--rate"), 0u);
}

TEST(CommandLine, ValuesAreStrictWithTheWordsOfCliH) {
  Options options;
  auto line = MakeLine(&options);
  EXPECT_EQ(UsageErrorOf(*line, {"--rate", "nan"}), "--rate expects a number, got 'nan'");
  EXPECT_EQ(UsageErrorOf(*line, {"--rate", "inf"}), "--rate expects a number, got 'inf'");
  EXPECT_EQ(UsageErrorOf(*line, {"--rate", "3x"}), "--rate expects a number, got '3x'");
  EXPECT_EQ(UsageErrorOf(*line, {"--seed", "-1"}),
            "--seed expects a non-negative integer, got '-1'");
  EXPECT_EQ(UsageErrorOf(*line, {"--offset", "1.5"}), "--offset expects an integer, got '1.5'");
  EXPECT_NE(UsageErrorOf(*line, {"--count", "99999999999"}).find("--count"), std::string::npos);
  EXPECT_EQ(UsageErrorOf(*line, {"--duration", " 1"}), "--duration expects a number, got ' 1'");
  // An InvalidArgumentError of a value's parser names the flag.
  EXPECT_EQ(UsageErrorOf(*line, {"--mode", "medium"}),
            "--mode: unknown mode 'medium'; expected slow or fast");
}

TEST(CommandLine, UnknownArgumentsAndMissingValuesAreUsageErrors) {
  Options options;
  auto line = MakeLine(&options);
  EXPECT_EQ(UsageErrorOf(*line, {"--input", "a", "--bogus"}), "unknown argument '--bogus'");
  EXPECT_EQ(UsageErrorOf(*line, {"--bogus", "5"}), "unknown argument '--bogus'");
  EXPECT_EQ(UsageErrorOf(*line, {"stray"}), "unknown argument 'stray'");
  EXPECT_EQ(UsageErrorOf(*line, {"--force", "yes"}), "unknown argument 'yes'");
  EXPECT_EQ(UsageErrorOf(*line, {"--input"}), "--input needs a value");
  EXPECT_EQ(UsageErrorOf(*line, {"--input", "a", "--", "b"}), "unknown argument '--'");
  // As with cli.h's TakeFlagValue, a value flag takes the next argument whatever it looks like.
  options = Options();
  EXPECT_EQ(UsageErrorOf(*line, {"--input", "--force"}), "");
  EXPECT_EQ(options.input, "--force");
  EXPECT_FALSE(options.force);
}

TEST(CommandLine, HelpIsGeneratedFromTheDeclarations) {
  Options options;
  auto line = MakeLine(&options);
  line->Parse({"--rate", "5", "--help"});
  EXPECT_TRUE(line->help_requested());
  line->Parse({"-h"});
  EXPECT_TRUE(line->help_requested());
  const std::string help = line->Help();
  EXPECT_EQ(help.rfind("Usage: evloc-test --input PATH [options]\n\n"
                       "Tests the adapter of core/common/cli_app.h.\n",
                       0),
            0u)
      << help;
  for (const char* expected : {"--rate HZ", "step rate (default 300)", "Output:", "--force",
                               "-h,--help", "Exit codes: 0 success"}) {
    EXPECT_NE(help.find(expected), std::string::npos) << expected << " in\n" << help;
  }
  EXPECT_LT(help.find("--mode NAME"), help.find("Output:"));
  EXPECT_GT(help.find("--force"), help.find("Output:"));
  // Long descriptions are wrapped to 100 columns, under the description column.
  CommandLine wide("evloc-wide", "", "");
  wide.Add("--x", "X", std::string(40, 'a') + " " + std::string(40, 'b'), &options.rate);
  const std::string wrapped = wide.Help();
  EXPECT_NE(wrapped.find(std::string(40, 'a') + "\n" + std::string(30, ' ') + std::string(40, 'b')),
            std::string::npos)
      << wrapped;
  for (size_t start = 0, end = 0; end != std::string::npos; start = end + 1) {
    end = wrapped.find('\n', start);
    EXPECT_LE((end == std::string::npos ? wrapped.size() : end) - start, 100u) << wrapped;
  }
}

TEST(CommandLine, SubcommandsHaveTheirOwnFlagsAndHelp) {
  CommandLine tool("evloc-tool", "COMMAND [options]", "Two commands.");
  double speed = 0;
  bool clean = false;
  std::filesystem::path out;
  CommandLine& render = tool.Subcommand("render", "--out DIR [options]", "Renders.");
  render.Add("--out", "DIR", "output folder", &out).Add("--speed", "M/S", "speed", &speed);
  CommandLine& convert = tool.Subcommand("convert", "--out DIR", "Converts.");
  convert.Add("--out", "DIR", "output folder", &out).Switch("--clean", "clean", &clean);

  // Before any parse (after one, CLI11's help is that of the subcommand chosen).
  const std::string all = tool.Help(/*expand_subcommands=*/true);
  for (const char* expected : {"Usage: evloc-tool COMMAND [options]", "render", "Renders.",
                               "Usage: evloc-tool convert --out DIR", "--clean", "--speed M/S"}) {
    EXPECT_NE(all.find(expected), std::string::npos) << expected << " in\n" << all;
  }

  tool.Parse({"render", "--out", "o", "--speed", "2"});
  EXPECT_EQ(tool.chosen_subcommand(), &render);
  EXPECT_EQ(out, "o");
  EXPECT_EQ(speed, 2);
  EXPECT_EQ(UsageErrorOf(tool, {"render", "--clean"}), "unknown argument '--clean'");
  EXPECT_EQ(UsageErrorOf(tool, {"render", "--speed", "fast"}),
            "--speed expects a number, got 'fast'");
  tool.Parse({"convert", "--clean"});
  EXPECT_EQ(tool.chosen_subcommand(), &convert);
  EXPECT_TRUE(clean);
  EXPECT_EQ(UsageErrorOf(tool, {"explode"}), "unknown argument 'explode'");
  tool.Parse({});
  EXPECT_EQ(tool.chosen_subcommand(), nullptr);

  tool.Parse({"render", "--help"});
  EXPECT_TRUE(render.help_requested());
  EXPECT_FALSE(tool.help_requested());
  EXPECT_EQ(render.Help().rfind("Usage: evloc-tool render --out DIR [options]\n", 0), 0u)
      << render.Help();
}

// A flag set shared with hand-written parsers keeps its one usage text and its one parser.
TEST(CommandLine, FlagsOfAHandWrittenUsageText) {
  constexpr char kUsage[] =
      "  --topic T              the topic (default /dvs/events) of the\n"
      "                         events\n"
      "  --a-long-flag-name VALUE\n"
      "                         help on the next line\n";
  std::vector<std::pair<std::string, std::string>> applied;
  CommandLine line("evloc-test", "", "");
  line.AddFlagsOfUsage(kUsage, [&](const std::string& flag, const std::string& value) {
    applied.emplace_back(flag, value);
    return true;
  });
  line.Parse({"--a-long-flag-name", "x", "--topic", "/t"});
  EXPECT_EQ(applied, (std::vector<std::pair<std::string, std::string>>{{"--a-long-flag-name", "x"},
                                                                       {"--topic", "/t"}}));
  const std::string help = line.Help();
  EXPECT_NE(help.find("--topic T                   the topic (default /dvs/events) of the events"),
            std::string::npos)
      << help;
  EXPECT_NE(help.find("--a-long-flag-name VALUE    help on the next line"), std::string::npos)
      << help;
  CommandLine broken("evloc-test", "", "");
  broken.AddFlagsOfUsage(kUsage, [](const std::string&, const std::string&) { return false; });
  EXPECT_THROW(broken.Parse({"--topic", "x"}), std::logic_error);
}

}  // namespace
}  // namespace evloc
