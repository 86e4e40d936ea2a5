// Event Camera Dataset text events: one `t x y p` per line, t in seconds (decimal), x and y
// pixel coordinates, p in {0, 1} (0 = OFF). Lines starting with '#' and blank lines are skipped.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <istream>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "core/events/event.h"
#include "core/events/event_reader.h"
#include "core/events/output_file.h"

namespace evloc {

// Parses a decimal, non-negative number of seconds ("12.345678901") to nanoseconds exactly
// (no floating point); more than 9 decimals round to the nearest nanosecond, ties up. Returns
// nullopt for anything else (signs, exponents, empty, above 9e9 s).
std::optional<int64_t> ParseSecondsToNanoseconds(std::string_view text);

// Reads ECD text events from a stream in blocks, never holding the whole file.
class EcdTextReader final : public EventReader {
 public:
  // Opens `path`. Throws IoError when it cannot. `sensor_size`, when given, is reported by
  // sensor_size() and every event must lie inside it (else ParseError).
  explicit EcdTextReader(const std::filesystem::path& path,
                         std::optional<SensorSize> sensor_size = std::nullopt);
  // Reads from `stream`; `source` names it in error messages.
  EcdTextReader(std::unique_ptr<std::istream> stream, std::string source,
                std::optional<SensorSize> sensor_size = std::nullopt);

  // Throws ParseError naming the line for a malformed line.
  size_t Read(size_t max_events, EventBuffer* out) override;
  std::optional<SensorSize> sensor_size() const override { return sensor_size_; }

 private:
  // Sets `line` to the next line (without its '\n'); false at the end.
  bool NextLine(std::string_view* line);
  void ParseLine(std::string_view line, EventBuffer* out);

  std::unique_ptr<std::istream> stream_;
  std::string source_;
  std::optional<SensorSize> sensor_size_;
  std::string buffer_;
  size_t position_ = 0;
  bool end_of_stream_ = false;
  int64_t line_number_ = 0;
};

// Writes ECD text events (`%.9f`-style seconds, exact) to a temporary file, renamed into place
// by Close(); destroying the writer without Close() removes the temporary file.
class EcdTextWriter {
 public:
  // Throws IoError when the file cannot be created.
  explicit EcdTextWriter(const std::filesystem::path& path);

  // Appends events. Throws InvalidArgumentError for negative times or a polarity other than
  // +1/-1 (nothing of that call is written).
  void Write(const EventBuffer& events);
  // Flushes and renames the file into place. Throws IoError.
  void Close();

 private:
  TemporaryOutputFile file_;
  std::string text_;
  bool closed_ = false;
};

}  // namespace evloc
