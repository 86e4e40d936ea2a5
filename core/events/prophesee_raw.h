// Prophesee .raw files: `% key value` header lines, then an EVT 2.0 or EVT 3.0 payload
// (docs/event-formats.md).
#pragma once

#include <cstdint>
#include <filesystem>
#include <istream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/events/event_reader.h"
#include "core/events/prophesee_decoder.h"

namespace evloc {

// The payload encodings evloc decodes.
enum class PropheseeEncoding { kEvt2, kEvt3 };

// What a .raw header says.
struct PropheseeRawHeader {
  // Every `% key value` line, in file order (keys may repeat).
  std::vector<std::pair<std::string, std::string>> fields;
  // From `% evt 2.0|3.0` or `% format EVT2|EVT3;...`.
  PropheseeEncoding encoding = PropheseeEncoding::kEvt3;
  // From `% format ...;width=W;height=H`, else `% geometry WxH`, else inferred from the sensor
  // generation in `plugin_name` / `sensor_generation` (docs/event-formats.md); nullopt if none.
  std::optional<SensorSize> sensor_size;
  // True when sensor_size was inferred from the sensor generation, not stated.
  bool sensor_size_inferred = false;
  // Length of the header in bytes; the payload starts here.
  uint64_t size_bytes = 0;
};

// Reads and interprets the header at the start of `stream`, leaving it at the payload. Throws
// ParseError when the header names no supported encoding.
PropheseeRawHeader ReadPropheseeRawHeader(std::istream& stream, const std::string& source);

// Streams the events of a .raw file through the decoder its header names.
class PropheseeRawReader final : public EventReader {
 public:
  // Opens `path`. Throws IoError when it cannot, ParseError for a bad header.
  explicit PropheseeRawReader(const std::filesystem::path& path);
  // Reads from `stream`; `source` names it in error messages.
  PropheseeRawReader(std::unique_ptr<std::istream> stream, std::string source);

  // Throws ParseError at the byte offset of malformed words or of a truncated last word.
  size_t Read(size_t max_events, EventBuffer* out) override;
  std::optional<SensorSize> sensor_size() const override { return header_.sensor_size; }
  uint64_t dropped_event_count() const override;

  // The parsed header.
  const PropheseeRawHeader& header() const { return header_; }
  // The decoder's counters.
  const DecoderStatistics& statistics() const { return decoder_->statistics(); }

 private:
  void Initialise();

  std::unique_ptr<std::istream> stream_;
  std::string source_;
  PropheseeRawHeader header_;
  std::unique_ptr<EventStreamDecoder> decoder_;
  std::vector<uint8_t> block_;
  EventBuffer pending_;
  size_t pending_position_ = 0;
  bool end_of_stream_ = false;
};

}  // namespace evloc
