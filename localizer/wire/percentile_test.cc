#include "localizer/wire/percentile.h"

#include <gtest/gtest.h>

namespace evloc::wire {
namespace {

TEST(Percentile, TakesTheElementAtTheFloorOfTheFractionClampedToTheLast) {
  const std::vector<double> values = {9, 1, 8, 2, 7, 3, 6, 4, 5, 10};
  EXPECT_EQ(Percentile(values, 0.0), 1);
  EXPECT_EQ(Percentile(values, 0.5), 6);    // index 5 of 1..10
  EXPECT_EQ(Percentile(values, 0.99), 10);  // index 9
  EXPECT_EQ(Percentile(values, 1.0), 10);   // index 10, clamped to 9
  EXPECT_EQ(Percentile({}, 0.5), 0);
}

}  // namespace
}  // namespace evloc::wire
