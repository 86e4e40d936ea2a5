#include "core/events/event.h"

#include <algorithm>
#include <string>

#include "core/common/error.h"

namespace evloc {

void SensorSize::Check() const {
  if (width <= 0 || height <= 0 || width > 65535 || height > 65535) {
    throw InvalidArgumentError("sensor size " + std::to_string(width) + "x" +
                               std::to_string(height) +
                               " is invalid: width and height must be in 1..65535");
  }
}

void EventBuffer::clear() {
  t_ns.clear();
  x.clear();
  y.clear();
  polarity.clear();
}

void EventBuffer::reserve(size_t count) {
  t_ns.reserve(count);
  x.reserve(count);
  y.reserve(count);
  polarity.reserve(count);
}

void EventBuffer::Append(const EventBuffer& other) {
  Append(other.t_ns.data(), other.x.data(), other.y.data(), other.polarity.data(), other.size());
}

void EventBuffer::Append(const EventBuffer& other, size_t begin, size_t count) {
  Append(other.t_ns.data() + begin, other.x.data() + begin, other.y.data() + begin,
         other.polarity.data() + begin, count);
}

void EventBuffer::Append(const int64_t* t_ns_values, const uint16_t* x_values,
                         const uint16_t* y_values, const int8_t* polarity_values, size_t count) {
  // Grown without a fill, then copied as bytes: `insert` with EventArray's allocator would
  // construct element by element (std::vector copies as one memmove only with std::allocator).
  const size_t base = size();
  t_ns.resize(base + count);
  x.resize(base + count);
  y.resize(base + count);
  polarity.resize(base + count);
  std::copy_n(t_ns_values, count, t_ns.data() + base);
  std::copy_n(x_values, count, x.data() + base);
  std::copy_n(y_values, count, y.data() + base);
  std::copy_n(polarity_values, count, polarity.data() + base);
}

void EventBuffer::AppendEvery(const EventBuffer& other, size_t begin, size_t end, size_t stride) {
  reserve(size() + (end > begin ? (end - begin + stride - 1) / stride : 0));
  for (size_t i = begin; i < end; i += stride) push_back(other[i]);
}

bool EventBuffer::IsConsistent() const {
  return x.size() == t_ns.size() && y.size() == t_ns.size() && polarity.size() == t_ns.size();
}

}  // namespace evloc
