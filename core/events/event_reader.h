// Streaming readers of event files and the format dispatcher (docs/event-formats.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "core/events/event.h"

namespace evloc {

// Reads the events of a file (or stream) in order, a bounded number at a time: no reader ever
// holds the whole file in memory.
class EventReader {
 public:
  virtual ~EventReader() = default;
  // Appends up to `max_events` events to `out` and returns how many; 0 only at the end.
  // Throws ParseError (naming the source and the line or byte offset) on malformed content and
  // IoError when the underlying file fails.
  virtual size_t Read(size_t max_events, EventBuffer* out) = 0;
  // The sensor size when the format records it (or the reader could infer it), else nullopt.
  virtual std::optional<SensorSize> sensor_size() const = 0;
  // Events present in the source but not returned (outside the sensor, or before the stream
  // gave their time base); 0 for formats that never drop. See docs/event-formats.md.
  virtual uint64_t dropped_event_count() const { return 0; }
};

// Serves events already in memory (kept by reference) through the EventReader interface: for
// in-process callers and tests of code that reads an EventReader.
class BufferEventReader final : public EventReader {
 public:
  // Reads `events`, which must outlive the reader.
  explicit BufferEventReader(const EventBuffer& events) : events_(events) {}
  // Appends up to `max_events` events to `out`; 0 at the end.
  size_t Read(size_t max_events, EventBuffer* out) override;
  // Unknown: the buffer has no sensor size.
  std::optional<SensorSize> sensor_size() const override { return std::nullopt; }

 private:
  const EventBuffer& events_;
  size_t next_ = 0;
};

// An EventReader over a source that decodes whole packets at a time (the messages of a ROS1 bag,
// the packets of an AEDAT4 file): Read() decodes the next packet straight into the caller's
// buffer and keeps the events beyond `max_events` for the next call, so at most one packet's
// events are held between calls.
class PacketEventReader : public EventReader {
 public:
  size_t Read(size_t max_events, EventBuffer* out) final;

 protected:
  // Appends the next packet's events to `out`; false at the end.
  virtual bool DecodeNextPacket(EventBuffer* out) = 0;
  // Decodes the first packet now (readers whose sensor size comes with it call this from their
  // constructor, after which Read() starts with that packet's events).
  void DecodeFirstPacket();

 private:
  EventBuffer pending_;
  size_t pending_position_ = 0;
  bool ended_ = false;
};

// The event file formats evloc reads.
enum class EventFileFormat {
  // Event Camera Dataset text, `t[s] x y p` per line.
  kEcdText,
  // Prophesee .raw with a `% ...` header, EVT 2.0 or EVT 3.0 payload.
  kPropheseeRaw,
  // DSEC-style HDF5: /events/{x,y,p,t}, /t_offset.
  kDsecHdf5,
  // evloc's compact binary format (.evb).
  kEvb,
  // ROS1 bag (format 2.0) with event messages on /dvs/events (see rosbag_events.h).
  kRosbag,
  // iniVation DV AEDAT 4.0 with an events stream named "events" (see aedat4.h).
  kAedat4,
};

// Human-readable name of a format ("ECD text", ...).
const char* EventFileFormatName(EventFileFormat format);

// Detects the format of `path` from its first bytes, falling back to the extension for text.
// Throws IoError when the file cannot be read and ParseError (at byte 0) for unknown content.
EventFileFormat DetectEventFileFormat(const std::filesystem::path& path);

// Opens `path` with the reader of its detected format.
std::unique_ptr<EventReader> OpenEventFile(const std::filesystem::path& path);

}  // namespace evloc
