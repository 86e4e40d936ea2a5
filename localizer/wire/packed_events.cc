#include "localizer/wire/packed_events.h"

#include <cmath>

#include <limits>

#include "core/common/error.h"

namespace evloc::wire {

std::string EncodePackedEvents(const EventBuffer& events, size_t begin, size_t end,
                               int64_t time_base_ns) {
  std::string data(kPackedEventBytes * (end - begin), '\0');
  auto* out = reinterpret_cast<uint8_t*>(data.data());
  for (size_t i = begin; i < end; ++i, out += kPackedEventBytes) {
    const int64_t offset_ns = events.t_ns[i] - time_base_ns;
    if (offset_ns < 0 || offset_ns > kMaxPackedOffsetNs) {
      throw InvalidArgumentError("EncodePackedEvents: event " + std::to_string(i) +
                                 " lies outside [time base, time base + 2^31 ns)");
    }
    const uint32_t word =
        static_cast<uint32_t>(offset_ns) | (events.polarity[i] > 0 ? 0x80000000u : 0u);
    out[0] = static_cast<uint8_t>(word);
    out[1] = static_cast<uint8_t>(word >> 8);
    out[2] = static_cast<uint8_t>(word >> 16);
    out[3] = static_cast<uint8_t>(word >> 24);
    out[4] = static_cast<uint8_t>(events.x[i]);
    out[5] = static_cast<uint8_t>(events.x[i] >> 8);
    out[6] = static_cast<uint8_t>(events.y[i]);
    out[7] = static_cast<uint8_t>(events.y[i] >> 8);
  }
  return data;
}

void DecodePackedEvents(std::string_view data, int64_t time_base_ns, EventBuffer* out) {
  if (data.size() % kPackedEventBytes != 0) {
    throw InvalidArgumentError("PACKED data of " + std::to_string(data.size()) +
                               " bytes is not a whole number of 8-byte events");
  }
  if (time_base_ns > std::numeric_limits<int64_t>::max() - kMaxPackedOffsetNs) {
    throw InvalidArgumentError("PACKED time base " + std::to_string(time_base_ns) +
                               " ns is too large: event times would overflow");
  }
  const auto* bytes = reinterpret_cast<const uint8_t*>(data.data());
  const size_t first = out->size();
  const size_t count = data.size() / kPackedEventBytes;
  out->t_ns.resize(first + count);
  out->x.resize(first + count);
  out->y.resize(first + count);
  out->polarity.resize(first + count);
  for (size_t i = 0; i < count; ++i) {
    const uint8_t* record = bytes + i * kPackedEventBytes;
    const uint32_t time_word =
        static_cast<uint32_t>(record[0]) | (static_cast<uint32_t>(record[1]) << 8) |
        (static_cast<uint32_t>(record[2]) << 16) | (static_cast<uint32_t>(record[3]) << 24);
    out->t_ns[first + i] = time_base_ns + static_cast<int64_t>(time_word & 0x7fffffffu);
    out->polarity[first + i] = (time_word >> 31) != 0 ? 1 : -1;
    out->x[first + i] = static_cast<uint16_t>(record[4] | (record[5] << 8));
    out->y[first + i] = static_cast<uint16_t>(record[6] | (record[7] << 8));
  }
}

std::vector<api::EventPacket> PackEventWindows(const EventBuffer& events, int64_t origin_ns,
                                               int64_t window_ns) {
  if (window_ns < 1 || window_ns > kMaxPackedOffsetNs) {
    throw InvalidArgumentError("PackEventWindows: the window must be 1 .. 2^31 - 1 ns");
  }
  if (!events.empty() && events.t_ns.front() <= origin_ns) {
    throw InvalidArgumentError("PackEventWindows: the first event lies at or before the origin");
  }
  std::vector<api::EventPacket> packets;
  size_t begin = 0;
  for (int64_t window_start = origin_ns; begin < events.size(); window_start += window_ns) {
    const int64_t window_end = window_start + window_ns;
    size_t end = begin;
    while (end < events.size() && events.t_ns[end] <= window_end) ++end;
    api::EventPacket& packet = packets.emplace_back();
    packet.set_encoding(api::EVENT_ENCODING_PACKED);
    packet.set_time_base_ns(window_start);
    packet.set_end_t_ns(window_end);
    packet.set_data(EncodePackedEvents(events, begin, end, window_start));
    begin = end;
  }
  return packets;
}

size_t ThinningStride(size_t events, int64_t span_ns, uint64_t rate) {
  if (rate == 0 || span_ns <= 0 || events == 0) return 1;
  const double allowed = static_cast<double>(rate) * static_cast<double>(span_ns) * 1e-9;
  if (static_cast<double>(events) <= allowed) return 1;
  if (allowed < 1.0) return events;  // one event of the packet
  return static_cast<size_t>(std::ceil(static_cast<double>(events) / allowed));
}

size_t ThinEvents(const EventBuffer& events, size_t begin, size_t end, int64_t span_ns,
                  uint64_t rate, EventBuffer* kept) {
  const size_t stride = ThinningStride(end - begin, span_ns, rate);
  if (stride > 1) {
    kept->clear();
    kept->AppendEvery(events, begin, end, stride);
  }
  return stride;
}

}  // namespace evloc::wire
