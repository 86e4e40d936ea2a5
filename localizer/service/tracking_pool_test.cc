#include "localizer/service/tracking_pool.h"

#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <future>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/common/error.h"

namespace evloc::service {
namespace {

using Clock = std::chrono::steady_clock;

// A job that runs `slices` slices, each calling `body`, and counts how many workers run it at
// once.
class CountingJob : public TrackingPool::Job {
 public:
  CountingJob(int slices, std::function<void()> body = {})
      : remaining_(slices), body_(std::move(body)) {}

  bool RunSlice() override {
    const int inside = ++inside_;
    most_inside_ = std::max(most_inside_.load(), inside);
    if (body_) body_();
    --inside_;
    ++ran_;
    if (--remaining_ > 0) return true;
    done_.set_value();
    return false;
  }

  std::atomic<int> ran_{0};
  std::atomic<int> most_inside_{0};
  std::promise<void> done_;

 private:
  std::atomic<int> remaining_;
  std::atomic<int> inside_{0};
  std::function<void()> body_;
};

TEST(TrackingPool, AJobIsNeverRunByTwoWorkersAtOnce) {
  TrackingPool pool(4);
  auto job = std::make_shared<CountingJob>(
      200, [] { std::this_thread::sleep_for(std::chrono::microseconds(200)); });
  auto done = job->done_.get_future();
  // Wakes from many threads while it runs: each is absorbed (queued once, or run again after
  // the slice), never a second worker.
  std::vector<std::thread> wakers;
  for (int i = 0; i < 4; ++i) {
    wakers.emplace_back([&] {
      for (int k = 0; k < 500; ++k) pool.Wake(job);
    });
  }
  for (std::thread& waker : wakers) waker.join();
  ASSERT_EQ(done.wait_for(std::chrono::seconds(20)), std::future_status::ready);
  EXPECT_EQ(job->most_inside_.load(), 1);
  EXPECT_EQ(job->ran_.load(), 200);
}

// A job shaped like a session: producers (the gRPC threads) push items into its inbox and wake
// it; each slice takes one item and updates state that is not atomic and has no lock of its own,
// so two slices of one job must be ordered by the pool itself (a ThreadSanitizer build reports
// it otherwise: docs/reliability.md). No wake may be lost: every item pushed is processed.
class InboxJob : public TrackingPool::Job {
 public:
  void Push() {
    std::lock_guard<std::mutex> lock(mutex_);
    ++inbox_;
  }
  bool RunSlice() override {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (inbox_ == 0) return false;
      --inbox_;
    }
    ++processed_;  // Plain: only the pool's ordering of slices protects it.
    checksum_ = checksum_ * 31 + static_cast<uint64_t>(processed_);
    published_.store(processed_, std::memory_order_release);
    std::lock_guard<std::mutex> lock(mutex_);
    return inbox_ > 0;
  }
  // The items processed, as the last slice published them.
  int processed() const { return published_.load(std::memory_order_acquire); }

 private:
  std::mutex mutex_;
  int inbox_ = 0;
  int processed_ = 0;
  uint64_t checksum_ = 0;
  std::atomic<int> published_{0};
};

TEST(TrackingPool, ManyJobsWokenFromManyThreadsProcessEveryItemOneSliceAtATime) {
  constexpr int kJobs = 24;
  constexpr int kProducers = 6;
  constexpr int kItemsPerProducerAndJob = 300;
  TrackingPool pool(3);
  std::vector<std::shared_ptr<InboxJob>> jobs;
  for (int i = 0; i < kJobs; ++i) jobs.push_back(std::make_shared<InboxJob>());
  std::vector<std::thread> producers;
  for (int p = 0; p < kProducers; ++p) {
    producers.emplace_back([&, p] {
      for (int k = 0; k < kItemsPerProducerAndJob; ++k) {
        for (int j = 0; j < kJobs; ++j) {
          InboxJob& job = *jobs[(j + p * 7 + k) % kJobs];
          job.Push();
          pool.Wake(jobs[(j + p * 7 + k) % kJobs]);
        }
        if (k % 50 == 0) std::this_thread::yield();
      }
    });
  }
  for (std::thread& producer : producers) producer.join();
  const auto deadline = Clock::now() + std::chrono::seconds(60);
  const auto all_done = [&] {
    for (const auto& job : jobs) {
      if (job->processed() < kProducers * kItemsPerProducerAndJob) return false;
    }
    return true;
  };
  while (!all_done() && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  for (const auto& job : jobs) {
    EXPECT_EQ(job->processed(), kProducers * kItemsPerProducerAndJob);
  }
}

// A job that says whether it is background work, and records where its slices ran.
class LaneJob : public TrackingPool::Job {
 public:
  explicit LaneJob(std::chrono::milliseconds first_slice) : first_slice_(first_slice) {}
  bool background() const override { return background_.load(); }
  bool RunSlice() override {
    char name[16] = {};
    pthread_getname_np(pthread_self(), name, sizeof(name));
    std::lock_guard<std::mutex> lock(mutex_);
    threads_.push_back(name);
    policies_.push_back(sched_getscheduler(0));
    inside_first_ = threads_.size() == 1;
    if (threads_.size() == 1) {
      mutex_.unlock();
      std::this_thread::sleep_for(first_slice_);
      mutex_.lock();
    }
    inside_first_ = false;
    ++slices_;
    return false;
  }
  std::atomic<bool> background_{false};
  std::atomic<bool> inside_first_{false};
  std::atomic<int> slices_{0};
  std::vector<std::string> threads() {
    std::lock_guard<std::mutex> lock(mutex_);
    return threads_;
  }
  std::vector<int> policies() {
    std::lock_guard<std::mutex> lock(mutex_);
    return policies_;
  }

 private:
  const std::chrono::milliseconds first_slice_;
  std::mutex mutex_;
  std::vector<std::string> threads_;
  std::vector<int> policies_;
};

// How long a one-slice tracking job waits while a background job's long slice runs, in a pool of
// one tracking worker with `background_threads` background workers.
double TrackingJobWaitSeconds(int background_threads, TrackingPool::BackgroundPriority priority,
                              std::shared_ptr<LaneJob>* searching) {
  TrackingPool pool(1, background_threads, priority);
  *searching = std::make_shared<LaneJob>(std::chrono::milliseconds(1500));
  (*searching)->background_ = true;
  pool.Wake(*searching);
  while (!(*searching)->inside_first_) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  auto tracking = std::make_shared<CountingJob>(1);
  auto done = tracking->done_.get_future();
  const auto start = Clock::now();
  pool.Wake(tracking);
  done.wait();
  const double waited = std::chrono::duration<double>(Clock::now() - start).count();
  // The searching job found the map: its next slice runs on the tracking worker.
  while ((*searching)->slices_ < 1) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  (*searching)->background_ = false;
  pool.Wake(*searching);
  while ((*searching)->slices_ < 2) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  return waited;
}

TEST(TrackingPool, BackgroundJobsRunOnTheirOwnWorkersAndNeverHoldATrackingWorker) {
  std::shared_ptr<LaneJob> searching;
  // With a background worker the tracking job does not wait for the 1.5 s slice.
  EXPECT_LT(TrackingJobWaitSeconds(1, TrackingPool::BackgroundPriority::kIdle, &searching), 1.0);
  ASSERT_EQ(searching->threads().size(), 2u);
  EXPECT_EQ(searching->threads()[0], "evloc-bg-0");
  EXPECT_EQ(searching->threads()[1], "evloc-track-0");
  EXPECT_EQ(searching->policies()[0], SCHED_IDLE);
  EXPECT_EQ(searching->policies()[1], SCHED_OTHER);
  // Without one it waits for the slice to end (one worker for both).
  EXPECT_GT(TrackingJobWaitSeconds(0, TrackingPool::BackgroundPriority::kIdle, &searching), 1.0);
  EXPECT_EQ(searching->threads()[0], "evloc-track-0");

  TrackingPool low(1, 1, TrackingPool::BackgroundPriority::kLow);
  EXPECT_TRUE(low.background_priority_applied());
  TrackingPool idle(1, 1, TrackingPool::BackgroundPriority::kIdle);
  EXPECT_TRUE(idle.background_priority_applied());
  EXPECT_EQ(ParseSearchPriority("low"), TrackingPool::BackgroundPriority::kLow);
  EXPECT_THROW(ParseSearchPriority("high"), InvalidArgumentError);
}

TEST(TrackingPool, RunnableJobsTakeTurnsOneSliceEach) {
  // One worker, two jobs with much work: the order of slices alternates (FIFO of runnable
  // jobs), so neither waits for the other to finish.
  TrackingPool pool(1);
  std::mutex mutex;
  std::string order;
  std::promise<void> gate;
  std::shared_future<void> open = gate.get_future().share();
  auto first = std::make_shared<CountingJob>(5, [&] {
    open.wait();
    std::lock_guard<std::mutex> lock(mutex);
    order += 'a';
  });
  auto second = std::make_shared<CountingJob>(5, [&] {
    std::lock_guard<std::mutex> lock(mutex);
    order += 'b';
  });
  auto first_done = first->done_.get_future();
  auto second_done = second->done_.get_future();
  pool.Wake(first);
  pool.Wake(second);
  gate.set_value();
  ASSERT_EQ(first_done.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  ASSERT_EQ(second_done.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_EQ(order, "ababababab");
}

TEST(TrackingPool, AWakeDuringASliceRunsTheJobAgain) {
  TrackingPool pool(2);
  std::atomic<int> slices{0};
  std::promise<void> in_slice;
  std::promise<void> release;
  std::shared_future<void> released = release.get_future().share();
  struct Job : TrackingPool::Job {
    std::function<bool()> body;
    bool RunSlice() override { return body(); }
  };
  auto job = std::make_shared<Job>();
  job->body = [&] {
    if (++slices == 1) {
      in_slice.set_value();
      released.wait();
    }
    return false;  // Nothing more by itself: only the wake below runs it again.
  };
  pool.Wake(job);
  in_slice.get_future().wait();
  pool.Wake(job);  // While it runs.
  release.set_value();
  const auto deadline = Clock::now() + std::chrono::seconds(10);
  while (slices.load() < 2 && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(slices.load(), 2);
}

TEST(TrackingPool, ZeroThreadsMeansOnePerCore) {
  TrackingPool pool(0);
  EXPECT_EQ(pool.threads(), TrackingPool::ThreadsFor(0));
  EXPECT_GE(pool.threads(), 1);
  EXPECT_EQ(TrackingPool::ThreadsFor(3), 3);
}

TEST(SharedTimer, RunsCallbacksInDeadlineOrderAndCancelDropsThem) {
  SharedTimer timer;
  std::mutex mutex;
  std::vector<int> order;
  std::promise<void> last;
  const auto now = Clock::now();
  const auto note = [&](int value) {
    std::lock_guard<std::mutex> lock(mutex);
    order.push_back(value);
  };
  timer.Schedule(now + std::chrono::milliseconds(60), [&] {
    note(3);
    last.set_value();
  });
  timer.Schedule(now + std::chrono::milliseconds(20), [&] { note(1); });
  const uint64_t dropped = timer.Schedule(now + std::chrono::milliseconds(30), [&] { note(99); });
  timer.Schedule(now + std::chrono::milliseconds(40), [&] { note(2); });
  EXPECT_TRUE(timer.Cancel(dropped));
  EXPECT_FALSE(timer.Cancel(dropped));
  ASSERT_EQ(last.get_future().wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_GE(Clock::now() - now, std::chrono::milliseconds(60));
  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_EQ(order, (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(timer.pending(), 0u);
}

TEST(SharedTimer, ACallbackMayScheduleTheNextOne) {
  // The watchdog pattern: each check schedules the next.
  SharedTimer timer;
  std::atomic<int> checks{0};
  std::promise<void> done;
  std::function<void()> check = [&] {
    if (++checks == 5) {
      done.set_value();
      return;
    }
    timer.Schedule(Clock::now() + std::chrono::milliseconds(2), check);
  };
  timer.Schedule(Clock::now(), check);
  ASSERT_EQ(done.get_future().wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_EQ(checks.load(), 5);
}

}  // namespace
}  // namespace evloc::service
