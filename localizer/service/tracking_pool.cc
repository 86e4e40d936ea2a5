#include "localizer/service/tracking_pool.h"

#include <string>
#include <utility>

#include <pthread.h>

#include "core/common/error.h"

namespace evloc::service {

int TrackingPool::ThreadsFor(int requested) {
  if (requested > 0) return requested;
  const unsigned cores = std::thread::hardware_concurrency();
  return cores == 0 ? 1 : static_cast<int>(cores);
}

TrackingPool::TrackingPool(int threads, int background_threads,
                           BackgroundPriority background_priority) {
  if (threads < 0)
    throw InvalidArgumentError("TrackingPool: the thread count must not be negative");
  if (background_threads < 0) {
    throw InvalidArgumentError("TrackingPool: the background thread count must not be negative");
  }
  const int count = ThreadsFor(threads);
  workers_.reserve(static_cast<size_t>(count));
  for (int i = 0; i < count; ++i) {
    workers_.emplace_back([this, i] {
      // Named for top, perf and gdb (at most 15 characters).
      pthread_setname_np(pthread_self(),
                         ("evloc-track-" + std::to_string(i)).substr(0, 15).c_str());
      WorkerLoop(lane_);
    });
  }
  background_priority_applied_ = StartThreadsAtPriority(
      background_threads, background_priority,
      [this](int i) {
        pthread_setname_np(pthread_self(), ("evloc-bg-" + std::to_string(i)).substr(0, 15).c_str());
        WorkerLoop(background_lane_);
      },
      &background_workers_);
}

TrackingPool::~TrackingPool() {
  std::deque<std::shared_ptr<Job>> dropped;
  std::deque<std::shared_ptr<Job>> dropped_background;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  lane_.ready.notify_all();
  background_lane_.ready.notify_all();
  for (std::thread& worker : workers_) worker.join();
  for (std::thread& worker : background_workers_) worker.join();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    dropped.swap(lane_.queue);
    dropped_background.swap(background_lane_.queue);
  }
  // Released outside the lock: a job's destructor may wake another job.
}

TrackingPool::Lane& TrackingPool::LaneOf(const Job& job) {
  return !background_workers_.empty() && job.background() ? background_lane_ : lane_;
}

void TrackingPool::Wake(const std::shared_ptr<Job>& job) {
  Lane* lane = nullptr;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    switch (job->state_) {
      case Job::State::kQueued:
      case Job::State::kRunningWoken:
        return;
      case Job::State::kRunning:
        job->state_ = Job::State::kRunningWoken;
        return;
      case Job::State::kIdle:
        if (stopping_) return;
        job->state_ = Job::State::kQueued;
        lane = &LaneOf(*job);
        lane->queue.push_back(job);
        break;
    }
  }
  lane->ready.notify_one();
}

size_t TrackingPool::queued() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return lane_.queue.size() + background_lane_.queue.size();
}

size_t TrackingPool::background_queued() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return background_lane_.queue.size();
}

void TrackingPool::WorkerLoop(Lane& own) {
  std::unique_lock<std::mutex> lock(mutex_);
  while (true) {
    own.ready.wait(lock, [&] { return stopping_ || !own.queue.empty(); });
    if (stopping_) return;
    std::shared_ptr<Job> job = std::move(own.queue.front());
    own.queue.pop_front();
    job->state_ = Job::State::kRunning;
    lock.unlock();
    const bool more = job->RunSlice();
    lock.lock();
    if ((more || job->state_ == Job::State::kRunningWoken) && !stopping_) {
      job->state_ = Job::State::kQueued;
      // Its lane now: a session that found the map leaves the background lane at once.
      Lane& lane = LaneOf(*job);
      lane.queue.push_back(std::move(job));
      lane.ready.notify_one();
    } else {
      job->state_ = Job::State::kIdle;
    }
    if (job) {
      // The last reference may go here: release it outside the lock.
      lock.unlock();
      job.reset();
      lock.lock();
    }
  }
}

TrackingPool::BackgroundPriority ParseSearchPriority(const std::string& name) {
  const std::optional<ThreadPriority> priority = ThreadPriorityNamed(name);
  if (!priority) {
    throw InvalidArgumentError("--search-priority must be idle, low or normal, got '" + name + "'");
  }
  return *priority;
}

SharedTimer::SharedTimer()
    : thread_([this] {
        pthread_setname_np(pthread_self(), "evloc-timer");
        Loop();
      }) {}

SharedTimer::~SharedTimer() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  changed_.notify_all();
  thread_.join();
}

uint64_t SharedTimer::Schedule(Clock::time_point deadline, Callback callback) {
  uint64_t id = 0;
  bool earliest = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    id = ++last_id_;
    earliest = callbacks_.empty() || deadline < callbacks_.begin()->first.first;
    callbacks_.emplace(std::make_pair(deadline, id), std::move(callback));
    deadlines_.emplace(id, deadline);
  }
  if (earliest) changed_.notify_all();
  return id;
}

bool SharedTimer::Cancel(uint64_t id) {
  Callback dropped;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto found = deadlines_.find(id);
    if (found == deadlines_.end()) return false;
    const auto entry = callbacks_.find(std::make_pair(found->second, id));
    dropped = std::move(entry->second);
    callbacks_.erase(entry);
    deadlines_.erase(found);
  }
  return true;  // `dropped` (and what it holds) is released outside the lock.
}

size_t SharedTimer::pending() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return callbacks_.size();
}

void SharedTimer::Loop() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stopping_) {
    if (callbacks_.empty()) {
      changed_.wait(lock);
      continue;
    }
    const auto first = callbacks_.begin();
    if (first->first.first > Clock::now()) {
      changed_.wait_until(lock, first->first.first);
      continue;
    }
    Callback callback = std::move(first->second);
    deadlines_.erase(first->first.second);
    callbacks_.erase(first);
    lock.unlock();
    callback();
    callback = nullptr;  // Released outside the lock too.
    lock.lock();
  }
}

}  // namespace evloc::service
