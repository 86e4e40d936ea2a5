// Lowering the scheduling priority of the calling thread, for background work that must not take
// CPU from latency-bound threads: the service's search workers and the tile loaders.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace evloc {

enum class ThreadPriority {
  // SCHED_IDLE (else nice 19 where the policy cannot be set): only CPU nothing else wants.
  kIdle,
  // Nice 10: about a tenth of a core against each busy thread of normal priority.
  kLow,
  // Unchanged: the priority of the threads that started it.
  kNormal,
};

// "idle", "low" or "normal".
const char* ThreadPriorityName(ThreadPriority priority);
// The priority of that name, or nullopt.
std::optional<ThreadPriority> ThreadPriorityNamed(const std::string& name);

// Sets the calling thread's priority (Linux: per thread; lowering needs no privilege). Returns
// false when the kernel refused it: kIdle then falls back to nice 19, kLow stays unchanged.
bool SetThisThreadPriority(ThreadPriority priority);

// Starts `count` threads into `threads`; the i-th sets its priority (SetThisThreadPriority) and
// then runs body(i). Returns once every one has set it: true when none was refused.
bool StartThreadsAtPriority(int count, ThreadPriority priority,
                            const std::function<void(int)>& body,
                            std::vector<std::thread>* threads);

}  // namespace evloc
