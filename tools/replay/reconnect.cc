#include "tools/replay/reconnect.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string_view>

#include "core/common/error.h"

namespace evloc::replay {
namespace {

using Clock = ReconnectBackoff::Clock;

Clock::duration FromMilliseconds(double ms) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double, std::milli>(ms));
}

double MillisecondsOf(Clock::duration duration) {
  return std::chrono::duration<double, std::milli>(duration).count();
}

// A minimal reader of the protobuf wire format, for the three messages of a google.rpc.Status
// with a RetryInfo (no dependency on googleapis' protos).
class WireReader {
 public:
  explicit WireReader(std::string_view bytes) : bytes_(bytes) {}
  bool done() const { return position_ >= bytes_.size(); }

  bool ReadVarint(uint64_t* value) {
    *value = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (position_ >= bytes_.size()) return false;
      const auto byte = static_cast<unsigned char>(bytes_[position_++]);
      *value |= static_cast<uint64_t>(byte & 0x7f) << shift;
      if ((byte & 0x80) == 0) return true;
    }
    return false;
  }

  // Reads a field key; `field` and `wire_type` of it.
  bool ReadKey(uint64_t* field, int* wire_type) {
    uint64_t key = 0;
    if (!ReadVarint(&key)) return false;
    *field = key >> 3;
    *wire_type = static_cast<int>(key & 7);
    return true;
  }

  bool ReadLengthDelimited(std::string_view* value) {
    uint64_t length = 0;
    if (!ReadVarint(&length) || length > bytes_.size() - position_) return false;
    *value = bytes_.substr(position_, length);
    position_ += length;
    return true;
  }

  // Skips a field of `wire_type` (varint, 64-bit, length-delimited, 32-bit).
  bool Skip(int wire_type) {
    uint64_t ignored = 0;
    std::string_view ignored_bytes;
    switch (wire_type) {
      case 0:
        return ReadVarint(&ignored);
      case 1:
        return Advance(8);
      case 2:
        return ReadLengthDelimited(&ignored_bytes);
      case 5:
        return Advance(4);
      default:
        return false;
    }
  }

 private:
  bool Advance(size_t count) {
    if (count > bytes_.size() - position_) return false;
    position_ += count;
    return true;
  }
  std::string_view bytes_;
  size_t position_ = 0;
};

// google.protobuf.Duration {int64 seconds = 1; int32 nanos = 2;}, in milliseconds.
std::optional<double> ParseDurationMs(std::string_view bytes) {
  WireReader reader(bytes);
  int64_t seconds = 0;
  int64_t nanos = 0;
  while (!reader.done()) {
    uint64_t field = 0;
    int wire_type = 0;
    if (!reader.ReadKey(&field, &wire_type)) return std::nullopt;
    if ((field == 1 || field == 2) && wire_type == 0) {
      uint64_t value = 0;
      if (!reader.ReadVarint(&value)) return std::nullopt;
      (field == 1 ? seconds : nanos) = static_cast<int64_t>(value);
    } else if (!reader.Skip(wire_type)) {
      return std::nullopt;
    }
  }
  return static_cast<double>(seconds) * 1e3 + static_cast<double>(nanos) * 1e-6;
}

// The RetryInfo.retry_delay of a serialized google.rpc.Status, ms.
std::optional<double> RetryInfoDelayMs(std::string_view status) {
  constexpr std::string_view kRetryInfoType = "type.googleapis.com/google.rpc.RetryInfo";
  WireReader reader(status);
  while (!reader.done()) {
    uint64_t field = 0;
    int wire_type = 0;
    if (!reader.ReadKey(&field, &wire_type)) return std::nullopt;
    if (field != 3 || wire_type != 2) {
      if (!reader.Skip(wire_type)) return std::nullopt;
      continue;
    }
    // google.protobuf.Any {string type_url = 1; bytes value = 2;}
    std::string_view any;
    if (!reader.ReadLengthDelimited(&any)) return std::nullopt;
    WireReader any_reader(any);
    std::string_view type_url;
    std::string_view value;
    while (!any_reader.done()) {
      uint64_t any_field = 0;
      int any_wire_type = 0;
      if (!any_reader.ReadKey(&any_field, &any_wire_type)) return std::nullopt;
      if (any_field == 1 && any_wire_type == 2) {
        if (!any_reader.ReadLengthDelimited(&type_url)) return std::nullopt;
      } else if (any_field == 2 && any_wire_type == 2) {
        if (!any_reader.ReadLengthDelimited(&value)) return std::nullopt;
      } else if (!any_reader.Skip(any_wire_type)) {
        return std::nullopt;
      }
    }
    if (type_url != kRetryInfoType) continue;
    // google.rpc.RetryInfo {google.protobuf.Duration retry_delay = 1;}
    WireReader info(value);
    while (!info.done()) {
      uint64_t info_field = 0;
      int info_wire_type = 0;
      if (!info.ReadKey(&info_field, &info_wire_type)) return std::nullopt;
      if (info_field == 1 && info_wire_type == 2) {
        std::string_view duration;
        if (!info.ReadLengthDelimited(&duration)) return std::nullopt;
        return ParseDurationMs(duration);
      }
      if (!info.Skip(info_wire_type)) return std::nullopt;
    }
  }
  return std::nullopt;
}

}  // namespace

void ReconnectOptions::Check() const {
  if (max_attempts < 0) throw InvalidArgumentError("--reconnect must be 0 or more");
  if (!(base_ms >= 1 && base_ms <= 60'000)) {
    throw InvalidArgumentError("--reconnect-backoff-ms must be in 1..60000");
  }
  if (!(cap_ms >= base_ms && cap_ms <= 600'000)) {
    throw InvalidArgumentError(
        "--reconnect-backoff-max-ms must be at least --reconnect-backoff-ms and at most 600000");
  }
  if (!(max_total_s > 0 && max_total_s <= 86'400)) {
    throw InvalidArgumentError("--reconnect-max-s must be in (0, 86400]");
  }
  if (!(stable_s >= 0 && stable_s <= 86'400)) {
    throw InvalidArgumentError("--reconnect-stable-s must be in 0..86400");
  }
}

ReconnectBackoff::ReconnectBackoff(const ReconnectOptions& options) : options_(options) {
  options_.Check();
  random_.seed(options_.seed ? *options_.seed : std::random_device{}());
}

void ReconnectBackoff::SessionStarted(Clock::time_point now) { session_started_ = now; }

ReconnectDecision ReconnectBackoff::OnFailure(Clock::time_point now, FailureKind kind,
                                              std::optional<Clock::duration> server_delay) {
  // Only a session that stayed up ends the outage it came from: one that fails again soon
  // (a flapping replica, a proxy that accepts and drops) keeps the backoff growing.
  if (session_started_ && now - *session_started_ >= FromMilliseconds(options_.stable_s * 1e3)) {
    attempts_ = 0;
    outage_start_.reset();
  }
  session_started_.reset();
  if (!outage_start_) outage_start_ = now;

  ReconnectDecision decision;
  decision.attempt = attempts_;
  if (server_delay && *server_delay < Clock::duration::zero()) {
    decision.reason = "the server asked not to retry";
    return decision;
  }
  if (attempts_ >= options_.max_attempts) {
    decision.reason = "gave up after " + std::to_string(options_.max_attempts) +
                      " reconnect attempts (--reconnect)";
    return decision;
  }
  const int attempt = attempts_ + 1;
  // min(cap, base * 2^(attempt - 1)) without overflowing for many attempts.
  const double ceiling_ms =
      attempt > 60 ? options_.cap_ms
                   : std::min(options_.cap_ms, options_.base_ms * std::ldexp(1.0, attempt - 1));
  const double low_ms = kind == FailureKind::kOverloaded ? ceiling_ms / 2 : 0.0;
  std::uniform_real_distribution<double> jitter(low_ms, ceiling_ms);
  Clock::duration delay = FromMilliseconds(jitter(random_));
  if (server_delay) delay = std::max(delay, *server_delay);
  const Clock::time_point deadline = *outage_start_ + FromMilliseconds(options_.max_total_s * 1e3);
  if (now + delay > deadline) {
    decision.reason = "gave up after " + std::to_string(attempts_) +
                      " reconnect attempts: the next one, in " +
                      std::to_string(static_cast<int64_t>(MillisecondsOf(delay))) +
                      " ms, would start more than " + std::to_string(options_.max_total_s) +
                      " s after the outage began (--reconnect-max-s)";
    return decision;
  }
  attempts_ = attempt;
  decision.retry = true;
  decision.delay = delay;
  decision.attempt = attempt;
  return decision;
}

std::optional<Clock::duration> ServerRetryDelay(const std::string& pushback_ms,
                                                const std::string& status_details) {
  if (!pushback_ms.empty()) {
    // gRPC's retry design (A6): a decimal integer of milliseconds; negative or unparseable: the
    // server asks the client not to retry.
    constexpr Clock::duration kDoNotRetry(-1);
    size_t parsed = 0;
    try {
      const long long value = std::stoll(pushback_ms, &parsed);
      if (parsed != pushback_ms.size() || value < 0) return kDoNotRetry;
      return FromMilliseconds(static_cast<double>(value));
    } catch (const std::exception&) {
      return kDoNotRetry;
    }
  }
  if (!status_details.empty()) {
    if (const std::optional<double> ms = RetryInfoDelayMs(status_details)) {
      if (*ms >= 0) return FromMilliseconds(*ms);
    }
  }
  return std::nullopt;
}

std::optional<Vector6d> ResumeVelocity(const std::vector<TimedPose>& poses,
                                       const std::vector<bool>& tracking, int64_t window_ns) {
  if (poses.size() != tracking.size()) {
    throw InvalidArgumentError("ResumeVelocity: one TRACKING flag per pose is needed");
  }
  const size_t newest = poses.size();
  if (newest < 2 || !tracking[newest - 1] || !tracking[newest - 2]) return std::nullopt;
  // Walk back over the run while the span is shorter than the window.
  size_t oldest = newest - 2;
  const int64_t newest_t_ns = poses[newest - 1].t_ns;
  while (oldest > 0 && tracking[oldest - 1] && newest_t_ns - poses[oldest].t_ns < window_ns) {
    --oldest;
  }
  const int64_t span_ns = newest_t_ns - poses[oldest].t_ns;
  if (span_ns <= 0) return std::nullopt;
  return LogSE3(poses[oldest].world_from_cam.Inverse() * poses[newest - 1].world_from_cam) /
         (static_cast<double>(span_ns) * 1e-9);
}

}  // namespace evloc::replay
