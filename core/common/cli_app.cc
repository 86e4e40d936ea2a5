#include "core/common/cli_app.h"

#include <algorithm>
#include <sstream>
#include <stdexcept>

#include <CLI/CLI.hpp>

#include "core/common/error.h"

namespace evloc {
namespace {

// Width of the generated help, and of its flag column.
constexpr size_t kHelpWidth = 100;
constexpr size_t kFlagColumn = 30;

// `text` wrapped at spaces into lines of at most `width` characters (a longer word stays whole);
// its own line breaks and each line's indentation are kept.
std::string Wrap(std::string_view text, size_t width) {
  std::string wrapped;
  std::istringstream lines{std::string(text)};
  bool first_line = true;
  for (std::string line; std::getline(lines, line);) {
    if (!first_line) wrapped += '\n';
    first_line = false;
    const size_t indent = std::min(line.find_first_not_of(' '), line.size());
    wrapped.append(indent, ' ');
    size_t column = indent;
    std::istringstream words(line.substr(indent));
    bool first_word = true;
    for (std::string word; words >> word;) {
      if (!first_word && column + 1 + word.size() > width) {
        wrapped += '\n';
        wrapped.append(indent, ' ');
        column = indent;
      } else if (!first_word) {
        wrapped += ' ';
        ++column;
      }
      wrapped += word;
      column += word.size();
      first_word = false;
    }
  }
  return wrapped;
}

// The full name of an app: its parents' names, then its own ("evloc-sim render").
std::string FullName(const CLI::App* app) {
  std::string name = app->get_name();
  for (const CLI::App* parent = app->get_parent(); parent; parent = parent->get_parent()) {
    name = parent->get_name() + " " + name;
  }
  return name;
}

// CLI11's help in evloc's form: the tool's own usage lines, wrapped descriptions, and
// subcommands expanded with their usage.
class HelpFormatter final : public CLI::Formatter {
 public:
  explicit HelpFormatter(std::string synopsis) : synopsis_(std::move(synopsis)) {
    column_width(kFlagColumn);
  }

  std::string make_help(const CLI::App* app, std::string name,
                        CLI::AppFormatMode mode) const override {
    if (mode == CLI::AppFormatMode::Sub) return make_expanded(app);
    std::string help = make_usage(app, name) + make_description(app) + make_positionals(app) +
                       make_groups(app, mode) + make_subcommands(app, mode) + "\n" +
                       make_footer(app);
    // One blank line between sections.
    for (size_t at = help.find("\n\n\n"); at != std::string::npos; at = help.find("\n\n\n")) {
      help.erase(at, 1);
    }
    return help;
  }

  std::string make_usage(const CLI::App* app, std::string name) const override {
    if (synopsis_.empty()) return Formatter::make_usage(app, name) + "\n";
    const std::string full_name = FullName(app);
    std::string usage = "Usage: ";
    std::istringstream forms(synopsis_);
    bool first = true;
    // Each form after the name, wrapped under its own start.
    const std::string hanging(std::string("Usage: ").size() + full_name.size() + 1, ' ');
    for (std::string form; std::getline(forms, form);) {
      std::string wrapped = Wrap(form, kHelpWidth - hanging.size());
      for (size_t at = wrapped.find('\n'); at != std::string::npos;
           at = wrapped.find('\n', at + 1)) {
        wrapped.insert(at + 1, hanging);
      }
      usage += (first ? "" : "       ") + full_name + (form.empty() ? "" : " " + wrapped) + "\n";
      first = false;
    }
    return usage + "\n";
  }

  std::string make_description(const CLI::App* app) const override {
    const std::string& description = app->get_description();
    return description.empty() ? "" : Wrap(description, kHelpWidth) + "\n";
  }

  std::string make_footer(const CLI::App* app) const override {
    const std::string& footer = app->get_footer();
    return footer.empty() ? "" : Wrap(footer, kHelpWidth) + "\n";
  }

  std::string make_option_desc(const CLI::Option* option) const override {
    return Wrap(option->get_description(), kHelpWidth - kFlagColumn);
  }

  std::string make_subcommand(const CLI::App* sub) const override {
    std::stringstream out;
    CLI::detail::format_help(out, sub->get_name(),
                             Wrap(sub->get_description(), kHelpWidth - kFlagColumn), column_width_);
    return out.str();
  }

  std::string make_expanded(const CLI::App* sub) const override {
    // The subcommand's own help (usage, description, flags), under a rule.
    return "\n" + std::string(kHelpWidth, '-') + "\n" +
           sub->get_formatter()->make_help(sub, sub->get_name(), CLI::AppFormatMode::Normal);
  }

 private:
  std::string synopsis_;
};

// The name CLI11 uses for the option of a missing-value error ("--gt: 1 required TEXT missing").
std::string OptionNameOf(const std::string& message) {
  return message.substr(0, message.find(':'));
}

}  // namespace

CommandLine::CommandLine(std::string name, std::string synopsis, std::string description)
    : owned_app_(std::make_unique<CLI::App>(std::move(description), std::move(name))),
      app_(owned_app_.get()) {
  Configure(std::move(synopsis));
}

CommandLine::CommandLine(CLI::App* app, std::string synopsis) : app_(app) {
  Configure(std::move(synopsis));
}

CommandLine::~CommandLine() = default;

void CommandLine::Configure(std::string synopsis) {
  app_->set_help_flag("-h,--help", "print this help");
  // Unknown arguments are reported by Parse, in evloc's words.
  app_->allow_extras(true);
  app_->formatter(std::make_shared<HelpFormatter>(std::move(synopsis)));
}

CommandLine& CommandLine::Add(std::string_view flag, std::string_view value_name,
                              std::string_view help, Apply apply) {
  const std::string name(flag.substr(0, flag.find(',')));
  CLI::Option* option = app_->add_option_function<std::string>(
      std::string(flag),
      [apply = std::move(apply), name](const std::string& value) {
        try {
          apply(name, value);
        } catch (const UsageError&) {
          throw;
        } catch (const InvalidArgumentError& error) {
          const std::string message = error.what();
          throw UsageError(message.find(name) != std::string::npos ? message
                                                                   : name + ": " + message);
        }
      },
      std::string(help));
  option->type_name(std::string(value_name));
  // Applied as soon as it is read: command-line order, a later repeat wins.
  option->trigger_on_parse();
  option->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  option->group(group_);
  return *this;
}

CommandLine& CommandLine::AddFlagsOfUsage(
    std::string_view usage,
    const std::function<bool(const std::string& flag, const std::string& value)>& apply) {
  struct Declared {
    std::string flag;
    std::string value_name;
    std::string help;
  };
  std::vector<Declared> flags;
  std::istringstream lines{std::string(usage)};
  for (std::string line; std::getline(lines, line);) {
    const size_t start = line.find_first_not_of(' ');
    if (start == std::string::npos) continue;
    std::string text = line.substr(start);
    if (text.rfind("--", 0) != 0) {
      // A continuation of the last flag's help.
      if (!flags.empty()) flags.back().help += (flags.back().help.empty() ? "" : " ") + text;
      continue;
    }
    const size_t gap = text.find("  ");
    std::string head = text.substr(0, gap);
    const size_t space = head.find(' ');
    Declared declared{head.substr(0, space),
                      space == std::string::npos ? "" : head.substr(space + 1), ""};
    if (gap != std::string::npos) {
      declared.help = text.substr(text.find_first_not_of(' ', gap));
    }
    flags.push_back(std::move(declared));
  }
  for (const Declared& declared : flags) {
    Add(declared.flag, declared.value_name, declared.help,
        [apply](const std::string& flag, const std::string& value) {
          if (!apply(flag, value)) {
            throw std::logic_error("the usage text lists " + flag + " but its parser ignores it");
          }
        });
  }
  return *this;
}

CommandLine& CommandLine::Switch(std::string_view flag, std::string_view help, bool* target) {
  app_->add_flag_callback(
          std::string(flag), [target] { *target = true; }, std::string(help))
      ->group(group_);
  return *this;
}

CommandLine& CommandLine::Group(std::string_view heading) {
  group_ = heading;
  return *this;
}

CommandLine& CommandLine::Footer(std::string_view text) {
  app_->footer(std::string(text));
  return *this;
}

CommandLine& CommandLine::Subcommand(std::string_view name, std::string_view synopsis,
                                     std::string_view description) {
  CLI::App* sub = app_->add_subcommand(std::string(name), std::string(description));
  subcommands_.push_back(std::unique_ptr<CommandLine>(new CommandLine(sub, std::string(synopsis))));
  return *subcommands_.back();
}

void CommandLine::Parse(const std::vector<std::string>& arguments) {
  // CLI11 takes the arguments last first.
  std::vector<std::string> reversed(arguments.rbegin(), arguments.rend());
  try {
    app_->parse(reversed);
  } catch (const CLI::CallForHelp&) {
    return;
  } catch (const CLI::ArgumentMismatch& error) {
    const std::string message = error.what();
    if (message.find("missing") != std::string::npos) {
      throw UsageError(OptionNameOf(message) + " needs a value");
    }
    throw UsageError(message);
  } catch (const CLI::ParseError& error) {
    throw UsageError(error.what());
  }
  const std::vector<std::string> unknown = app_->remaining(true);
  if (!unknown.empty()) throw UsageError("unknown argument '" + unknown.front() + "'");
}

bool CommandLine::help_requested() const { return app_->get_help_ptr()->count() > 0; }

CommandLine* CommandLine::chosen_subcommand() const {
  for (const auto& sub : subcommands_) {
    if (sub->app_->parsed()) return sub.get();
  }
  return nullptr;
}

size_t CommandLine::Count(std::string_view flag) const { return app_->count(std::string(flag)); }

std::string CommandLine::Help(bool expand_subcommands) const {
  return app_->help("", expand_subcommands ? CLI::AppFormatMode::All : CLI::AppFormatMode::Normal);
}

}  // namespace evloc
