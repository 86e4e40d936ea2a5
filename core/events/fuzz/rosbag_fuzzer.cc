// libFuzzer target: the ROS1 bag reader (records, chunks with none / bz2 / lz4 compression,
// connections, the index) and the event message decoders of every topic
// (docs/reliability.md). Seeds: bags written by core/events/testing/write_test_bags.py.
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include "core/common/error.h"
#include "core/events/rosbag.h"
#include "core/events/rosbag_events.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  try {
    evloc::RosbagReader bag(std::make_unique<std::istringstream>(bytes), "fuzz.bag");
    evloc::RosbagMessage message;
    evloc::EventBuffer events;
    std::optional<evloc::SensorSize> sensor_size;
    uint64_t dropped = 0;
    std::unique_ptr<evloc::Evt3Decoder> evt3;
    while (bag.Next(&message)) {
      if (message.size > bytes.size()) std::abort();
      if (!evloc::IsRosbagEventType(message.connection->type)) continue;
      try {
        const size_t before = events.size();
        std::optional<evloc::SensorSize> message_size;
        evloc::DecodeRosEventMessage(message, "fuzz.bag", &events, &message_size, &dropped, &evt3);
        if (!events.IsConsistent()) std::abort();
        if (message_size && message.connection->type != "event_camera_msgs/EventPacket") {
          for (size_t i = before; i < events.size(); ++i) {
            if (!message_size->Contains(events.x[i], events.y[i])) std::abort();
          }
        }
        if (!sensor_size) sensor_size = message_size;
      } catch (const evloc::ParseError&) {
      }
      events.clear();
    }
  } catch (const evloc::ParseError&) {
  }
  return 0;
}
