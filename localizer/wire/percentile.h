// Percentiles of latency samples, as the server, its clients and the load driver report them.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace evloc::wire {

// The value at `fraction` (0..1) of the sorted samples: the element at index
// floor(fraction * n), clamped to the last; 0 for no samples.
inline double Percentile(std::vector<double> values, double fraction) {
  if (values.empty()) return 0.0;
  const size_t index = std::min(values.size() - 1,
                                static_cast<size_t>(fraction * static_cast<double>(values.size())));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(index),
                   values.end());
  return values[index];
}

// A fixed-size histogram of non-negative values (latencies in microseconds) with logarithmic
// buckets, kBucketsPerOctave per doubling from 1 to 2^kOctaves: its size does not grow with the
// number of values (a session's statistics stay bounded however long it runs). Percentile returns
// the geometric centre of the bucket holding the sample Percentile() above would return, so it is
// within a factor 2^(1/(2 * kBucketsPerOctave)) (+-1.1 %) of that sample for values in
// [1, 2^kOctaves); values below 1 count as 0.5, values at or above 2^kOctaves (2^40 us: 12.7
// days) as 2^kOctaves. Not thread-safe.
class LogHistogram {
 public:
  // Buckets per doubling of the value.
  static constexpr int kBucketsPerOctave = 32;
  // Doublings covered from 1.
  static constexpr int kOctaves = 40;
  // Number of buckets: one below 1, kOctaves * kBucketsPerOctave, one at the top.
  static constexpr int kBuckets = kOctaves * kBucketsPerOctave + 2;

  // Counts one value (NaN and negative values count as 0).
  void Add(double value) {
    ++counts_[static_cast<size_t>(Bucket(value))];
    ++count_;
  }
  // Values counted.
  uint64_t count() const { return count_; }
  // The value at `fraction` (0..1) as Percentile() defines it, to the bucket resolution; 0 for no
  // values.
  double Percentile(double fraction) const {
    if (count_ == 0) return 0.0;
    const uint64_t index = std::min<uint64_t>(
        count_ - 1, static_cast<uint64_t>(fraction * static_cast<double>(count_)));
    uint64_t seen = 0;
    for (int bucket = 0; bucket < kBuckets; ++bucket) {
      seen += counts_[static_cast<size_t>(bucket)];
      if (seen > index) return Centre(bucket);
    }
    return Centre(kBuckets - 1);
  }

 private:
  static int Bucket(double value) {
    if (!(value >= 1.0)) return 0;
    const double position = std::log2(value) * kBucketsPerOctave;
    if (position >= kOctaves * kBucketsPerOctave) return kBuckets - 1;
    return 1 + static_cast<int>(position);
  }
  static double Centre(int bucket) {
    if (bucket == 0) return 0.5;
    if (bucket == kBuckets - 1) return std::exp2(kOctaves);
    return std::exp2((bucket - 0.5) / kBucketsPerOctave);
  }

  std::array<uint64_t, kBuckets> counts_{};
  uint64_t count_ = 0;
};

}  // namespace evloc::wire
