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
#include <thread>
#include <vector>

namespace evloc::service {

// A fixed pool of worker threads running serial jobs. A job (a session) is run by one worker at a
// time, never two: Wake() queues it once, and a job woken while it runs is queued again when its
// slice ends. Runnable jobs take turns in FIFO order, one slice each (a slice is what the job
// chooses to do per call: a session tracks one queued request), so a busy session cannot keep
// the others waiting for more than one of its slices. Thread-safe.
class TrackingPool {
 public:
  // One serial job. Its RunSlice is never called by two workers at once.
  class Job {
   public:
    virtual ~Job() = default;
    // Runs one slice of the job's work; returns true when more work is ready now (the job goes
    // to the back of the queue), false when it waits to be woken.
    virtual bool RunSlice() = 0;

   private:
    friend class TrackingPool;
    // Where the job is (guarded by the pool's mutex).
    enum class State { kIdle, kQueued, kRunning, kRunningWoken };
    State state_ = State::kIdle;
  };

  // Starts `threads` workers (>= 1; 0 is taken as the number of cores).
  explicit TrackingPool(int threads);
  // Stops the workers after their current slice; jobs still queued are dropped (released).
  ~TrackingPool();
  TrackingPool(const TrackingPool&) = delete;
  TrackingPool& operator=(const TrackingPool&) = delete;

  // Makes `job` runnable: queued unless it is queued already; a job running now runs again after
  // its slice. The pool keeps `job` alive while it is queued or running.
  void Wake(const std::shared_ptr<Job>& job);

  // The number of worker threads.
  int threads() const { return static_cast<int>(workers_.size()); }
  // Jobs waiting for a worker now (for tests and metrics).
  size_t queued() const;

  // The worker count for `requested` threads: `requested` when positive, else the number of
  // cores (at least 1).
  static int ThreadsFor(int requested);

 private:
  void WorkerLoop();

  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<std::shared_ptr<Job>> queue_;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

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
