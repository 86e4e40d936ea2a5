// The CPU time the calling thread has used, for budgets and cost figures measured per thread
// (the search's CPU share, a session's CPU budget, build costs in benchmarks).
#pragma once

#include <time.h>

#include <cstdint>

namespace evloc {

// CPU time of the calling thread, nanoseconds (CLOCK_THREAD_CPUTIME_ID).
inline int64_t ThreadCpuTimeNs() {
  timespec now{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
  return int64_t{now.tv_sec} * 1'000'000'000 + now.tv_nsec;
}

}  // namespace evloc
