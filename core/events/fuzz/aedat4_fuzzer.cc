// libFuzzer target: the AEDAT4 reader (magic, IOHeader flatbuffer, the infoNode XML and its
// stream table, packet headers, none / LZ4 / Zstd bodies, the flatbuffers verifier, the data
// table) and the decoders of the four packet types (docs/reliability.md). Seeds: files written
// by core/events/testing/write_test_aedat4.py --small.
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include "core/common/error.h"
#include "core/events/aedat4.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  try {
    evloc::Aedat4Reader file(std::make_unique<std::istringstream>(bytes), "fuzz.aedat4");
    evloc::Aedat4Packet packet;
    evloc::EventBuffer events;
    std::vector<evloc::Aedat4ImuSample> imu;
    std::vector<evloc::Aedat4Trigger> triggers;
    uint64_t dropped = 0;
    while (file.Next(&packet)) {
      if (packet.size > evloc::Aedat4Reader::kMaxPacketBytes) std::abort();
      const std::string& type = packet.stream->type;
      try {
        if (type == "EVTS") {
          evloc::DecodeAedat4Events(packet, "fuzz.aedat4", packet.stream->size, &events, &dropped);
          if (!events.IsConsistent()) std::abort();
          for (size_t i = 0; i < events.size(); ++i) {
            if (packet.stream->size && !packet.stream->size->Contains(events.x[i], events.y[i])) {
              std::abort();
            }
          }
        } else if (type == "FRME") {
          const evloc::Aedat4Frame frame = evloc::DecodeAedat4Frame(packet, "fuzz.aedat4");
          if (frame.pixels.size() != static_cast<size_t>(frame.width) * frame.height *
                                         frame.channels * frame.bytes_per_channel) {
            std::abort();
          }
        } else if (type == "IMUS") {
          evloc::DecodeAedat4Imu(packet, "fuzz.aedat4", &imu);
        } else if (type == "TRIG") {
          evloc::DecodeAedat4Triggers(packet, "fuzz.aedat4", &triggers);
        }
      } catch (const evloc::ParseError&) {
      }
      events.clear();
      imu.clear();
      triggers.clear();
    }
  } catch (const evloc::ParseError&) {
  }
  return 0;
}
