#include "core/events/evt3_encoder.h"

#include "core/common/error.h"

namespace evloc {
namespace {

constexpr uint16_t kAddrY = 0x0;
constexpr uint16_t kAddrX = 0x2;
constexpr uint16_t kTimeLow = 0x6;
constexpr uint16_t kTimeHigh = 0x8;
// Largest forward step of EVT_TIME_HIGH a decoder reads as a step and not as a wrap-around
// (half of the 12-bit range), with margin.
constexpr uint64_t kMaxTimeHighStep = 1024;

uint16_t MakeWord(uint16_t type, uint32_t payload) {
  return static_cast<uint16_t>((type << 12) | (payload & 0xfff));
}

}  // namespace

void Evt3Encoder::Word(uint16_t word, std::string* out) {
  out->push_back(static_cast<char>(word & 0xff));
  out->push_back(static_cast<char>(word >> 8));
}

void Evt3Encoder::Encode(const EventBuffer& events, std::string* out) {
  int64_t previous_t_ns = last_t_ns_;
  for (size_t i = 0; i < events.size(); ++i) {
    const int64_t t_ns = events.t_ns[i];
    if (t_ns < 0 || t_ns % 1000 != 0) {
      throw InvalidArgumentError("Evt3Encoder: event " + std::to_string(i) + " time " +
                                 std::to_string(t_ns) +
                                 " ns is negative or not a whole microsecond");
    }
    if (t_ns < previous_t_ns) {
      throw InvalidArgumentError("Evt3Encoder: event " + std::to_string(i) + " goes back in time");
    }
    if (events.x[i] >= 2048 || events.y[i] >= 2048) {
      throw InvalidArgumentError("Evt3Encoder: event " + std::to_string(i) +
                                 " has a coordinate EVT 3.0 cannot address (>= 2048)");
    }
    previous_t_ns = t_ns;
  }
  for (size_t i = 0; i < events.size(); ++i) {
    const uint64_t t_us = static_cast<uint64_t>(events.t_ns[i] / 1000);
    const uint64_t high = t_us >> 12;
    const uint32_t low = static_cast<uint32_t>(t_us & 0xfff);
    if (!time_high_ || *time_high_ != high) {
      if (time_high_) {
        while (high - *time_high_ > kMaxTimeHighStep) {
          *time_high_ += kMaxTimeHighStep;
          Word(MakeWord(kTimeHigh, static_cast<uint32_t>(*time_high_)), out);
        }
      }
      time_high_ = high;
      Word(MakeWord(kTimeHigh, static_cast<uint32_t>(high)), out);
      time_low_.reset();
    }
    if (!time_low_ || *time_low_ != low) {
      time_low_ = low;
      Word(MakeWord(kTimeLow, low), out);
    }
    if (!y_ || *y_ != events.y[i]) {
      y_ = events.y[i];
      Word(MakeWord(kAddrY, events.y[i]), out);
    }
    Word(MakeWord(kAddrX,
                  static_cast<uint32_t>(events.x[i]) | (events.polarity[i] > 0 ? 0x800u : 0u)),
         out);
  }
  if (!events.empty()) last_t_ns_ = events.t_ns.back();
}

}  // namespace evloc
