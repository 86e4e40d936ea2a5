#include "localizer/wire/percentile.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

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

// Finding 9 of issue 14: a session kept three doubles per pose for its percentiles (memory
// growing with its length); the histogram has a fixed size and gives the same percentiles to
// its stated resolution.
TEST(LogHistogram, FixedSizePercentilesWithinTheStatedResolution) {
  static_assert(sizeof(LogHistogram) < 12 * 1024, "a fixed, small footprint");
  LogHistogram histogram;
  EXPECT_EQ(histogram.Percentile(0.5), 0);
  std::vector<double> values;
  uint64_t state = 12345;
  for (int i = 0; i < 200'000; ++i) {
    state = state * 6364136223846793005u + 1442695040888963407u;
    // Latencies from 50 us to ~50 ms, log-uniform.
    const double value = 50.0 * std::exp2(10.0 * static_cast<double>(state >> 11) * 0x1p-53);
    values.push_back(value);
    histogram.Add(value);
  }
  EXPECT_EQ(histogram.count(), values.size());
  const double resolution = std::exp2(0.5 / LogHistogram::kBucketsPerOctave);  // +-1.1 %
  for (double fraction : {0.0, 0.5, 0.9, 0.99, 1.0}) {
    const double exact = Percentile(values, fraction);
    EXPECT_LE(histogram.Percentile(fraction), exact * resolution) << fraction;
    EXPECT_GE(histogram.Percentile(fraction), exact / resolution) << fraction;
  }
  LogHistogram edges;
  edges.Add(0.2);
  edges.Add(-1);
  edges.Add(1e30);
  EXPECT_EQ(edges.Percentile(0.0), 0.5);
  EXPECT_EQ(edges.Percentile(1.0), std::exp2(LogHistogram::kOctaves));
}

}  // namespace
}  // namespace evloc::wire
