// The PACKED event encoding of the service API (docs/api.md, proto/evloc/localizer.proto) at the
// byte level, for the server and its clients alike: 8 bytes per event, little-endian, a 32-bit
// word (bits 0..30: time offset from the packet's time_base_ns in ns, bit 31: polarity ON) then
// x and y as 16-bit words. The session's checks of a packet (sensor bounds, order, packet ends)
// are the service's (localizer/service/session.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/events/event.h"
#include "evloc/localizer.pb.h"

namespace evloc::wire {

// Bytes per event of the PACKED encoding.
inline constexpr size_t kPackedEventBytes = 8;

// Largest time offset of a PACKED event from its packet's time base, ns (2^31 - 1).
inline constexpr int64_t kMaxPackedOffsetNs = 0x7fffffff;

// Encodes events [begin, end) of `events` in the PACKED layout relative to `time_base_ns`.
// Throws InvalidArgumentError when an event lies before the base or more than
// kMaxPackedOffsetNs after it.
std::string EncodePackedEvents(const EventBuffer& events, size_t begin, size_t end,
                               int64_t time_base_ns);

// Decodes PACKED `data` relative to `time_base_ns` and appends the events to `out`, as they are
// (no order or bounds checks). Throws InvalidArgumentError (nothing appended) when the data is not
// a whole number of kPackedEventBytes records or time_base_ns + kMaxPackedOffsetNs overflows.
void DecodePackedEvents(std::string_view data, int64_t time_base_ns, EventBuffer* out);

// Splits time-ordered events into PACKED EventPackets of consecutive windows
// (origin_ns + k window_ns, origin_ns + (k + 1) window_ns], k = 0, 1, ... up to the window of
// the last event; a window without events gives an empty packet. Throws InvalidArgumentError
// when window_ns is not in 1..kMaxPackedOffsetNs or an event lies at or before origin_ns.
std::vector<api::EventPacket> PackEventWindows(const EventBuffer& events, int64_t origin_ns,
                                               int64_t window_ns);

// A client's thinning while its session searches (SessionStarted.searching_event_rate,
// docs/api.md "Thinning while searching"): the stride k of the events kept (every k-th) so that
// `events` over `span_ns` of session time stay within `rate` events per second,
// ceil(events / (rate * span)); one event when not even one fits; 1 (all of them) when they
// already fit, when `rate` is 0 (no advice) or the span is not positive.
size_t ThinningStride(size_t events, int64_t span_ns, uint64_t rate);

// Thins events [begin, end) of `events`, spanning `span_ns`, to `rate` events per second: the
// stride k = ThinningStride(end - begin, span_ns, rate), and when k > 1 every k-th event from
// `begin` in `kept` (cleared first; untouched when k is 1). Returns k.
size_t ThinEvents(const EventBuffer& events, size_t begin, size_t end, int64_t span_ns,
                  uint64_t rate, EventBuffer* kept);

}  // namespace evloc::wire
