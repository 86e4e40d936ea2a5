#include "core/common/thread_priority.h"

#include <atomic>

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace evloc {
namespace {

// setpriority on a thread id sets that thread alone (Linux).
bool SetNice(int nice) {
  return setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), nice) == 0;
}

}  // namespace

const char* ThreadPriorityName(ThreadPriority priority) {
  switch (priority) {
    case ThreadPriority::kIdle:
      return "idle";
    case ThreadPriority::kLow:
      return "low";
    case ThreadPriority::kNormal:
      return "normal";
  }
  return "normal";
}

std::optional<ThreadPriority> ThreadPriorityNamed(const std::string& name) {
  for (const auto priority :
       {ThreadPriority::kIdle, ThreadPriority::kLow, ThreadPriority::kNormal}) {
    if (name == ThreadPriorityName(priority)) return priority;
  }
  return std::nullopt;
}

bool SetThisThreadPriority(ThreadPriority priority) {
  switch (priority) {
    case ThreadPriority::kIdle: {
      const sched_param param{};
      if (pthread_setschedparam(pthread_self(), SCHED_IDLE, &param) == 0) return true;
      SetNice(19);
      return false;
    }
    case ThreadPriority::kLow:
      return SetNice(10);
    case ThreadPriority::kNormal:
      return true;
  }
  return true;
}

bool StartThreadsAtPriority(int count, ThreadPriority priority,
                            const std::function<void(int)>& body,
                            std::vector<std::thread>* threads) {
  std::atomic<int> refused{0};
  std::atomic<int> started{0};
  for (int i = 0; i < count; ++i) {
    threads->emplace_back([i, priority, body, &refused, &started] {
      if (!SetThisThreadPriority(priority)) ++refused;
      ++started;  // The last use of the caller's counters.
      body(i);
    });
  }
  while (started.load() < count) std::this_thread::yield();
  return refused.load() == 0;
}

}  // namespace evloc
