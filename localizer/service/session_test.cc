#include "localizer/service/session.h"

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::service {
namespace {

EventBuffer ThreeEvents() {
  EventBuffer events;
  events.push_back({1'000, 3, 4, 1});
  events.push_back({2'000, 319, 239, -1});
  events.push_back({2'000, 0, 0, 1});
  return events;
}

api::EventPacket Packed(const EventBuffer& events, int64_t base, int64_t end) {
  api::EventPacket packet;
  packet.set_encoding(api::EVENT_ENCODING_PACKED);
  packet.set_time_base_ns(base);
  packet.set_end_t_ns(end);
  packet.set_data(EncodePackedEvents(events, 0, events.size(), base));
  return packet;
}

TEST(PacketDecoder, PackedRoundTripAndEmptyWindows) {
  PacketDecoder decoder({320, 240}, 0);
  const EventBuffer events = ThreeEvents();
  EventBuffer decoded;
  decoder.Decode(Packed(events, 500, 2'000), &decoded);
  EXPECT_EQ(decoded, events);
  EXPECT_EQ(decoded.size() * kPackedEventBytes, 24u);
  api::EventPacket empty;
  empty.set_end_t_ns(5'000);
  decoder.Decode(empty, &decoded);
  EXPECT_TRUE(decoded.empty());
  EXPECT_EQ(decoder.end_t_ns(), 5'000);
  EXPECT_EQ(decoder.packets(), 2u);
}

TEST(PacketDecoder, RejectsBadPackets) {
  const EventBuffer events = ThreeEvents();
  {
    PacketDecoder decoder({320, 240}, 0);
    EventBuffer decoded;
    EXPECT_THROW(decoder.Decode(Packed(events, 0, 1'500), &decoded), InvalidArgumentError)
        << "events after the window end";
  }
  {
    PacketDecoder decoder({319, 240}, 0);
    EventBuffer decoded;
    EXPECT_THROW(decoder.Decode(Packed(events, 0, 3'000), &decoded), InvalidArgumentError)
        << "x = 319 on a 319-wide sensor";
  }
  {
    PacketDecoder decoder({320, 240}, 0);
    EventBuffer decoded;
    decoder.Decode(Packed(events, 0, 3'000), &decoded);
    EXPECT_THROW(decoder.Decode(Packed(events, 0, 4'000), &decoded), InvalidArgumentError)
        << "events at or before the previous window's end";
    api::EventPacket earlier;
    earlier.set_end_t_ns(2'999);
    EXPECT_THROW(decoder.Decode(earlier, &decoded), InvalidArgumentError);
  }
  {
    PacketDecoder decoder({320, 240}, 0);
    EventBuffer decoded;
    api::EventPacket packet = Packed(events, 0, 3'000);
    packet.mutable_data()->pop_back();
    EXPECT_THROW(decoder.Decode(packet, &decoded), InvalidArgumentError) << "23 bytes";
    packet.set_encoding(api::EVENT_ENCODING_UNSPECIFIED);
    EXPECT_THROW(decoder.Decode(packet, &decoded), InvalidArgumentError);
  }
  {
    PacketDecoder decoder({320, 240}, 0);
    EventBuffer decoded;
    decoder.Decode(Packed(events, 0, 3'000), &decoded);
    api::EventPacket raw;
    raw.set_encoding(api::EVENT_ENCODING_EVT3);
    raw.set_data(std::string(2, '\0'));
    raw.set_end_t_ns(4'000);
    EXPECT_THROW(decoder.Decode(raw, &decoded), InvalidArgumentError) << "encoding changed";
  }
}

TEST(PacketDecoder, RawEvt3ReservedWordIsInvalid) {
  PacketDecoder decoder({320, 240}, 0);
  EventBuffer decoded;
  api::EventPacket raw;
  raw.set_encoding(api::EVENT_ENCODING_EVT3);
  raw.set_data(std::string("\x00\x10", 2));  // type 0x1: reserved
  raw.set_end_t_ns(1'000);
  EXPECT_THROW(decoder.Decode(raw, &decoded), InvalidArgumentError);
}

TEST(SessionSettings, RejectsInvalidCamerasAndOptions) {
  api::SessionStart start;
  start.mutable_camera()->set_model(map_format::CAMERA_MODEL_PINHOLE);
  start.mutable_camera()->set_width(320);
  start.mutable_camera()->set_height(240);
  start.mutable_camera()->set_fx(250);
  start.mutable_camera()->set_fy(250);
  start.mutable_camera()->set_cx(160);
  start.mutable_camera()->set_cy(120);
  start.mutable_initial_world_from_cam()->mutable_rotation()->set_w(1);
  const tracking::TrackerOptions defaults;
  const SessionSettings settings = SessionSettingsFromProto(start, defaults);
  EXPECT_EQ(settings.camera.width, 320);
  EXPECT_EQ(settings.tracker.step_rate_hz, defaults.step_rate_hz);

  api::SessionStart bad = start;
  bad.mutable_camera()->set_fx(-1);
  EXPECT_THROW(SessionSettingsFromProto(bad, defaults), InvalidArgumentError);
  bad = start;
  bad.mutable_camera()->set_model(map_format::CAMERA_MODEL_UNSPECIFIED);
  EXPECT_THROW(SessionSettingsFromProto(bad, defaults), InvalidArgumentError);
  bad = start;
  bad.mutable_initial_world_from_cam()->mutable_rotation()->set_w(2);
  EXPECT_THROW(SessionSettingsFromProto(bad, defaults), InvalidArgumentError);
  bad = start;
  bad.mutable_options()->set_variant("EVT-XY");
  EXPECT_THROW(SessionSettingsFromProto(bad, defaults), InvalidArgumentError);
  bad = start;
  bad.mutable_options()->set_step_rate_hz(-5);
  EXPECT_THROW(SessionSettingsFromProto(bad, defaults), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::service
