// A bounded, closable multi-producer multi-consumer queue: the hand-over between a session's
// stream reader (gRPC's read callback) and the tracking pool (the reader never waits: a full queue
// is the session's overflow); bounded in items and in weight (a session's queue: packets and
// events). And the server-wide memory budget that queued items are charged to.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

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

// A FIFO of at most `capacity` items whose weights sum to at most `max_weight` (an item heavier
// than max_weight alone is queued only into an empty queue). Close() lets consumers drain what
// is queued; Abort() drops it. Nobody waits on it: the consumer is woken by other means (the
// tracking pool).
template <typename T>
class BoundedQueue {
 public:
  // `capacity` >= 1; `max_weight` >= 1.
  explicit BoundedQueue(size_t capacity, uint64_t max_weight = std::numeric_limits<uint64_t>::max())
      : capacity_(capacity), max_weight_(max_weight) {}

  // Queues `item` of `weight` unless the queue is full (items or weight) or closed.
  PushResult TryPush(T item, uint64_t weight = 0) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (closed_) return PushResult::kClosed;
    if (FullLocked(weight)) return PushResult::kFull;
    items_.emplace_back(std::move(item), weight);
    weight_ += weight;
    return PushResult::kQueued;
  }

  // The next item without waiting; nullopt when none is queued.
  std::optional<T> TryPop() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (items_.empty()) return std::nullopt;
    T item = std::move(items_.front().first);
    weight_ -= items_.front().second;
    items_.pop_front();
    return item;
  }

  // Drops items from the front while `droppable(item)` holds, at most `count`; returns how many
  // and their weight. The dropped items are destroyed after the lock is released.
  template <typename Droppable>
  std::pair<size_t, uint64_t> DropFront(size_t count, const Droppable& droppable) {
    std::vector<T> dropped;
    uint64_t dropped_weight = 0;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      while (dropped.size() < count && !items_.empty() && droppable(items_.front().first)) {
        dropped.push_back(std::move(items_.front().first));
        dropped_weight += items_.front().second;
        weight_ -= items_.front().second;
        items_.pop_front();
      }
    }
    return {dropped.size(), dropped_weight};
  }

  // Merges into the last queued item instead of queuing a new one: when the queue holds an item
  // for which `can_append(last)` holds and `added_weight` more fits the weight bound,
  // `append(last)` changes it and its weight grows by `added_weight`; returns whether it did.
  // `append` runs under the lock: keep it short (a searching session appends one packet's
  // thinned events).
  template <typename CanAppend, typename Append>
  bool TryAppendToBack(uint64_t added_weight, const CanAppend& can_append, const Append& append) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (closed_ || items_.empty() || !can_append(items_.back().first) ||
        added_weight > max_weight_ - weight_) {
      return false;
    }
    append(items_.back().first);
    items_.back().second += added_weight;
    weight_ += added_weight;
    return true;
  }

  // Folds adjacent pairs of items, front to back: where `foldable(a, b)` holds for an item `a`
  // and the next `b`, `fold(a, b)` merges b into a and returns a's new weight, and b goes.
  // Returns how many items went and the weight freed. The work is done outside the lock on the
  // items taken out (a consumer meanwhile finds the queue empty, as if it were drained a moment
  // early); items pushed meanwhile stay behind them, and an Abort meanwhile drops them all.
  template <typename Foldable, typename Fold>
  std::pair<size_t, uint64_t> FoldPairs(const Foldable& foldable, const Fold& fold) {
    std::deque<std::pair<T, uint64_t>> items;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      items.swap(items_);
      weight_ = 0;
    }
    std::deque<std::pair<T, uint64_t>> folded;
    size_t gone = 0;
    uint64_t before = 0;
    uint64_t after = 0;
    for (const auto& entry : items) before += entry.second;
    for (size_t i = 0; i < items.size(); ++i) {
      if (i + 1 < items.size() && foldable(items[i].first, items[i + 1].first)) {
        items[i].second = fold(items[i].first, std::move(items[i + 1].first));
        ++gone;
        folded.push_back(std::move(items[i++]));
      } else {
        folded.push_back(std::move(items[i]));
      }
      after += folded.back().second;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (aborted_) return {gone, before - std::min(before, after)};
    for (auto& entry : items_) folded.push_back(std::move(entry));
    items_.swap(folded);
    weight_ = 0;
    for (const auto& entry : items_) weight_ += entry.second;
    return {gone, before - std::min(before, after)};
  }

  // True when the queue could not take an item of `weight` now (items or weight).
  bool WouldBeFull(uint64_t weight) const {
    std::lock_guard<std::mutex> lock(mutex_);
    return FullLocked(weight);
  }

  // True when closed (or aborted) and nothing is left to pop.
  bool drained() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return closed_ && items_.empty();
  }

  // No more pushes; consumers still get what is queued.
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
  }

  // No more pushes, and what is queued is dropped.
  void Abort() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    aborted_ = true;
    items_.clear();
    weight_ = 0;
  }

  // Items queued now.
  size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return items_.size();
  }
  // Sum of the weights of the items queued now.
  uint64_t weight() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return weight_;
  }
  // The capacity.
  size_t capacity() const { return capacity_; }
  // The most weight queued at once.
  uint64_t max_weight() const { return max_weight_; }

 private:
  // The queue cannot take an item of `weight` (items or weight; an item heavier than the bound
  // still enters an empty queue). Needs mutex_.
  bool FullLocked(uint64_t weight) const {
    return items_.size() >= capacity_ || (!items_.empty() && weight > max_weight_ - weight_);
  }

  const size_t capacity_;
  const uint64_t max_weight_;
  mutable std::mutex mutex_;
  std::deque<std::pair<T, uint64_t>> items_;
  uint64_t weight_ = 0;
  bool closed_ = false;
  bool aborted_ = false;
};

// A budget of bytes shared by threads (the server's decoded, queued data): reservations that
// would exceed the limit are refused. Thread-safe.
class MemoryBudget {
 public:
  // Reservations beyond `limit_bytes` are refused.
  explicit MemoryBudget(int64_t limit_bytes) : limit_(limit_bytes) {}

  // A reservation, released when destroyed (movable).
  class Reservation {
   public:
    Reservation() = default;
    Reservation(MemoryBudget* budget, int64_t bytes) : budget_(budget), bytes_(bytes) {}
    Reservation(Reservation&& other) noexcept
        : budget_(std::exchange(other.budget_, nullptr)), bytes_(other.bytes_) {}
    Reservation& operator=(Reservation&& other) noexcept {
      if (this != &other) {
        Release();
        budget_ = std::exchange(other.budget_, nullptr);
        bytes_ = other.bytes_;
      }
      return *this;
    }
    Reservation(const Reservation&) = delete;
    Reservation& operator=(const Reservation&) = delete;
    ~Reservation() { Release(); }
    // Gives the bytes back now.
    void Release() {
      if (budget_) budget_->used_ -= bytes_;
      budget_ = nullptr;
    }

   private:
    MemoryBudget* budget_ = nullptr;
    int64_t bytes_ = 0;
  };

  // Reserves `bytes` (>= 0); nullopt when that would exceed the limit.
  std::optional<Reservation> TryReserve(int64_t bytes) {
    int64_t used = used_.load();
    do {
      if (bytes > limit_ - used) return std::nullopt;
    } while (!used_.compare_exchange_weak(used, used + bytes));
    return Reservation(this, bytes);
  }
  // Bytes reserved now.
  int64_t used() const { return used_.load(); }
  // The limit, bytes.
  int64_t limit() const { return limit_; }

 private:
  const int64_t limit_;
  std::atomic<int64_t> used_{0};
};

}  // namespace evloc::service
