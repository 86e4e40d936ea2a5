// The command line of an evloc-* tool on CLI11 (docs/conventions.md, "Command lines"): one
// declaration per flag gives both the parser and the generated --help, while the values keep
// evloc's strict parsers (cli.h: no nan, no inf, no trailing text, errors that name the flag)
// instead of CLI11's lenient number conversion, and every mistake is a UsageError (exit code 2
// through RunTool), worded as the hand-written parsers worded it:
//   unknown argument '--bogus'        an unknown flag, or an argument where none is expected
//   --gt needs a value                a value flag last (it takes the next argument whatever it
//                                     looks like, as cli.h's TakeFlagValue does)
//   --fps expects a number, got 'x'   (the cli.h parser of the flag's type)
//   --align: unknown alignment ...    an InvalidArgumentError of a value's parser, prefixed by
//                                     the flag unless its message already names it
// Flags are applied in command-line order (a later repeat wins), as the hand-written loops did.
//
//   CommandLine line("evloc-eval", "--gt GT.txt --est EST.txt [options]", "Scores ...");
//   line.Add("--gt", "PATH", "ground-truth TUM trajectory (required)", &options.gt_path)
//       .Add("--delta", "SECONDS", "RPE time step (default 1.0)", &options.delta_s)
//       .Switch("--force", "replace an existing output", &options.force)
//       .Footer("Exit codes: 0 success, 1 bad input, 2 bad command line.");
//   line.Parse(arguments);               // throws UsageError
//   if (line.help_requested()) std::cout << line.Help();
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "core/common/cli.h"

namespace CLI {
class App;
}  // namespace CLI

namespace evloc {

// The value of `text` for a flag whose target has type T, with cli.h's parser of that type:
// std::string and std::filesystem::path as given, double (ParseDoubleFlag), int (ParseIntFlag),
// int64_t (ParseIntegerFlag), uint64_t (ParseUnsignedFlag), std::optional<one of those>.
template <typename T>
T ParseFlagValue(std::string_view flag, const std::string& text) {
  if constexpr (std::is_same_v<T, std::string> || std::is_same_v<T, std::filesystem::path>) {
    return T(text);
  } else if constexpr (std::is_same_v<T, double>) {
    return ParseDoubleFlag(flag, text);
  } else if constexpr (std::is_same_v<T, int>) {
    return ParseIntFlag(flag, text);
  } else if constexpr (std::is_same_v<T, int64_t>) {
    return ParseIntegerFlag(flag, text);
  } else if constexpr (std::is_same_v<T, uint64_t>) {
    return ParseUnsignedFlag(flag, text);
  } else {
    static_assert(sizeof(T) == 0, "no strict parser for this flag type: use Add with a function");
  }
}

// A tool's (or subcommand's) command line: flags, help text, parsing.
class CommandLine {
 public:
  // Stores the value of a flag: `flag` is its name, `value` the text given. Throws UsageError,
  // or InvalidArgumentError (turned into a UsageError naming the flag).
  using Apply = std::function<void(const std::string& flag, const std::string& value)>;

  // `name`: the program (for a subcommand, its name alone); `synopsis`: what follows the name on
  // the usage line (lines after the first are further forms, printed under it); `description`:
  // the paragraph under the usage, wrapped to the help's width.
  CommandLine(std::string name, std::string synopsis, std::string description);
  ~CommandLine();
  CommandLine(const CommandLine&) = delete;
  CommandLine& operator=(const CommandLine&) = delete;

  // A flag with a value (`value_name` in --help, e.g. "PATH"), stored by `apply`. `flag` may list
  // aliases, "--input,--bag" (errors name the first).
  CommandLine& Add(std::string_view flag, std::string_view value_name, std::string_view help,
                   Apply apply);
  // A flag with a value parsed strictly into `*target` (ParseFlagValue).
  template <typename T>
  CommandLine& Add(std::string_view flag, std::string_view value_name, std::string_view help,
                   T* target) {
    return Add(flag, value_name, help, [target](const std::string& name, const std::string& text) {
      *target = ParseFlagValue<T>(name, text);
    });
  }
  template <typename T>
  CommandLine& Add(std::string_view flag, std::string_view value_name, std::string_view help,
                   std::optional<T>* target) {
    return Add(flag, value_name, help, [target](const std::string& name, const std::string& text) {
      *target = ParseFlagValue<T>(name, text);
    });
  }
  // The flags a hand-written usage text lists, one "  --flag VALUE  help" line each (continuation
  // lines indented deeper; the help starts after two spaces), each stored by `apply`, which
  // returns false for a flag it does not know (a programming error: std::logic_error). So a flag
  // set shared with tools still on hand-written parsers keeps one help text and one parser:
  // kRecordingFlagsUsage with ApplyRecordingFlag (core/dataset/dataset.h).
  CommandLine& AddFlagsOfUsage(
      std::string_view usage,
      const std::function<bool(const std::string& flag, const std::string& value)>& apply);
  // A flag without a value that sets `*target` to true.
  CommandLine& Switch(std::string_view flag, std::string_view help, bool* target);
  // Flags declared after this call are listed under `heading` in --help (default "Options").
  CommandLine& Group(std::string_view heading);
  // Text printed after the options (exit codes, notes), wrapped; its line breaks are kept.
  CommandLine& Footer(std::string_view text);
  // A subcommand of this command line (`evloc-sim render`), owned by it.
  CommandLine& Subcommand(std::string_view name, std::string_view synopsis,
                          std::string_view description);

  // Parses the arguments after the program name. Throws UsageError (see the top of this file).
  // --help or -h anywhere is no error: help_requested() of the command line it was given to.
  void Parse(const std::vector<std::string>& arguments);
  // --help or -h was given to this command line (not to one of its subcommands).
  bool help_requested() const;
  // The subcommand the arguments chose, or nullptr.
  CommandLine* chosen_subcommand() const;
  // How many times `flag` was given in the last Parse.
  size_t Count(std::string_view flag) const;
  // The generated --help text: usage, description, the flags by group, the subcommands (with
  // their own flags when `expand_subcommands`), the footer.
  std::string Help(bool expand_subcommands = false) const;

  // The CLI11 app, for what this adapter does not cover.
  CLI::App& app() { return *app_; }

 private:
  CommandLine(CLI::App* app, std::string synopsis);
  // Sets up help flag, formatter and error handling of `app_`.
  void Configure(std::string synopsis);

  std::unique_ptr<CLI::App> owned_app_;
  CLI::App* app_ = nullptr;
  std::string group_ = "Options";
  std::vector<std::unique_ptr<CommandLine>> subcommands_;
};

// A function that declares a tool's command line over its options (each flag writes a field).
template <typename Options>
using DeclareCommandLine = std::unique_ptr<CommandLine> (*)(Options* options);

// Parses `arguments` into default Options with the command line `declare` builds over them; sets
// `help` (the field RunCommandTool reads) when --help was given. Throws UsageError. The options
// are not checked: the caller calls their Check().
template <typename Options>
Options ParseDeclaredCommandLine(DeclareCommandLine<Options> declare,
                                 const std::vector<std::string>& arguments) {
  Options options;
  const std::unique_ptr<CommandLine> line = declare(&options);
  line->Parse(arguments);
  options.help = line->help_requested();
  return options;
}

// The --help text of the command line `declare` builds.
template <typename Options>
std::string HelpOfDeclaredCommandLine(DeclareCommandLine<Options> declare) {
  Options options;
  return declare(&options)->Help();
}

}  // namespace evloc
