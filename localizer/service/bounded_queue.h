// A bounded, closable multi-producer multi-consumer queue: the hand-over between a session's
// stream reader and its tracking worker (the reader never waits: a full queue is the session's
// overflow).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <optional>

namespace evloc::service {

// What a push did.
enum class PushResult {
  // The item was queued.
  kQueued,
  // The queue is full; the item was not queued.
  kFull,
  // The queue was closed or aborted; the item was not queued.
  kClosed,
};

// A FIFO of at most `capacity` items. Close() lets consumers drain what is queued; Abort()
// drops it.
template <typename T>
class BoundedQueue {
 public:
  // `capacity` >= 1.
  explicit BoundedQueue(size_t capacity) : capacity_(capacity) {}

  // Queues `item` unless the queue is full or closed.
  PushResult TryPush(T item) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (closed_) return PushResult::kClosed;
    if (items_.size() >= capacity_) return PushResult::kFull;
    items_.push_back(std::move(item));
    not_empty_.notify_one();
    return PushResult::kQueued;
  }

  // The next item, waiting up to `timeout`; nullopt on timeout or when closed and drained.
  // `timed_out` (optional) tells the two apart.
  std::optional<T> Pop(std::chrono::steady_clock::duration timeout, bool* timed_out = nullptr) {
    std::unique_lock<std::mutex> lock(mutex_);
    const bool ready =
        not_empty_.wait_for(lock, timeout, [&] { return closed_ || !items_.empty(); });
    if (timed_out) *timed_out = !ready;
    if (!ready || items_.empty()) return std::nullopt;
    T item = std::move(items_.front());
    items_.pop_front();
    return item;
  }

  // No more pushes; consumers still get what is queued.
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    not_empty_.notify_all();
  }

  // No more pushes, and what is queued is dropped.
  void Abort() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    items_.clear();
    not_empty_.notify_all();
  }

  // Items queued now.
  size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return items_.size();
  }
  // The capacity.
  size_t capacity() const { return capacity_; }

 private:
  const size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable not_empty_;
  std::deque<T> items_;
  bool closed_ = false;
};

}  // namespace evloc::service
