// libFuzzer target: a session's EventPacket decoding and validation, through RequestValidator as
// the server's stream reader runs it (docs/reliability.md §4), for random sensor sizes, sensor
// time offsets and encodings (PACKED, EVT3, EVT2, unset and unknown).
//
// Input: a header, then packets until the input ends.
//   header: uint16 width - 1, uint16 height - 1 (each mod 2048), int64 sensor_time_offset_ns,
//           int64 start_t_ns (the "previous end" the first packet's times count from)
//   packet: uint8 encoding (mod 5: 0 unset, 1 PACKED, 2 EVT3, 3 EVT2, 4 unknown),
//           int32 time_base_ns - previous end, int32 end_t_ns - previous end, uint16 size, data
// Oracles (abort): only OK or INVALID_ARGUMENT; an accepted packet's events are on the sensor, in
// order, after the previous end and at or before its own (CheckAcceptedPacket); PACKED data
// re-encodes to the same bytes; the raw events of the accepted packets equal one decoder's
// output on their concatenated bytes, shifted by the offset.
#include <algorithm>
#include <climits>
#include <memory>
#include <vector>

#include "core/common/error.h"
#include "core/events/prophesee_decoder.h"
#include "localizer/service/fuzz/session_fuzz_common.h"
#include "localizer/wire/packed_events.h"

namespace evloc::service::fuzz {
namespace {

api::SessionStart StartFor(int width, int height, int64_t sensor_time_offset_ns) {
  api::SessionStart start;
  map_format::Camera* camera = start.mutable_camera();
  camera->set_model(map_format::CAMERA_MODEL_PINHOLE);
  camera->set_width(static_cast<uint32_t>(width));
  camera->set_height(static_cast<uint32_t>(height));
  camera->set_fx(100);
  camera->set_fy(100);
  camera->set_cx(width / 2.0);
  camera->set_cy(height / 2.0);
  start.mutable_initial_world_from_cam()->mutable_rotation()->set_w(1);
  start.set_sensor_time_offset_ns(sensor_time_offset_ns);
  return start;
}

int Run(const uint8_t* data, size_t size) {
  FuzzInput input(data, size);
  const int width = 1 + input.Read<uint16_t>() % 2048;
  const int height = 1 + input.Read<uint16_t>() % 2048;
  const int64_t offset_ns = input.Read<int64_t>();
  int64_t previous_end_t_ns = input.Read<int64_t>();

  SessionLimits limits;
  limits.max_camera_pixels = int64_t{2048} * 2048;
  // No tracker runs here: any span (the requests target checks the span limit).
  limits.max_packet_span_ns = int64_t{1} << 60;
  SessionSettings settings;
  try {
    settings = SessionSettingsFromProto(StartFor(width, height, offset_ns), limits);
  } catch (const InvalidArgumentError&) {
    return 0;  // An offset out of range: the session is refused at its start.
  }
  RequestValidator validator(settings, limits);
  const SensorSize sensor{width, height};

  std::string raw_bytes;
  EventBuffer raw_events;
  api::EventEncoding raw_encoding = api::EVENT_ENCODING_UNSPECIFIED;
  std::optional<int64_t> accepted_end_t_ns;
  // Per accepted packet: index of its first raw event, and the end of the packet before it.
  struct Boundary {
    size_t first_event;
    std::optional<int64_t> previous_end_t_ns;
  };
  std::vector<Boundary> boundaries;
  api::TrackRequest request;
  SessionItem item;
  while (!input.done()) {
    api::EventPacket* packet = request.mutable_events();
    packet->set_encoding(static_cast<api::EventEncoding>(input.Read<uint8_t>() % 5));
    const int64_t base_delta = input.Read<int32_t>();
    const int64_t end_delta = input.Read<int32_t>();
    // Wrapping arithmetic (defined for unsigned): extreme times must be refused, not overflow.
    packet->set_time_base_ns(static_cast<int64_t>(static_cast<uint64_t>(previous_end_t_ns) +
                                                  static_cast<uint64_t>(base_delta)));
    packet->set_end_t_ns(static_cast<int64_t>(static_cast<uint64_t>(previous_end_t_ns) +
                                              static_cast<uint64_t>(end_delta)));
    packet->set_data(input.Bytes(input.Read<uint16_t>()));
    previous_end_t_ns = packet->end_t_ns();

    const grpc::Status status = validator.Accept(request, &item);
    CheckStatus(status, {grpc::StatusCode::INVALID_ARGUMENT});
    if (!status.ok()) break;  // The session ends with the first error.
    CheckAcceptedPacket(item, sensor, accepted_end_t_ns);
    EVLOC_FUZZ_REQUIRE(validator.decoder().end_t_ns() == item.t_ns);
    boundaries.push_back({raw_events.size(), accepted_end_t_ns});
    accepted_end_t_ns = item.t_ns;
    if (packet->data().empty()) continue;
    if (packet->encoding() == api::EVENT_ENCODING_PACKED) {
      EVLOC_FUZZ_REQUIRE(wire::EncodePackedEvents(item.events, 0, item.events.size(),
                                                  packet->time_base_ns()) == packet->data());
    } else {
      EVLOC_FUZZ_REQUIRE(raw_encoding == api::EVENT_ENCODING_UNSPECIFIED ||
                         raw_encoding == packet->encoding());
      raw_encoding = packet->encoding();
      raw_bytes += packet->data();
      for (size_t i = 0; i < item.events.size(); ++i) raw_events.push_back(item.events[i]);
    }
  }
  if (raw_encoding != api::EVENT_ENCODING_UNSPECIFIED) {
    std::unique_ptr<EventStreamDecoder> reference;
    if (raw_encoding == api::EVENT_ENCODING_EVT3) {
      reference = std::make_unique<Evt3Decoder>(PropheseeDecoderOptions{});
    } else {
      reference = std::make_unique<Evt2Decoder>(PropheseeDecoderOptions{});
    }
    EventBuffer expected;
    // Every accepted packet decoded without a ParseError, so their concatenation must too.
    reference->Decode(reinterpret_cast<const uint8_t*>(raw_bytes.data()), raw_bytes.size(),
                      &expected);
    EVLOC_FUZZ_REQUIRE(expected.size() == raw_events.size());
    // The session's times are the sensor's plus the offset, raised where they went back
    // (PacketDecoder: to the previous event's time, or to the previous packet's end + 1 ns).
    std::optional<int64_t> floor_ns;
    uint64_t adjusted = 0;
    for (size_t b = 0; b < boundaries.size(); ++b) {
      if (boundaries[b].previous_end_t_ns) {
        floor_ns = std::max(floor_ns.value_or(INT64_MIN), *boundaries[b].previous_end_t_ns + 1);
      }
      const size_t end =
          b + 1 < boundaries.size() ? boundaries[b + 1].first_event : raw_events.size();
      for (size_t i = boundaries[b].first_event; i < end; ++i) {
        int64_t t_ns = expected.t_ns[i] + offset_ns;
        if (floor_ns && t_ns < *floor_ns) {
          EVLOC_FUZZ_REQUIRE(*floor_ns - t_ns <= kMaxRawTimeAdjustmentNs);
          t_ns = *floor_ns;
          ++adjusted;
        }
        EVLOC_FUZZ_REQUIRE(raw_events.t_ns[i] == t_ns);
        EVLOC_FUZZ_REQUIRE(raw_events.x[i] == expected.x[i] && raw_events.y[i] == expected.y[i]);
        EVLOC_FUZZ_REQUIRE(raw_events.polarity[i] == expected.polarity[i]);
        floor_ns = t_ns;
      }
    }
    EVLOC_FUZZ_REQUIRE(adjusted == validator.decoder().raw_time_adjustments());
  }
  return 0;
}

}  // namespace
}  // namespace evloc::service::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return evloc::service::fuzz::Run(data, size);
}
