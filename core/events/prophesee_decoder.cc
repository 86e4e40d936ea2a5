#include "core/events/prophesee_decoder.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <string>
#include <utility>

#include "core/common/error.h"

namespace evloc {
namespace {

static_assert(std::endian::native == std::endian::little,
              "the Prophesee decoders read little-endian words with memcpy");

// The largest address either format can encode (11-bit coordinates).
constexpr uint32_t kFormatAddressLimit = 2048;

// Coordinates at or above this are outside the sensor: its size along `axis` when known, else the
// format's address range.
uint32_t AddressLimit(const std::optional<SensorSize>& sensor_size, int SensorSize::*axis) {
  return sensor_size ? std::min<uint32_t>((*sensor_size).*axis, kFormatAddressLimit)
                     : kFormatAddressLimit;
}

// Events are decoded into a fixed-size staging buffer (owned by the decoder, allocated once)
// and appended to the output in blocks, so the hot loop writes without capacity checks.
class StagingArea {
 public:
  // Capacity of the staging buffer; Flush() is due when fewer than 12 slots (the most events
  // one word gives) are left.
  static constexpr size_t kCapacity = 4096;
  static constexpr size_t kFlushThreshold = kCapacity - 12;

  // Sizes `storage` to the capacity once and writes into it.
  explicit StagingArea(EventBuffer* storage) {
    if (storage->size() != kCapacity) {
      storage->t_ns.resize(kCapacity);
      storage->x.resize(kCapacity);
      storage->y.resize(kCapacity);
      storage->polarity.resize(kCapacity);
    }
    t_ns_ = storage->t_ns.data();
    x_ = storage->x.data();
    y_ = storage->y.data();
    polarity_ = storage->polarity.data();
  }

  void Emit(int64_t t_ns, uint32_t x, uint32_t y, int8_t polarity) {
    t_ns_[count_] = t_ns;
    x_[count_] = static_cast<uint16_t>(x);
    y_[count_] = static_cast<uint16_t>(y);
    polarity_[count_] = polarity;
    ++count_;
  }
  bool NeedsFlush() const { return count_ >= kFlushThreshold; }
  // Appends the staged events to `out`; returns how many.
  size_t Flush(EventBuffer* out) {
    const size_t flushed = count_;
    out->Append(t_ns_, x_, y_, polarity_, count_);
    count_ = 0;
    return flushed;
  }

 private:
  int64_t* t_ns_;
  uint16_t* x_;
  uint16_t* y_;
  int8_t* polarity_;
  size_t count_ = 0;
};

[[noreturn]] void ThrowMalformed(const PropheseeDecoderOptions& options, uint64_t offset,
                                 const char* format, uint64_t malformed_count) {
  throw ParseError::AtByte(options.source, offset,
                           std::string("word of a reserved ") + format + " type (" +
                               std::to_string(malformed_count) +
                               " malformed word(s) so far); is this really " + format + " data?");
}

}  // namespace

void PropheseeDecoderOptions::Check() const {
  if (sensor_size) sensor_size->Check();
}

// ---------------------------------------------------------------------------------------------
// EVT 3.0

Evt3Decoder::Evt3Decoder(PropheseeDecoderOptions options) : options_(std::move(options)) {
  options_.Check();
  width_limit_ = AddressLimit(options_.sensor_size, &SensorSize::width);
  height_limit_ = AddressLimit(options_.sensor_size, &SensorSize::height);
}

void Evt3Decoder::Reset() { *this = Evt3Decoder(std::move(options_)); }

void Evt3Decoder::Decode(const uint8_t* data, size_t size, EventBuffer* out) {
  if (out == nullptr) throw InvalidArgumentError("Evt3Decoder::Decode: output buffer is null");
  if (size == 0) return;
  if (data == nullptr) throw InvalidArgumentError("Evt3Decoder::Decode: data is null");
  const uint64_t start = options_.first_byte_offset + statistics_.bytes;
  statistics_.bytes += size;
  std::optional<uint64_t> first_malformed_offset;
  size_t consumed = 0;
  if (has_pending_byte_) {
    const uint8_t word[2] = {pending_byte_, data[0]};
    has_pending_byte_ = false;
    consumed = 1;
    DecodeWords(word, 1, start - 1, out, &first_malformed_offset);
  }
  const size_t word_count = (size - consumed) / 2;
  DecodeWords(data + consumed, word_count, start + consumed, out, &first_malformed_offset);
  consumed += 2 * word_count;
  if (consumed < size) {
    pending_byte_ = data[consumed];
    has_pending_byte_ = true;
  }
  if (first_malformed_offset) {
    ThrowMalformed(options_, *first_malformed_offset, "EVT 3.0", statistics_.malformed_words);
  }
}

void Evt3Decoder::DecodeWords(const uint8_t* bytes, size_t word_count, uint64_t offset,
                              EventBuffer* out, std::optional<uint64_t>* first_malformed_offset) {
  StagingArea staging(&staging_);
  // Local copies of the state let the compiler keep it in registers.
  bool has_time_high = has_time_high_;
  bool has_y = has_y_;
  bool has_vector_base = has_vector_base_;
  uint32_t time_high = time_high_;
  uint32_t time_low = time_low_;
  uint64_t time_epoch = time_epoch_;
  int64_t last_time_us = last_time_us_;
  uint32_t y = y_;
  uint32_t vector_base_x = vector_base_x_;
  int8_t vector_polarity = vector_polarity_;
  const uint32_t width_limit = width_limit_;
  const uint32_t height_limit = height_limit_;
  int64_t t_ns = current_t_ns_;
  uint64_t appended = 0;

  // Recomposes the current time; `at_time_low` compares it with the previous EVT_TIME_LOW's time
  // (between an EVT_TIME_HIGH and the next EVT_TIME_LOW the composed time is transient).
  auto update_time = [&](bool at_time_low) {
    const int64_t time_us =
        static_cast<int64_t>((time_epoch << 24) | (uint64_t{time_high} << 12) | time_low);
    if (at_time_low) {
      if (time_us < last_time_us) ++statistics_.time_regressions;
      last_time_us = time_us;
    }
    // Unsigned arithmetic: a hostile stream of billions of wrap-arounds must not be UB.
    t_ns = static_cast<int64_t>(static_cast<uint64_t>(time_us) * 1000u);
  };

  for (size_t i = 0; i < word_count; ++i) {
    uint16_t word;
    std::memcpy(&word, bytes + 2 * i, 2);
    switch (word >> 12) {
      case 0x0:  // EVT_ADDR_Y: [11] system type, [10:0] y.
        y = word & 0x7FF;
        has_y = true;
        break;
      case 0x2: {  // EVT_ADDR_X: [11] polarity, [10:0] x; one event.
        const uint32_t x = word & 0x7FF;
        if (!has_time_high || !has_y) {
          ++statistics_.dropped_before_state;
        } else if (x >= width_limit || y >= height_limit) {
          ++statistics_.dropped_outside_sensor;
        } else {
          staging.Emit(t_ns, x, y, (word & 0x800) ? int8_t{1} : int8_t{-1});
        }
        break;
      }
      case 0x3:  // VECT_BASE_X: [11] polarity, [10:0] base x.
        vector_base_x = word & 0x7FF;
        vector_polarity = (word & 0x800) ? int8_t{1} : int8_t{-1};
        has_vector_base = true;
        break;
      case 0x4:    // VECT_12: [11:0] valid bits for base x + 0..11.
      case 0x5: {  // VECT_8: [7:0] valid bits for base x + 0..7.
        const uint32_t length = (word >> 12) == 0x4 ? 12 : 8;
        uint32_t valid = word & ((1u << length) - 1);
        if (!has_time_high || !has_y || !has_vector_base) {
          statistics_.dropped_before_state += std::popcount(valid);
        } else if (y >= height_limit) {
          statistics_.dropped_outside_sensor += std::popcount(valid);
        } else if (vector_base_x + length <= width_limit) {
          while (valid != 0) {
            staging.Emit(t_ns, vector_base_x + std::countr_zero(valid), y, vector_polarity);
            valid &= valid - 1;
          }
        } else {
          while (valid != 0) {
            const uint32_t x = vector_base_x + std::countr_zero(valid);
            if (x < width_limit) {
              staging.Emit(t_ns, x, y, vector_polarity);
            } else {
              ++statistics_.dropped_outside_sensor;
            }
            valid &= valid - 1;
          }
        }
        // The base advances even past the format's range; such events are out of the sensor.
        if (has_vector_base && vector_base_x < (1u << 20)) vector_base_x += length;
        break;
      }
      case 0x6:  // EVT_TIME_LOW: [11:0] lower 12 bits of the 24-bit time.
        time_low = word & 0xFFF;
        if (has_time_high) update_time(/*at_time_low=*/true);
        break;
      case 0x8: {  // EVT_TIME_HIGH: [11:0] upper 12 bits of the 24-bit time.
        const uint32_t new_time_high = word & 0xFFF;
        if (has_time_high && new_time_high < time_high) {
          // A jump back by at least half the range is the 24-bit counter wrapping around.
          if (time_high - new_time_high >= 2048) {
            ++time_epoch;
            ++statistics_.time_wraps;
          } else {
            ++statistics_.time_regressions;
          }
        }
        time_high = new_time_high;
        has_time_high = true;
        update_time(/*at_time_low=*/false);
        break;
      }
      case 0xA:  // EXT_TRIGGER.
        ++statistics_.trigger_words;
        break;
      case 0x7:  // CONTINUED_4.
      case 0xE:  // OTHERS.
      case 0xF:  // CONTINUED_12.
        ++statistics_.skipped_words;
        break;
      default:  // Reserved types 0x1, 0x9, 0xB, 0xC, 0xD.
        ++statistics_.malformed_words;
        if (!*first_malformed_offset) *first_malformed_offset = offset + 2 * i;
        break;
    }
    if (staging.NeedsFlush()) appended += staging.Flush(out);
  }
  appended += staging.Flush(out);
  statistics_.events += appended;

  has_time_high_ = has_time_high;
  has_y_ = has_y;
  has_vector_base_ = has_vector_base;
  time_high_ = time_high;
  time_low_ = time_low;
  time_epoch_ = time_epoch;
  last_time_us_ = last_time_us;
  current_t_ns_ = t_ns;
  y_ = y;
  vector_base_x_ = vector_base_x;
  vector_polarity_ = vector_polarity;
}

// ---------------------------------------------------------------------------------------------
// EVT 2.0

Evt2Decoder::Evt2Decoder(PropheseeDecoderOptions options) : options_(std::move(options)) {
  options_.Check();
  width_limit_ = AddressLimit(options_.sensor_size, &SensorSize::width);
  height_limit_ = AddressLimit(options_.sensor_size, &SensorSize::height);
}

void Evt2Decoder::Reset() { *this = Evt2Decoder(std::move(options_)); }

void Evt2Decoder::Decode(const uint8_t* data, size_t size, EventBuffer* out) {
  if (out == nullptr) throw InvalidArgumentError("Evt2Decoder::Decode: output buffer is null");
  if (size == 0) return;
  if (data == nullptr) throw InvalidArgumentError("Evt2Decoder::Decode: data is null");
  const uint64_t start = options_.first_byte_offset + statistics_.bytes;
  statistics_.bytes += size;
  std::optional<uint64_t> first_malformed_offset;
  size_t consumed = 0;
  if (pending_size_ > 0) {
    const size_t missing = 4 - pending_size_;
    const size_t taken = std::min(missing, size);
    std::memcpy(pending_ + pending_size_, data, taken);
    pending_size_ += taken;
    consumed = taken;
    if (pending_size_ < 4) return;
    pending_size_ = 0;
    DecodeWords(pending_, 1, start + taken - 4, out, &first_malformed_offset);
  }
  const size_t word_count = (size - consumed) / 4;
  DecodeWords(data + consumed, word_count, start + consumed, out, &first_malformed_offset);
  consumed += 4 * word_count;
  pending_size_ = size - consumed;
  std::memcpy(pending_, data + consumed, pending_size_);
  if (first_malformed_offset) {
    ThrowMalformed(options_, *first_malformed_offset, "EVT 2.0", statistics_.malformed_words);
  }
}

void Evt2Decoder::DecodeWords(const uint8_t* bytes, size_t word_count, uint64_t offset,
                              EventBuffer* out, std::optional<uint64_t>* first_malformed_offset) {
  StagingArea staging(&staging_);
  bool has_time_high = has_time_high_;
  uint32_t time_high = time_high_;
  uint64_t time_epoch = time_epoch_;
  const uint32_t width_limit = width_limit_;
  const uint32_t height_limit = height_limit_;
  // Time of the current EVT_TIME_HIGH in microseconds, low 6 bits zero.
  uint64_t time_base_us = ((time_epoch << 28) | time_high) << 6;
  uint64_t appended = 0;

  for (size_t i = 0; i < word_count; ++i) {
    uint32_t word;
    std::memcpy(&word, bytes + 4 * i, 4);
    const uint32_t type = word >> 28;
    if (type <= 1) {  // CD_OFF / CD_ON: [27:22] time low, [21:11] x, [10:0] y.
      const uint32_t x = (word >> 11) & 0x7FF;
      const uint32_t y = word & 0x7FF;
      if (!has_time_high) {
        ++statistics_.dropped_before_state;
      } else if (x >= width_limit || y >= height_limit) {
        ++statistics_.dropped_outside_sensor;
      } else {
        const uint64_t time_us = time_base_us + ((word >> 22) & 0x3F);
        staging.Emit(static_cast<int64_t>(time_us * 1000u), x, y,
                     static_cast<int8_t>(2 * static_cast<int>(type) - 1));
        if (staging.NeedsFlush()) appended += staging.Flush(out);
      }
      continue;
    }
    switch (type) {
      case 0x8: {  // EVT_TIME_HIGH: [27:0] time >> 6.
        const uint32_t new_time_high = word & 0x0FFFFFFF;
        if (has_time_high && new_time_high < time_high) {
          // A jump back by at least half the range is the 28-bit counter wrapping around.
          if (time_high - new_time_high >= (1u << 27)) {
            ++time_epoch;
            ++statistics_.time_wraps;
          } else {
            ++statistics_.time_regressions;
          }
        }
        time_high = new_time_high;
        has_time_high = true;
        time_base_us = ((time_epoch << 28) | time_high) << 6;
        break;
      }
      case 0xA:  // EXT_TRIGGER.
        ++statistics_.trigger_words;
        break;
      case 0xE:  // OTHERS.
      case 0xF:  // CONTINUED.
        ++statistics_.skipped_words;
        break;
      default:
        ++statistics_.malformed_words;
        if (!*first_malformed_offset) *first_malformed_offset = offset + 4 * i;
        break;
    }
  }
  appended += staging.Flush(out);
  statistics_.events += appended;
  has_time_high_ = has_time_high;
  time_high_ = time_high;
  time_epoch_ = time_epoch;
}

}  // namespace evloc
