// Percentiles of latency samples, as the server, its clients and the load driver report them.
#pragma once

#include <algorithm>
#include <cstddef>
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

}  // namespace evloc::wire
