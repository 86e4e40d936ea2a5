#include "core/common/cli.h"

#include <string>
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
  EXPECT_THROW(ParseDoubleFlag("--rate", "300Hz"), InvalidArgumentError);
  EXPECT_THROW(ParseDoubleFlag("--rate", ""), InvalidArgumentError);
  EXPECT_THROW(ParseDoubleFlag("--rate", "nan"), InvalidArgumentError);
  try {
    ParseDoubleFlag("--rate", "fast");
    FAIL();
  } catch (const InvalidArgumentError& error) {
    EXPECT_EQ(std::string(error.what()), "--rate expects a number, got 'fast'");
  }
}

TEST(ParseIntegerFlag, RejectsFractionsAndText) {
  EXPECT_EQ(ParseIntegerFlag("--n", "42"), 42);
  EXPECT_THROW(ParseIntegerFlag("--n", "4.2"), InvalidArgumentError);
  EXPECT_THROW(ParseIntegerFlag("--n", "x"), InvalidArgumentError);
}

TEST(ParseIntFlag, RejectsValuesBeyondInt) {
  EXPECT_EQ(ParseIntFlag("--n", "-7"), -7);
  EXPECT_THROW(ParseIntFlag("--n", "4294967296"), InvalidArgumentError);
}

TEST(ParseSizeFlag, WidthByHeight) {
  int width = 0;
  int height = 0;
  ParseSizeFlag("--ecd-size", "240x180", &width, &height);
  EXPECT_EQ(width, 240);
  EXPECT_EQ(height, 180);
  EXPECT_THROW(ParseSizeFlag("--ecd-size", "240", &width, &height), InvalidArgumentError);
  EXPECT_THROW(ParseSizeFlag("--ecd-size", "0x180", &width, &height), InvalidArgumentError);
}

TEST(ParseSwitchFlag, OnOff) {
  EXPECT_TRUE(ParseSwitchFlag("--polarity", "on"));
  EXPECT_FALSE(ParseSwitchFlag("--polarity", "off"));
  EXPECT_THROW(ParseSwitchFlag("--polarity", "maybe"), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc
