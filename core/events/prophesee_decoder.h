// Streaming decoders for the Prophesee EVT 2.0 and EVT 3.0 raw event encodings
// (docs/event-formats.md). They accept byte chunks of any size, keep partial words and the time
// base across calls, and can therefore be fed raw camera packets as they arrive.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "core/events/event.h"

namespace evloc {

// Counters a decoder keeps from construction (or the last Reset()). Nothing is dropped silently:
// every word and every event that does not reach the output is counted here.
struct DecoderStatistics {
  // Bytes consumed, including a trailing partial word held for the next call.
  uint64_t bytes = 0;
  // Change-detection events appended to the output.
  uint64_t events = 0;
  // Events dropped because they lie outside the sensor size.
  uint64_t dropped_outside_sensor = 0;
  // Events dropped because the stream had not yet given their time base (the first
  // EVT_TIME_HIGH) or, in EVT 3.0, their row (EVT_ADDR_Y) or vector base (VECT_BASE_X).
  uint64_t dropped_before_state = 0;
  // EXT_TRIGGER words seen (not part of the output).
  uint64_t trigger_words = 0;
  // OTHERS and CONTINUED words skipped.
  uint64_t skipped_words = 0;
  // Words of a reserved (undefined) type: skipped, and reported by a ParseError.
  uint64_t malformed_words = 0;
  // Wrap-arounds of the sensor's time counter that were unrolled into the 64-bit time.
  uint64_t time_wraps = 0;
  // Time-base updates that went backwards without being a wrap-around (kept as given).
  uint64_t time_regressions = 0;
};

// Options shared by the Prophesee decoders.
struct PropheseeDecoderOptions {
  // Events with x >= width or y >= height are dropped and counted; std::nullopt keeps every
  // event the format can address (up to 2048 x 2048).
  std::optional<SensorSize> sensor_size;
  // Name of the source in error messages (a file name or a stream description).
  std::string source = "event stream";
  // Byte offset of the first byte given to the decoder within `source` (e.g. the length of a
  // file header), so that error positions are offsets in the source.
  uint64_t first_byte_offset = 0;

  // Throws InvalidArgumentError when a field is out of its domain.
  void Check() const;
};

// A stateful decoder from raw bytes to events.
class EventStreamDecoder {
 public:
  virtual ~EventStreamDecoder() = default;
  // Decodes `size` bytes, appending the complete events to `out` (times in ns). A trailing
  // partial word is kept for the next call. Words of a reserved type are skipped and counted;
  // after the whole chunk has been decoded, a ParseError names the source and the cumulative
  // byte offset of the first of them. The decoder stays usable: the next call continues the
  // stream.
  virtual void Decode(const uint8_t* data, size_t size, EventBuffer* out) = 0;
  // Forgets the time base, addresses, partial word and statistics.
  virtual void Reset() = 0;
  // Counters since construction or Reset().
  virtual const DecoderStatistics& statistics() const = 0;
  // True when a partial word is waiting for more bytes (a stream ending here is truncated).
  virtual bool has_partial_word() const = 0;
};

// Prophesee EVT 3.0: 16-bit little-endian words, 24-bit microsecond time unrolled to 64 bits.
class Evt3Decoder final : public EventStreamDecoder {
 public:
  // Throws InvalidArgumentError when `options` are invalid.
  explicit Evt3Decoder(PropheseeDecoderOptions options = {});
  void Decode(const uint8_t* data, size_t size, EventBuffer* out) override;
  void Reset() override;
  const DecoderStatistics& statistics() const override { return statistics_; }
  bool has_partial_word() const override { return has_pending_byte_; }

 private:
  // Decodes whole words starting at stream offset `offset`; records the first malformed word.
  void DecodeWords(const uint8_t* bytes, size_t word_count, uint64_t offset, EventBuffer* out,
                   std::optional<uint64_t>* first_malformed_offset);

  PropheseeDecoderOptions options_;
  uint32_t width_limit_;
  uint32_t height_limit_;
  DecoderStatistics statistics_;
  // Staging storage for decoded events (see the .cc file).
  EventBuffer staging_;
  bool has_pending_byte_ = false;
  uint8_t pending_byte_ = 0;
  bool has_time_high_ = false;
  bool has_y_ = false;
  bool has_vector_base_ = false;
  uint32_t time_high_ = 0;
  uint32_t time_low_ = 0;
  uint64_t time_epoch_ = 0;
  // Time of the previous EVT_TIME_LOW, microseconds (for counting regressions).
  int64_t last_time_us_ = 0;
  // Time given to the next events, nanoseconds.
  int64_t current_t_ns_ = 0;
  uint32_t y_ = 0;
  uint32_t vector_base_x_ = 0;
  int8_t vector_polarity_ = 1;
};

// Prophesee EVT 2.0: 32-bit little-endian words, 34-bit microsecond time unrolled to 64 bits.
class Evt2Decoder final : public EventStreamDecoder {
 public:
  // Throws InvalidArgumentError when `options` are invalid.
  explicit Evt2Decoder(PropheseeDecoderOptions options = {});
  void Decode(const uint8_t* data, size_t size, EventBuffer* out) override;
  void Reset() override;
  const DecoderStatistics& statistics() const override { return statistics_; }
  bool has_partial_word() const override { return pending_size_ > 0; }

 private:
  // Decodes whole words starting at stream offset `offset`; records the first malformed word.
  void DecodeWords(const uint8_t* bytes, size_t word_count, uint64_t offset, EventBuffer* out,
                   std::optional<uint64_t>* first_malformed_offset);

  PropheseeDecoderOptions options_;
  uint32_t width_limit_;
  uint32_t height_limit_;
  DecoderStatistics statistics_;
  // Staging storage for decoded events (see the .cc file).
  EventBuffer staging_;
  uint8_t pending_[4] = {0, 0, 0, 0};
  size_t pending_size_ = 0;
  bool has_time_high_ = false;
  uint32_t time_high_ = 0;
  uint64_t time_epoch_ = 0;
};

}  // namespace evloc
