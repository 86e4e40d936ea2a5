// libFuzzer target of the ROS node's message input (docs/reliability.md): the fields of a
// dvs_msgs/EventArray, an event_camera_msgs/EventPacket or a sensor_msgs/CameraInfo (byte 0 picks
// which), taken from the bytes as a publisher could set them, go through the node's conversions
// (localizer_node.h) into NodeCore, which must accept each message or reject it with evloc's
// typed errors (what the node logs and skips), never crash. roscpp's own deserialization of the
// wire bytes is not fuzzed here: it is Debian's roscpp, before the node's code.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "ros/localizer_node.h"

namespace {

// Reads little-endian fields off the input; zeros past its end.
class Fields {
 public:
  Fields(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  template <typename T>
  T Take() {
    T value{};
    const size_t count = std::min(sizeof(T), size_ - offset_);
    std::memcpy(&value, data_ + offset_, count);
    offset_ += count;
    return value;
  }
  const uint8_t* rest() const { return data_ + offset_; }
  size_t remaining() const { return size_ - offset_; }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t offset_ = 0;
};

// A node on a small map, started without a pose (searching): events reach the tracker once a
// camera info was accepted.
evloc::ros_node::NodeCore& Core() {
  static std::unique_ptr<evloc::ros_node::NodeCore> core;
  if (!core) {
    evloc::ros_node::NodeCoreOptions options;
    options.map_path = EVLOC_FUZZ_MAP;
    options.init_pose = "none";
    // Short jumps: each input runs at most 0.05 s * 300 Hz = 15 steps.
    options.max_gap_s = 0.05;
    core = std::make_unique<evloc::ros_node::NodeCore>(options);
  }
  return *core;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1 || size > (1 << 16)) return 0;
  evloc::ros_node::NodeCore& core = Core();
  Fields fields(data + 1, size - 1);
  try {
    switch (data[0] % 3) {
      case 0: {
        dvs_msgs::EventArray message;
        message.width = fields.Take<uint16_t>();
        message.height = fields.Take<uint16_t>();
        while (fields.remaining() >= 13) {
          dvs_msgs::Event event;
          event.x = fields.Take<uint16_t>();
          event.y = fields.Take<uint16_t>();
          event.ts.sec = fields.Take<uint32_t>();
          event.ts.nsec = fields.Take<uint32_t>() % 1000000000u;
          event.polarity = fields.Take<uint8_t>() & 1;
          message.events.push_back(event);
        }
        core.AddEventArray(message.width, message.height, evloc::ros_node::ToColumns(message));
        break;
      }
      case 1: {
        event_camera_msgs::EventPacket message;
        message.width = fields.Take<uint16_t>();
        message.height = fields.Take<uint16_t>();
        message.header.stamp.sec = fields.Take<uint32_t>();
        message.header.stamp.nsec = fields.Take<uint32_t>() % 1000000000u;
        const uint8_t flags = fields.Take<uint8_t>();
        static const char* const kEncodings[] = {"mono", "evt3", "evt2", ""};
        message.encoding = kEncodings[flags % 4];
        message.is_bigendian = (flags & 0x80) != 0;
        message.events.assign(fields.rest(), fields.rest() + fields.remaining());
        core.AddEventPacket(message.width, message.height,
                            evloc::ros_node::ToNanoseconds(message.header.stamp), message.encoding,
                            message.is_bigendian != 0, message.events.data(),
                            message.events.size());
        break;
      }
      default: {
        sensor_msgs::CameraInfo message;
        message.width = fields.Take<uint16_t>();
        message.height = fields.Take<uint16_t>();
        const uint8_t model = fields.Take<uint8_t>();
        static const char* const kModels[] = {"plumb_bob", "equidistant", "radtan",
                                              "rational_polynomial"};
        message.distortion_model = kModels[model % 4];
        message.D.resize((model >> 2) % 9);
        for (double& value : message.D) value = fields.Take<double>();
        for (double& value : message.K) value = fields.Take<double>();
        std::vector<evloc::ros_node::StepOutput> steps;
        core.SetCameraInfo(evloc::ros_node::ToFields(message), &steps);
        break;
      }
    }
  } catch (const evloc::Error&) {
    // A rejected message: the node logs it and goes on.
  }
  // The counters stay consistent.
  static uint64_t events_before = 0;
  const evloc::ros_node::NodeCounters& counters = core.counters();
  if (counters.events < events_before || counters.rejected_messages > counters.messages) abort();
  events_before = counters.events;
  return 0;
}
