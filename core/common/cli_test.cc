#include "core/common/cli.h"

#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc {
namespace {

TEST(TakeFlagValue, ReturnsTheNextArgumentOrSaysWhatIsMissing) {
  const std::vector<std::string> arguments = {"--rate", "300", "--map"};
  size_t index = 0;
  EXPECT_EQ(TakeFlagValue(arguments, &index), "300");
  EXPECT_EQ(index, 1u);
  index = 2;
  try {
    TakeFlagValue(arguments, &index);
    FAIL() << "expected an error";
  } catch (const InvalidArgumentError& error) {
    EXPECT_STREQ(error.what(), "--map needs a value");
  }
  const std::vector<std::string> stray = {"extra"};
  index = 0;
  try {
    TakeFlagValue(stray, &index);
    FAIL() << "expected an error";
  } catch (const InvalidArgumentError& error) {
    EXPECT_STREQ(error.what(), "unexpected argument 'extra'");
  }
}

TEST(ParseDoubleFlag, AcceptsWholeNumbersOnly) {
  EXPECT_DOUBLE_EQ(ParseDoubleFlag("--rate", "300"), 300.0);
  EXPECT_DOUBLE_EQ(ParseDoubleFlag("--rate", "-1.5e-3"), -1.5e-3);
  EXPECT_THROW(ParseDoubleFlag("--rate", "300Hz"), UsageError);
  EXPECT_THROW(ParseDoubleFlag("--rate", ""), UsageError);
  EXPECT_THROW(ParseDoubleFlag("--rate", "nan"), UsageError);
  EXPECT_THROW(ParseDoubleFlag("--rate", "inf"), UsageError);
  EXPECT_THROW(ParseDoubleFlag("--rate", "-inf"), UsageError);
  EXPECT_THROW(ParseDoubleFlag("--rate", "1e999"), UsageError);
  try {
    ParseDoubleFlag("--rate", "fast");
    FAIL();
  } catch (const InvalidArgumentError& error) {
    EXPECT_EQ(std::string(error.what()), "--rate expects a number, got 'fast'");
  }
}

TEST(ParseDoubleOrWordFlag, TakesTheWordOrAStrictNumber) {
  EXPECT_EQ(ParseDoubleOrWordFlag("--speed", "max", "max"), std::nullopt);
  EXPECT_EQ(ParseDoubleOrWordFlag("--speed", "2.5", "max"), 2.5);
  EXPECT_THROW(ParseDoubleOrWordFlag("--speed", "Max", "max"), UsageError);
  EXPECT_THROW(ParseDoubleOrWordFlag("--speed", "nan", "max"), UsageError);
}

TEST(ParseIntegerFlag, RejectsFractionsAndText) {
  EXPECT_EQ(ParseIntegerFlag("--n", "42"), 42);
  EXPECT_THROW(ParseIntegerFlag("--n", "4.2"), UsageError);
  EXPECT_THROW(ParseIntegerFlag("--n", "x"), UsageError);
}

TEST(ParseUnsignedFlag, RejectsSignsFractionsAndText) {
  EXPECT_EQ(ParseUnsignedFlag("--seed", "18446744073709551615"), 18446744073709551615u);
  EXPECT_THROW(ParseUnsignedFlag("--seed", "-1"), UsageError);
  EXPECT_THROW(ParseUnsignedFlag("--seed", "1.5"), UsageError);
  EXPECT_THROW(ParseUnsignedFlag("--seed", "7 "), UsageError);
  EXPECT_THROW(ParseUnsignedFlag("--seed", ""), UsageError);
}

TEST(ParseIntFlag, RejectsValuesBeyondInt) {
  EXPECT_EQ(ParseIntFlag("--n", "-7"), -7);
  EXPECT_THROW(ParseIntFlag("--n", "4294967296"), UsageError);
}

TEST(ParseDoubleListFlag, OneOrMoreNumbersSplitAtCommas) {
  EXPECT_EQ(ParseDoubleListFlag("--segments", "2"), std::vector<double>({2.0}));
  EXPECT_EQ(ParseDoubleListFlag("--segments", "0.5,1,2e1"), std::vector<double>({0.5, 1.0, 20.0}));
  EXPECT_THROW(ParseDoubleListFlag("--segments", ""), UsageError);
  EXPECT_THROW(ParseDoubleListFlag("--segments", "1,"), UsageError);
  EXPECT_THROW(ParseDoubleListFlag("--segments", ",1"), UsageError);
  EXPECT_THROW(ParseDoubleListFlag("--segments", "1,,2"), UsageError);
  EXPECT_THROW(ParseDoubleListFlag("--segments", "1,nan"), UsageError);
}

TEST(ParseDoublePairFlag, TwoNumbersSplitAtTheComma) {
  EXPECT_EQ(ParseDoublePairFlag("--motion-prior", "2,0"), std::make_pair(2.0, 0.0));
  EXPECT_EQ(ParseDoublePairFlag("--motion-prior", "-1.5,2e1"), std::make_pair(-1.5, 20.0));
  EXPECT_THROW(ParseDoublePairFlag("--motion-prior", "2"), UsageError);
  EXPECT_THROW(ParseDoublePairFlag("--motion-prior", "2,"), UsageError);
  EXPECT_THROW(ParseDoublePairFlag("--motion-prior", "2,0,1"), UsageError);
  EXPECT_THROW(ParseDoublePairFlag("--motion-prior", "nan,0"), UsageError);
  try {
    ParseDoublePairFlag("--motion-prior", "2");
  } catch (const UsageError& error) {
    EXPECT_NE(std::string(error.what()).find("--motion-prior expects two numbers A,B, got '2'"),
              std::string::npos)
        << error.what();
  }
}

TEST(ParseSizeFlag, WidthByHeight) {
  int width = 0;
  int height = 0;
  ParseSizeFlag("--ecd-size", "240x180", &width, &height);
  EXPECT_EQ(width, 240);
  EXPECT_EQ(height, 180);
  EXPECT_THROW(ParseSizeFlag("--ecd-size", "240", &width, &height), UsageError);
  EXPECT_THROW(ParseSizeFlag("--ecd-size", "0x180", &width, &height), UsageError);
}

TEST(ParseTwoWordFlag, OneOfTwoWords) {
  EXPECT_TRUE(ParseTwoWordFlag("--initial-velocity", "truth", "rest", "truth"));
  EXPECT_FALSE(ParseTwoWordFlag("--initial-velocity", "rest", "rest", "truth"));
  try {
    ParseTwoWordFlag("--initial-velocity", "fast", "rest", "truth");
    ADD_FAILURE() << "a third word was accepted";
  } catch (const UsageError& error) {
    EXPECT_NE(std::string(error.what()).find("expects rest or truth, got 'fast'"),
              std::string::npos)
        << error.what();
  }
}

TEST(ParseSwitchFlag, OnOff) {
  EXPECT_TRUE(ParseSwitchFlag("--polarity", "on"));
  EXPECT_FALSE(ParseSwitchFlag("--polarity", "off"));
  EXPECT_THROW(ParseSwitchFlag("--polarity", "maybe"), UsageError);
}

// The exit code and the text RunGuarded writes for a body that throws `thrown`.
std::pair<int, std::string> RunThrowing(const std::function<void()>& thrown) {
  std::ostringstream err;
  const int code = RunGuarded("evloc-x", err, [&] {
    thrown();
    return 0;
  });
  return {code, err.str()};
}

TEST(RunGuarded, OneErrorLineAndOneExitCodePerKindOfError) {
  std::ostringstream err;
  EXPECT_EQ(RunGuarded("evloc-x", err, [] { return 7; }), 7);
  EXPECT_EQ(err.str(), "");

  EXPECT_EQ(RunThrowing([] { throw UsageError("--rate expects a number, got 'x'"); }),
            std::make_pair(kExitUsage, std::string("evloc-x: error: --rate expects a number, got "
                                                   "'x'\nRun `evloc-x --help` for the usage.\n")));
  EXPECT_EQ(RunThrowing([] { throw InvalidArgumentError("bad camera"); }),
            std::make_pair(kExitFailure, std::string("evloc-x: error: bad camera\n")));
  EXPECT_EQ(RunThrowing([] { throw IoError("cannot open a.txt"); }),
            std::make_pair(kExitFailure, std::string("evloc-x: error: cannot open a.txt\n")));
  EXPECT_EQ(RunThrowing([] { throw ParseError::AtLine("a.txt", 3, "bad"); }),
            std::make_pair(kExitFailure, std::string("evloc-x: error: a.txt: line 3: bad\n")));
  EXPECT_EQ(RunThrowing([] { throw std::runtime_error("disk full"); }),
            std::make_pair(kExitFailure, std::string("evloc-x: error: disk full\n")));
  EXPECT_EQ(RunThrowing([] { throw 42; }),
            std::make_pair(kExitFailure, std::string("evloc-x: error: an unknown exception\n")));
}

TEST(RunTool, GivesTheBodyTheArgumentsAfterTheProgramName) {
  const char* argv[] = {"evloc-x", "--rate", "300"};
  std::vector<std::string> seen;
  EXPECT_EQ(RunTool("evloc-x", 3, argv,
                    [&](const std::vector<std::string>& arguments) {
                      seen = arguments;
                      return 3;
                    }),
            3);
  EXPECT_EQ(seen, (std::vector<std::string>{"--rate", "300"}));
  const char* usage_argv[] = {"evloc-x", "--rate", "nan"};
  EXPECT_EQ(RunTool("evloc-x", 3, usage_argv,
                    [](const std::vector<std::string>& arguments) {
                      return static_cast<int>(ParseDoubleFlag(arguments[0], arguments[1]));
                    }),
            kExitUsage);
}

TEST(ParseCommandLine, TurnsEveryParserErrorIntoAUsageError) {
  const std::vector<std::string> arguments = {"--rate", "-5"};
  const auto parse = [](const std::vector<std::string>& given) {
    const double rate = ParseDoubleFlag(given[0], given[1]);
    if (rate <= 0) throw InvalidArgumentError("step_rate_hz must be > 0.");
    return rate;
  };
  try {
    ParseCommandLine(parse, arguments);
    FAIL() << "expected a UsageError";
  } catch (const UsageError& error) {
    EXPECT_STREQ(error.what(), "step_rate_hz must be > 0.");
  }
  EXPECT_DOUBLE_EQ(ParseCommandLine(parse, {"--rate", "300"}), 300.0);
  EXPECT_THROW(ParseCommandLine(parse, {"--rate", "nan"}), UsageError);
}

}  // namespace
}  // namespace evloc

namespace evloc {
namespace {

TEST(ParseByteSizeFlag, TakesBinarySuffixesAndRefusesTheRest) {
  EXPECT_EQ(ParseByteSizeFlag("--map-memory", "2G"), uint64_t{2} << 30);
  EXPECT_EQ(ParseByteSizeFlag("--map-memory", "512M"), uint64_t{512} << 20);
  EXPECT_EQ(ParseByteSizeFlag("--map-memory", "3k"), 3072u);
  EXPECT_EQ(ParseByteSizeFlag("--map-memory", "1048576"), 1048576u);
  EXPECT_EQ(ParseByteSizeFlag("--map-memory", "1024T"), uint64_t{1} << 50);
  for (const char* bad : {"", "G", "-1G", "2.5G", "2GB", "1025T", "nan"}) {
    EXPECT_THROW(ParseByteSizeFlag("--map-memory", bad), UsageError) << bad;
  }
}

}  // namespace
}  // namespace evloc
