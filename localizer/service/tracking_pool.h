// The server's shared threads (docs/architecture.md, "Serving"): a fixed pool of tracking workers
// that runs the sessions' queued work, and one timer thread for every deadline of every stream
// (handshake, idle, drain). No thread belongs to a session: the server's thread count does not
// grow with the number of streams.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/common/thread_priority.h"

namespace evloc::service {

// A fixed pool of worker threads running serial jobs. A job (a session) is run by one worker at a
// time, never two: Wake() queues it once, and a job woken while it runs is queued again when its
// slice ends. Runnable jobs take turns in FIFO order, one slice each (a slice is what the job
// chooses to do per call: a session tracks one queued request), so a busy session cannot keep
// the others waiting for more than one of its slices. Thread-safe.
//
// Background lane: with background workers, a job that says it is background work (a session
// searching the map) is queued for them instead, each time it is queued, so its long slices never
// hold a worker that tracking sessions wait for; the background workers run at the priority the
// pool was given (idle: the kernel runs them only on CPU the other threads leave).
class TrackingPool {
 public:
  // One serial job. Its RunSlice is never called by two workers at once.
  class Job {
   public:
    virtual ~Job() = default;
    // Runs one slice of the job's work; returns true when more work is ready now (the job goes
    // to the back of the queue), false when it waits to be woken.
    virtual bool RunSlice() = 0;
    // True while the job's work is background work (asked whenever it is queued, from any
    // thread: must be thread-safe).
    virtual bool background() const { return false; }

   private:
    friend class TrackingPool;
    // Where the job is (guarded by the pool's mutex).
    enum class State { kIdle, kQueued, kRunning, kRunningWoken };
    State state_ = State::kIdle;
  };

  // The scheduling of the background workers (kNormal: the tracking workers' priority, only the
  // queue is separate).
  using BackgroundPriority = ThreadPriority;

  // Starts `threads` workers (>= 1; 0 is taken as the number of cores) and `background_threads`
  // background workers (0: background jobs share the workers).
  explicit TrackingPool(int threads, int background_threads = 0,
                        BackgroundPriority background_priority = BackgroundPriority::kIdle);
  // Stops the workers after their current slice; jobs still queued are dropped (released).
  ~TrackingPool();
  TrackingPool(const TrackingPool&) = delete;
  TrackingPool& operator=(const TrackingPool&) = delete;

  // Makes `job` runnable: queued unless it is queued already; a job running now runs again after
  // its slice. The pool keeps `job` alive while it is queued or running.
  void Wake(const std::shared_ptr<Job>& job);

  // The number of worker threads.
  int threads() const { return static_cast<int>(workers_.size()); }
  // The number of background worker threads.
  int background_threads() const { return static_cast<int>(background_workers_.size()); }
  // Jobs waiting for a worker now, background ones included (for tests and metrics).
  size_t queued() const;
  // Background jobs waiting for a background worker now.
  size_t background_queued() const;
  // True when the background workers run at the priority asked (false when the kernel refused
  // SCHED_IDLE or the nice value; vacuously true without background workers).
  bool background_priority_applied() const { return background_priority_applied_; }

  // The worker count for `requested` threads: `requested` when positive, else the number of
  // cores (at least 1).
  static int ThreadsFor(int requested);

 private:
  // One lane: its queue and the condition its workers wait on.
  struct Lane {
    std::condition_variable ready;
    std::deque<std::shared_ptr<Job>> queue;
  };
  void WorkerLoop(Lane& lane);
  // The lane `job` goes to now. Needs mutex_.
  Lane& LaneOf(const Job& job);

  mutable std::mutex mutex_;
  Lane lane_;
  Lane background_lane_;
  bool stopping_ = false;
  // Set by the constructor once the background workers have started.
  bool background_priority_applied_ = true;
  std::vector<std::thread> workers_;
  std::vector<std::thread> background_workers_;
};

// The priority named "idle", "low" or "normal"; throws InvalidArgumentError naming
// --search-priority otherwise.
TrackingPool::BackgroundPriority ParseSearchPriority(const std::string& name);

// One thread that runs callbacks at their deadlines (the watchdog of every stream). Callbacks run
// on the timer thread one after another and must be short (no blocking). Thread-safe.
class SharedTimer {
 public:
  using Clock = std::chrono::steady_clock;
  using Callback = std::function<void()>;

  SharedTimer();
  // Stops the thread; callbacks not run yet are dropped.
  ~SharedTimer();
  SharedTimer(const SharedTimer&) = delete;
  SharedTimer& operator=(const SharedTimer&) = delete;

  // Runs `callback` once at `deadline` (at once when it has passed) and returns its id. Callbacks
  // due at the same time run in the order they were scheduled.
  uint64_t Schedule(Clock::time_point deadline, Callback callback);
  // Drops the callback `id` if it has not started; false when it has run, is running or is
  // unknown.
  bool Cancel(uint64_t id);
  // Callbacks waiting now.
  size_t pending() const;

 private:
  void Loop();

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  // Deadline and id (the id breaks ties in schedule order) -> callback.
  std::map<std::pair<Clock::time_point, uint64_t>, Callback> callbacks_;
  std::map<uint64_t, Clock::time_point> deadlines_;
  uint64_t last_id_ = 0;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace evloc::service
