// libFuzzer target of the ROS node's message input (docs/reliability.md): the bytes are
// deserialized by roscpp into a dvs_msgs/EventArray, an event_camera_msgs/EventPacket or a
// sensor_msgs/CameraInfo (the first byte picks which) and handed to NodeCore, which must accept
// the message or reject it with evloc's typed errors, never crash. Serialized messages are what
// a publisher (or a bag) puts on the wire, so any byte string is a possible input.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include <ros/serialization.h>

#include "core/common/error.h"
#include "ros/localizer_node.h"

namespace {

// A node on a tiny map, started without a pose (searching): every message reaches the tracker.
evloc::ros_node::NodeCore& Core() {
  static std::unique_ptr<evloc::ros_node::NodeCore> core;
  if (!core) {
    evloc::ros_node::NodeCoreOptions options;
    options.map_path = EVLOC_FUZZ_MAP;
    options.init_pose = "none";
    core = std::make_unique<evloc::ros_node::NodeCore>(options);
  }
  return *core;
}

template <typename Message>
bool Deserialize(const uint8_t* data, size_t size, Message* message) {
  try {
    ros::serialization::IStream stream(const_cast<uint8_t*>(data), static_cast<uint32_t>(size));
    ros::serialization::deserialize(stream, *message);
    return true;
  } catch (const ros::Exception&) {
    return false;  // roscpp's own check of the wire format
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1 || size > (1 << 20)) return 0;
  evloc::ros_node::NodeCore& core = Core();
  const uint8_t kind = data[0] % 3;
  ++data;
  --size;
  try {
    if (kind == 0) {
      dvs_msgs::EventArray message;
      if (!Deserialize(data, size, &message)) return 0;
      core.AddEventArray(message.width, message.height, evloc::ros_node::ToColumns(message));
    } else if (kind == 1) {
      event_camera_msgs::EventPacket message;
      if (!Deserialize(data, size, &message)) return 0;
      core.AddEventPacket(message.width, message.height,
                          evloc::ros_node::ToNanoseconds(message.header.stamp), message.encoding,
                          message.is_bigendian != 0, message.events.data(), message.events.size());
    } else {
      sensor_msgs::CameraInfo message;
      if (!Deserialize(data, size, &message)) return 0;
      std::vector<evloc::ros_node::StepOutput> steps;
      core.SetCameraInfo(evloc::ros_node::ToFields(message), &steps);
    }
  } catch (const evloc::Error&) {
    // A rejected message: what the node logs and skips.
  }
  return 0;
}
