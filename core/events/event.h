// Events of an event camera and a compact structure-of-arrays buffer of them
// (docs/event-formats.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace evloc {

// One brightness-change event.
struct Event {
  // Time stamp, nanoseconds, on the recording's clock.
  int64_t t_ns = 0;
  // Pixel column; pixel centres at integer coordinates.
  uint16_t x = 0;
  // Pixel row.
  uint16_t y = 0;
  // +1 for a brightness increase (ON), -1 for a decrease (OFF).
  int8_t polarity = 1;

  // Field-wise equality.
  friend bool operator==(const Event&, const Event&) = default;
};

// The pixel array size of a sensor.
struct SensorSize {
  // Number of columns; events have x < width.
  int width = 0;
  // Number of rows; events have y < height.
  int height = 0;

  // True when an event at (x, y) lies on the sensor.
  bool Contains(int x, int y) const { return x >= 0 && y >= 0 && x < width && y < height; }
  // Throws InvalidArgumentError unless 0 < width, height <= 65535.
  void Check() const;

  // Field-wise equality.
  friend bool operator==(const SensorSize&, const SensorSize&) = default;
};

// An allocator that default-initialises where std::allocator value-initialises: `resize` of a
// vector of plain numbers leaves the new elements unwritten instead of zeroing them. Every
// decoder sizes an EventBuffer first and then writes each new element; the zero-fill before
// that was a tenth of reading an uncompressed AEDAT4 file (docs/benchmarks.md, "Events").
// Written here because the standard library has no such option (Boost.Container's
// default_init_t would, but Boost is not one of evloc's dependencies).
template <typename T>
class DefaultInitAllocator : public std::allocator<T> {
 public:
  template <typename U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  DefaultInitAllocator() noexcept = default;
  template <typename U>
  DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}

  // Default-initialises (nothing for plain numbers).
  template <typename U>
  void construct(U* where) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(where)) U;
  }
  template <typename U, typename... Args>
  void construct(U* where, Args&&... args) {
    ::new (static_cast<void*>(where)) U(std::forward<Args>(args)...);
  }
};

// One array of an EventBuffer: a std::vector whose resize does not zero the new elements.
template <typename T>
using EventArray = std::vector<T, DefaultInitAllocator<T>>;

// A sequence of events stored as a structure of arrays: the four vectors always have the same
// length, element i of each describing event i.
class EventBuffer {
 public:
  // Time stamps, nanoseconds.
  EventArray<int64_t> t_ns;
  // Pixel columns.
  EventArray<uint16_t> x;
  // Pixel rows.
  EventArray<uint16_t> y;
  // +1 ON, -1 OFF.
  EventArray<int8_t> polarity;

  // Number of events.
  size_t size() const { return t_ns.size(); }
  // True when there are no events.
  bool empty() const { return t_ns.empty(); }
  // Removes every event (keeps the capacity).
  void clear();
  // Reserves room for `count` events in every array.
  void reserve(size_t count);
  // Appends one event.
  void push_back(const Event& event) {
    t_ns.push_back(event.t_ns);
    x.push_back(event.x);
    y.push_back(event.y);
    polarity.push_back(event.polarity);
  }
  // Event `index` (unchecked, like std::vector::operator[]).
  Event operator[](size_t index) const {
    return {t_ns[index], x[index], y[index], polarity[index]};
  }
  // Appends every event of `other`.
  void Append(const EventBuffer& other);
  // Appends events [begin, begin + count) of `other` (unchecked).
  void Append(const EventBuffer& other, size_t begin, size_t count);
  // Appends every `stride`-th event of [begin, end) of `other`, from `begin` (unchecked range;
  // stride >= 1).
  void AppendEvery(const EventBuffer& other, size_t begin, size_t end, size_t stride);
  // Appends `count` events given as parallel arrays.
  void Append(const int64_t* t_ns_values, const uint16_t* x_values, const uint16_t* y_values,
              const int8_t* polarity_values, size_t count);
  // True when all four arrays have the same length (an invariant every evloc function keeps).
  bool IsConsistent() const;

  // Equality of every event, in order.
  friend bool operator==(const EventBuffer&, const EventBuffer&) = default;
};

}  // namespace evloc
