#include "core/events/rosbag_events.h"

#include <algorithm>
#include <cstring>

#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc {
namespace {

constexpr char kDvsEventArray[] = "dvs_msgs/EventArray";
constexpr char kPropheseeEventArray[] = "prophesee_event_msgs/EventArray";
constexpr char kEventPacket[] = "event_camera_msgs/EventPacket";
// dvs_msgs/Event and prophesee_event_msgs/Event: uint16 x, uint16 y, time ts, bool polarity.
constexpr size_t kDvsEventBytes = 13;

// Appends the 13-byte events of a dvs_msgs or prophesee_event_msgs EventArray.
void DecodeEventArray(RosMessageCursor* cursor, EventBuffer* out,
                      std::optional<SensorSize>* sensor_size, uint64_t* dropped) {
  cursor->Header();
  const uint32_t height = cursor->U32("height");
  const uint32_t width = cursor->U32("width");
  const uint32_t count = cursor->ArrayLength("events", kDvsEventBytes);
  if (width > 65535 || height > 65535) {
    cursor->Fail("expected a width and height of at most 65535, found " + std::to_string(width) +
                 "x" + std::to_string(height));
  }
  const bool bounded = width > 0 && height > 0;
  if (bounded && !*sensor_size) {
    *sensor_size = SensorSize{static_cast<int>(width), static_cast<int>(height)};
  }
  const uint8_t* p = cursor->here();
  const size_t base = out->size();
  out->t_ns.resize(base + count);
  out->x.resize(base + count);
  out->y.resize(base + count);
  out->polarity.resize(base + count);
  int64_t* t = out->t_ns.data() + base;
  uint16_t* xs = out->x.data() + base;
  uint16_t* ys = out->y.data() + base;
  int8_t* ps = out->polarity.data() + base;
  size_t kept = 0;
  for (uint32_t i = 0; i < count; ++i, p += kDvsEventBytes) {
    uint16_t x;
    uint16_t y;
    uint32_t seconds;
    uint32_t nanoseconds;
    std::memcpy(&x, p, 2);
    std::memcpy(&y, p + 2, 2);
    std::memcpy(&seconds, p + 4, 4);
    std::memcpy(&nanoseconds, p + 8, 4);
    if (bounded && (x >= width || y >= height)) {
      ++*dropped;
      continue;
    }
    t[kept] = static_cast<int64_t>(seconds) * 1000000000 + nanoseconds;
    xs[kept] = x;
    ys[kept] = y;
    ps[kept] = p[12] != 0 ? 1 : -1;
    ++kept;
  }
  cursor->Skip(static_cast<size_t>(count) * kDvsEventBytes);
  out->t_ns.resize(base + kept);
  out->x.resize(base + kept);
  out->y.resize(base + kept);
  out->polarity.resize(base + kept);
}

void DecodeEventPacket(const RosbagMessage& message, RosMessageCursor* cursor,
                       const std::string& source, EventBuffer* out,
                       std::optional<SensorSize>* sensor_size, uint64_t* dropped,
                       std::unique_ptr<Evt3Decoder>* evt3) {
  const int64_t stamp_ns = cursor->Header();
  const uint32_t height = cursor->U32("height");
  const uint32_t width = cursor->U32("width");
  cursor->U64("seq");
  cursor->U64("time_base");
  const size_t encoding_offset = cursor->offset();
  const std::string encoding = cursor->String("encoding");
  const bool big_endian = cursor->U8("is_bigendian") != 0;
  const uint32_t size = cursor->ArrayLength("events", 1);
  if (width > 65535 || height > 65535) {
    cursor->Fail("expected a width and height of at most 65535, found " + std::to_string(width) +
                 "x" + std::to_string(height));
  }
  const bool bounded = width > 0 && height > 0;
  if (bounded && !*sensor_size) {
    *sensor_size = SensorSize{static_cast<int>(width), static_cast<int>(height)};
  }
  if (big_endian) cursor->Fail("big-endian event packets are not supported");
  if (!IsEventPacketEncoding(encoding)) {
    throw ParseError(source, RosbagPosition(message, encoding_offset),
                     std::string(kEventPacket) + " on " + message.connection->topic +
                         ": unsupported encoding '" + encoding + "' (evloc decodes evt3 and mono)");
  }
  try {
    // Mono events are bounded by this packet's size, the EVT 3.0 decoder by the stream's.
    const std::optional<SensorSize> bounds =
        encoding == "mono" ? (bounded ? std::optional<SensorSize>(SensorSize{
                                            static_cast<int>(width), static_cast<int>(height)})
                                      : std::nullopt)
                           : *sensor_size;
    DecodeEventPacketEvents(encoding, stamp_ns, cursor->here(), size, bounds,
                            source + " (" + message.connection->topic + ", EVT 3.0)", out, dropped,
                            evt3);
  } catch (const InvalidArgumentError& error) {
    cursor->Fail(error.what());
  }
  cursor->Skip(size);
}

}  // namespace

bool IsEventPacketEncoding(const std::string& encoding) {
  return encoding == "mono" || encoding == "evt3";
}

void DecodeEventPacketEvents(const std::string& encoding, int64_t stamp_ns, const uint8_t* data,
                             size_t size, const std::optional<SensorSize>& sensor_size,
                             const std::string& source, EventBuffer* out, uint64_t* dropped,
                             std::unique_ptr<Evt3Decoder>* evt3) {
  if (encoding == "mono") {
    // 64-bit little-endian words: [63] polarity, [62:48] y, [47:32] x, [31:0] dt (ns after
    // the header stamp).
    if (size % 8 != 0) {
      throw InvalidArgumentError("mono events: expected a multiple of 8 bytes, found " +
                                 std::to_string(size));
    }
    for (size_t i = 0; i < size / 8; ++i) {
      uint64_t word;
      std::memcpy(&word, data + 8 * i, 8);
      const auto x = static_cast<uint16_t>((word >> 32) & 0xffff);
      const auto y = static_cast<uint16_t>((word >> 48) & 0x7fff);
      if (sensor_size && (x >= sensor_size->width || y >= sensor_size->height)) {
        ++*dropped;
        continue;
      }
      out->push_back({stamp_ns + static_cast<int64_t>(word & 0xffffffffu), x, y,
                      static_cast<int8_t>((word >> 63) != 0 ? 1 : -1)});
    }
  } else if (encoding == "evt3") {
    if (!*evt3) {
      PropheseeDecoderOptions options;
      options.sensor_size = sensor_size;
      options.source = source;
      *evt3 = std::make_unique<Evt3Decoder>(options);
    }
    const uint64_t before =
        (*evt3)->statistics().dropped_outside_sensor + (*evt3)->statistics().dropped_before_state;
    (*evt3)->Decode(data, size, out);
    *dropped += (*evt3)->statistics().dropped_outside_sensor +
                (*evt3)->statistics().dropped_before_state - before;
  } else {
    throw InvalidArgumentError("unsupported encoding '" + encoding +
                               "' (evloc decodes evt3 and mono)");
  }
}

bool IsRosbagEventType(const std::string& type) {
  return type == kDvsEventArray || type == kPropheseeEventArray || type == kEventPacket;
}

void RosbagEventOptions::Check() const {
  if (topic.empty()) throw InvalidArgumentError("The bag events topic must not be empty.");
}

void DecodeRosEventMessage(const RosbagMessage& message, const std::string& source,
                           EventBuffer* out, std::optional<SensorSize>* sensor_size,
                           uint64_t* dropped, std::unique_ptr<Evt3Decoder>* evt3) {
  RosMessageCursor cursor(message, source);
  const std::string& type = message.connection->type;
  if (type == kDvsEventArray || type == kPropheseeEventArray) {
    DecodeEventArray(&cursor, out, sensor_size, dropped);
  } else if (type == kEventPacket) {
    DecodeEventPacket(message, &cursor, source, out, sensor_size, dropped, evt3);
  } else {
    cursor.Fail("not an event message type (evloc decodes " + std::string(kDvsEventArray) + ", " +
                kPropheseeEventArray + " and " + kEventPacket + ")");
  }
}

RosbagEventReader::RosbagEventReader(const std::filesystem::path& path,
                                     const RosbagEventOptions& options)
    : RosbagEventReader(OpenInputFile(path), path.string(), options) {}

RosbagEventReader::RosbagEventReader(std::unique_ptr<std::istream> stream, std::string source,
                                     const RosbagEventOptions& options)
    : bag_(std::make_unique<RosbagReader>(std::move(stream), std::move(source))) {
  Initialise(options);
}

void RosbagEventReader::Initialise(const RosbagEventOptions& options) {
  options.Check();
  const auto connections = bag_->ConnectionsOf(options.topic);
  if (connections.empty()) {
    throw InvalidArgumentError(bag_->source() + " has no topic '" + options.topic +
                               "'; its topics are: " + bag_->DescribeTopics() +
                               " (name the events topic: --events-topic)");
  }
  for (const RosbagConnection* connection : connections) {
    if (!IsRosbagEventType(connection->type)) {
      throw InvalidArgumentError(bag_->source() + ": topic '" + options.topic + "' has type " +
                                 connection->type + ", not an event type (" + kDvsEventArray +
                                 ", " + kPropheseeEventArray + ", " + kEventPacket +
                                 "); its topics are: " + bag_->DescribeTopics());
    }
  }
  bag_->SetTopics({options.topic});
  // The sensor size comes with the first message: decode it now.
  DecodeFirstPacket();
}

bool RosbagEventReader::DecodeNextPacket(EventBuffer* out) {
  RosbagMessage message;
  if (!bag_->Next(&message)) return false;
  ++messages_;
  DecodeRosEventMessage(message, bag_->source(), out, &sensor_size_, &dropped_, &evt3_);
  return true;
}

}  // namespace evloc
