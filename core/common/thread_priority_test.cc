#include "core/common/thread_priority.h"

#include <gtest/gtest.h>

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <thread>

namespace evloc {
namespace {

// The calling thread's scheduling policy and nice value.
std::pair<int, int> PolicyAndNice() {
  int policy = 0;
  sched_param param{};
  pthread_getschedparam(pthread_self(), &policy, &param);
  return {policy, getpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)))};
}

TEST(ThreadPriority, NamesRoundTripAndUnknownNamesAreRefused) {
  for (const auto priority :
       {ThreadPriority::kIdle, ThreadPriority::kLow, ThreadPriority::kNormal}) {
    EXPECT_EQ(ThreadPriorityNamed(ThreadPriorityName(priority)), priority);
  }
  EXPECT_FALSE(ThreadPriorityNamed("high").has_value());
  EXPECT_FALSE(ThreadPriorityNamed("").has_value());
}

// Each priority changes the thread it is set on, and only that thread.
TEST(ThreadPriority, SetsTheCallingThreadAlone) {
  const std::pair<int, int> before = PolicyAndNice();
  std::pair<int, int> idle, low, normal;
  bool idle_applied = false, low_applied = false;
  std::thread([&] {
    idle_applied = SetThisThreadPriority(ThreadPriority::kIdle);
    idle = PolicyAndNice();
  }).join();
  std::thread([&] {
    low_applied = SetThisThreadPriority(ThreadPriority::kLow);
    low = PolicyAndNice();
  }).join();
  std::thread([&] {
    EXPECT_TRUE(SetThisThreadPriority(ThreadPriority::kNormal));
    normal = PolicyAndNice();
  }).join();
  if (idle_applied) {
    EXPECT_EQ(idle.first, SCHED_IDLE);
  } else {
    EXPECT_EQ(idle.second, 19);  // the fallback
  }
  ASSERT_TRUE(low_applied);
  EXPECT_EQ(low.first, before.first);
  EXPECT_EQ(low.second, 10);
  EXPECT_EQ(normal, before);
  EXPECT_EQ(PolicyAndNice(), before);
}

}  // namespace
}  // namespace evloc
