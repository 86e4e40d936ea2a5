// Events from ROS1 bags: dvs_msgs/EventArray, prophesee_event_msgs/EventArray and
// event_camera_msgs/EventPacket (EVT 3.0 and mono encodings), decoded from their ROS
// serialization (docs/event-formats.md, section 7).
#pragma once

#include <cstdint>
#include <filesystem>
#include <istream>
#include <memory>
#include <optional>
#include <string>

#include "core/events/event_reader.h"
#include "core/events/prophesee_decoder.h"
#include "core/events/rosbag.h"

namespace evloc {

// The default events topic (rpg_dvs_ros, the Event Camera Dataset).
inline constexpr char kDefaultRosbagEventsTopic[] = "/dvs/events";

// True when `type` is a message type RosbagEventReader decodes.
bool IsRosbagEventType(const std::string& type);

// Options of the bag event reader.
struct RosbagEventOptions {
  // The topic whose messages hold the events.
  std::string topic = kDefaultRosbagEventsTopic;

  // Throws InvalidArgumentError when the topic is empty.
  void Check() const;
};

// True for the event_camera_msgs/EventPacket encodings evloc decodes: "mono" and "evt3".
bool IsEventPacketEncoding(const std::string& encoding);

// Decodes the `size` bytes of an event_camera_msgs/EventPacket's `events` field (little-endian) in
// `encoding` and appends them to `out` (the one decoder of the bag reader and the ROS node):
// "mono" (64-bit words, times in ns after `stamp_ns`, the header stamp) or "evt3" through `*evt3`
// (created on first use, named `source` in its errors; one per stream: its time base carries over
// between packets). Events outside `sensor_size` (when set) are dropped and counted in
// `*dropped`. Throws InvalidArgumentError for another encoding or a mono payload that is not
// whole words, ParseError for a malformed EVT 3.0 payload.
void DecodeEventPacketEvents(const std::string& encoding, int64_t stamp_ns, const uint8_t* data,
                             size_t size, const std::optional<SensorSize>& sensor_size,
                             const std::string& source, EventBuffer* out, uint64_t* dropped,
                             std::unique_ptr<Evt3Decoder>* evt3);

// Decodes the events of one message (any of the supported types) and appends them to `out`.
// `sensor_size` receives the message's width and height when both are non-zero. Events outside
// that size are dropped and counted in `*dropped`. EventPacket EVT 3.0 payloads go through
// `evt3` (one decoder per stream: its time base carries over between messages).
// Throws ParseError naming the message's byte position and the field that was expected.
void DecodeRosEventMessage(const RosbagMessage& message, const std::string& source,
                           EventBuffer* out, std::optional<SensorSize>* sensor_size,
                           uint64_t* dropped, std::unique_ptr<Evt3Decoder>* evt3);

// Streams the events of one topic of a bag, message by message.
class RosbagEventReader final : public PacketEventReader {
 public:
  // Opens the bag. Throws IoError / ParseError for the file, InvalidArgumentError when the topic
  // is missing (the message lists the bag's topics) or its type is not an event type.
  RosbagEventReader(const std::filesystem::path& path, const RosbagEventOptions& options = {});
  // Reads from a seekable stream; `source` names it in errors.
  RosbagEventReader(std::unique_ptr<std::istream> stream, std::string source,
                    const RosbagEventOptions& options = {});

  // The width and height of the first message (dvs_msgs and prophesee_event_msgs state them).
  std::optional<SensorSize> sensor_size() const override { return sensor_size_; }
  uint64_t dropped_event_count() const override { return dropped_; }

  // The bag underneath (topics, connections).
  const RosbagReader& bag() const { return *bag_; }
  // Messages decoded so far.
  uint64_t messages() const { return messages_; }

 private:
  void Initialise(const RosbagEventOptions& options);
  // Appends the next message's events to `out`; false at the end.
  bool DecodeNextPacket(EventBuffer* out) override;

  std::unique_ptr<RosbagReader> bag_;
  std::optional<SensorSize> sensor_size_;
  std::unique_ptr<Evt3Decoder> evt3_;
  uint64_t dropped_ = 0;
  uint64_t messages_ = 0;
};

}  // namespace evloc
