// evloc's compact binary event format, .evb: a header with the sensor size, then CRC-checked
// chunks of 8-byte events relative to a per-chunk base time, then an end record. Byte layout in
// docs/event-formats.md.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <istream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/events/event.h"
#include "core/events/event_reader.h"
#include "core/events/output_file.h"

namespace evloc {

// Options of EvbWriter.
struct EvbWriterOptions {
  // Largest number of events per chunk (1..1,048,576); a chunk is also closed early when an
  // event lies more than 2^31 - 1 ns after, or before, the chunk's first event.
  int max_events_per_chunk = 65536;

  // Throws InvalidArgumentError when a field is out of its domain.
  void Check() const;
};

// Writes a .evb file under a temporary name; Close() completes and renames it. Destroying the
// writer without Close() removes the temporary file, so a failed run leaves no partial file.
class EvbWriter {
 public:
  // `sensor_size` is recorded in the header (nullopt: unknown) and every event must lie inside
  // it. Throws IoError when the file cannot be created, InvalidArgumentError on bad options.
  explicit EvbWriter(const std::filesystem::path& path,
                     std::optional<SensorSize> sensor_size = std::nullopt,
                     EvbWriterOptions options = {});
  EvbWriter(const EvbWriter&) = delete;
  EvbWriter& operator=(const EvbWriter&) = delete;

  // Appends events. Throws InvalidArgumentError for an event outside the sensor or with a
  // polarity other than +1/-1 (nothing of that call is written), IoError on write failure.
  void Write(const EventBuffer& events);
  // Appends one event.
  void Write(const Event& event);
  // Writes the last chunk and the end record and renames the file into place. Throws IoError.
  void Close();
  // Events written so far.
  uint64_t event_count() const { return event_count_; }

 private:
  void FlushChunk();

  EvbWriterOptions options_;
  std::optional<SensorSize> sensor_size_;
  TemporaryOutputFile file_;
  EventBuffer chunk_;
  std::vector<uint8_t> bytes_;
  uint64_t event_count_ = 0;
  bool closed_ = false;
};

// Reads a .evb file or stream chunk by chunk, verifying every CRC.
class EvbReader final : public EventReader {
 public:
  // Opens `path`. Throws IoError when it cannot be opened, ParseError for a bad header.
  explicit EvbReader(const std::filesystem::path& path);
  // Reads from `stream`; `source` names it in error messages.
  EvbReader(std::unique_ptr<std::istream> stream, std::string source);

  size_t Read(size_t max_events, EventBuffer* out) override;
  std::optional<SensorSize> sensor_size() const override { return sensor_size_; }

 private:
  void ReadHeader();
  // Reads the next chunk into chunk_; returns false at the end record.
  bool ReadChunk();

  std::unique_ptr<std::istream> stream_;
  std::string source_;
  std::optional<SensorSize> sensor_size_;
  uint64_t offset_ = 0;
  uint64_t events_read_ = 0;
  EventBuffer chunk_;
  size_t chunk_position_ = 0;
  bool finished_ = false;
};

}  // namespace evloc
