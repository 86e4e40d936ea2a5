#include "core/events/event_reader.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <fstream>

#include "core/common/error.h"
#include "core/events/aedat4.h"
#include "core/events/dsec_hdf5.h"
#include "core/events/ecd_text.h"
#include "core/events/evb.h"
#include "core/events/prophesee_raw.h"
#include "core/events/rosbag_events.h"

namespace evloc {

size_t BufferEventReader::Read(size_t max_events, EventBuffer* out) {
  const size_t count = std::min(max_events, events_.size() - next_);
  out->Append(events_, next_, count);
  next_ += count;
  return count;
}

void PacketEventReader::DecodeFirstPacket() {
  if (!DecodeNextPacket(&pending_)) ended_ = true;
}

size_t PacketEventReader::Read(size_t max_events, EventBuffer* out) {
  size_t appended = 0;
  while (appended < max_events) {
    const size_t room = max_events - appended;
    if (pending_position_ < pending_.size()) {
      const size_t take = std::min(room, pending_.size() - pending_position_);
      out->Append(pending_, pending_position_, take);
      pending_position_ += take;
      appended += take;
      continue;
    }
    if (ended_) break;
    // Decode the next packet straight into `out` (no copy through pending_); the events beyond
    // `max_events` wait in pending_ for the next call.
    const size_t base = out->size();
    if (!DecodeNextPacket(out)) {
      ended_ = true;
      break;
    }
    const size_t decoded = out->size() - base;
    if (decoded > room) {
      pending_.clear();
      pending_.Append(*out, base + room, decoded - room);
      pending_position_ = 0;
      out->t_ns.resize(base + room);
      out->x.resize(base + room);
      out->y.resize(base + room);
      out->polarity.resize(base + room);
    }
    appended += std::min(decoded, room);
  }
  return appended;
}

const char* EventFileFormatName(EventFileFormat format) {
  switch (format) {
    case EventFileFormat::kEcdText:
      return "ECD text";
    case EventFileFormat::kPropheseeRaw:
      return "Prophesee .raw";
    case EventFileFormat::kDsecHdf5:
      return "DSEC HDF5";
    case EventFileFormat::kEvb:
      return "evloc .evb";
    case EventFileFormat::kRosbag:
      return "ROS1 bag";
    case EventFileFormat::kAedat4:
      return "AEDAT4";
  }
  return "unknown";
}

EventFileFormat DetectEventFileFormat(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw IoError(path.string() + ": cannot open");
  char start[14] = {0};
  file.read(start, sizeof(start));
  const auto size = static_cast<size_t>(file.gcount());
  if (size == 14 && std::memcmp(start, "#!AER-DAT4.0\r\n", 14) == 0) {
    return EventFileFormat::kAedat4;
  }
  if (size >= 8 && std::memcmp(start, "EVLOCEVB", 8) == 0) return EventFileFormat::kEvb;
  if (size >= 8 && std::memcmp(start, "\x89HDF\r\n\x1a\n", 8) == 0) {
    return EventFileFormat::kDsecHdf5;
  }
  if (size >= 8 && std::memcmp(start, "#ROSBAG ", 8) == 0) return EventFileFormat::kRosbag;
  if (size >= 2 && start[0] == '%' && start[1] == ' ') return EventFileFormat::kPropheseeRaw;
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (extension == ".raw") return EventFileFormat::kPropheseeRaw;
  if (extension == ".h5" || extension == ".hdf5") return EventFileFormat::kDsecHdf5;
  if (extension == ".evb") return EventFileFormat::kEvb;
  if (extension == ".bag") return EventFileFormat::kRosbag;
  if (extension == ".aedat4") return EventFileFormat::kAedat4;
  // ECD text: a digit, '#' or blank line first.
  if (extension == ".txt" ||
      (size > 0 && (std::isdigit(static_cast<unsigned char>(start[0])) || start[0] == '#'))) {
    return EventFileFormat::kEcdText;
  }
  throw ParseError::AtByte(path.string(), 0,
                           "unknown event file format (evloc reads .evb, Prophesee .raw with a "
                           "'% ' header, DSEC HDF5 .h5, ROS1 bags, AEDAT4 and ECD text 't x y p')");
}

std::unique_ptr<EventReader> OpenEventFile(const std::filesystem::path& path) {
  switch (DetectEventFileFormat(path)) {
    case EventFileFormat::kEcdText:
      return std::make_unique<EcdTextReader>(path);
    case EventFileFormat::kPropheseeRaw:
      return std::make_unique<PropheseeRawReader>(path);
    case EventFileFormat::kDsecHdf5:
      return std::make_unique<DsecHdf5Reader>(path);
    case EventFileFormat::kEvb:
      return std::make_unique<EvbReader>(path);
    case EventFileFormat::kRosbag:
      return std::make_unique<RosbagEventReader>(path);
    case EventFileFormat::kAedat4:
      return std::make_unique<Aedat4EventReader>(path);
  }
  throw InvalidArgumentError("OpenEventFile: unhandled format");
}

}  // namespace evloc
