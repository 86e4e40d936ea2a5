// When evloc-replay reconnects after a failed stream (docs/deploy.md, "Reconnecting"): full-jitter
// exponential backoff, bounded in attempts and in time, a backoff that only a session that stayed
// up resets, "slow down" for an overloaded server, and the server's pushback honoured. No gRPC
// here: the replay passes in the status code and the server's retry delay, and the clock.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "core/trajectory/trajectory.h"

namespace evloc::replay {

// Options of the reconnect backoff; every field is a flag of evloc-replay.
struct ReconnectOptions {
  // Most reconnect attempts of one outage; 0: fail at once (--reconnect N).
  int max_attempts = 0;
  // Ceiling of the first attempt's delay, ms: attempt k (1-based) waits uniformly in
  // [0, min(cap, base * 2^(k-1))] (full jitter) (--reconnect-backoff-ms).
  double base_ms = 100.0;
  // Largest ceiling of a delay, ms (--reconnect-backoff-max-ms).
  double cap_ms = 2000.0;
  // Most wall time from the failure that started an outage to the start of its last attempt,
  // seconds; an attempt whose delay would end later is not made (--reconnect-max-s).
  double max_total_s = 60.0;
  // A session must stay up this long, seconds of wall time from its admission, before its
  // failure starts a new outage with a fresh backoff; a session that fails sooner continues
  // the outage it came from (--reconnect-stable-s).
  double stable_s = 10.0;
  // Seed of the jitter; unset: a random seed (--reconnect-seed).
  std::optional<uint64_t> seed;

  // Throws InvalidArgumentError naming the flag of the first invalid field.
  void Check() const;
};

// How the server ended a stream, as far as the backoff cares.
enum class FailureKind {
  // Went away, refused the connection, draining, cut without a status: retry after a delay.
  kTransient,
  // RESOURCE_EXHAUSTED (full at admission, or the session's queue overflowed): slow down, the
  // delay is at least half its ceiling, never an immediate retry.
  kOverloaded,
};

// The decision after a failure.
struct ReconnectDecision {
  // Whether to try again.
  bool retry = false;
  // Wait before the attempt (when retry).
  std::chrono::steady_clock::duration delay{};
  // Attempt number in the outage, 1-based (when retry), or the attempts made (when not).
  int attempt = 0;
  // Why not (when !retry): which bound ended the outage.
  std::string reason;
};

// The backoff state of one replay; the caller passes the time in, so that tests can use a fake
// clock. Not thread-safe.
class ReconnectBackoff {
 public:
  using Clock = std::chrono::steady_clock;

  // Throws InvalidArgumentError for invalid options.
  explicit ReconnectBackoff(const ReconnectOptions& options);

  // The server admitted a session at `now` (SessionStarted).
  void SessionStarted(Clock::time_point now);

  // The stream failed at `now` with a retryable status of kind `kind`; `server_delay`: the
  // retry delay the server asked for (gRPC's grpc-retry-pushback-ms trailer, or a
  // google.rpc.RetryInfo), negative meaning "do not retry". Returns whether and when to try
  // again.
  ReconnectDecision OnFailure(Clock::time_point now, FailureKind kind,
                              std::optional<Clock::duration> server_delay);

  // Attempts made in the current outage (0 when none is under way).
  int attempts() const { return attempts_; }

 private:
  ReconnectOptions options_;
  std::mt19937_64 random_;
  int attempts_ = 0;
  // Start of the current outage (its first failure).
  std::optional<Clock::time_point> outage_start_;
  // Admission of the last session since the last failure.
  std::optional<Clock::time_point> session_started_;
};

// The retry delay a server asked for in a failed call's trailing metadata: gRPC's
// "grpc-retry-pushback-ms" (milliseconds, a negative value: do not retry), or else the
// google.rpc.RetryInfo.retry_delay in "grpc-status-details-bin" (a serialized google.rpc.Status).
// `pushback_ms` / `status_details`: the values of those keys, empty when absent. A negative or
// unparseable pushback gives a negative duration ("do not retry", as gRPC's retry design A6
// says); nullopt when neither holds a delay.
std::optional<std::chrono::steady_clock::duration> ServerRetryDelay(
    const std::string& pushback_ms, const std::string& status_details);

// The velocity a resumed session starts with (SessionStart.initial_velocity): the body-frame
// twist per second, as the tracker's constant-velocity model measures it, from the oldest pose of
// the trailing run of TRACKING poses that is at least `window_ns` older than the newest (the
// oldest of the run when none is) to the newest. `tracking[i]`: whether poses[i] was TRACKING.
// nullopt when the last two poses are not both TRACKING (the session then resumes at rest).
std::optional<Vector6d> ResumeVelocity(const std::vector<TimedPose>& poses,
                                       const std::vector<bool>& tracking, int64_t window_ns);

}  // namespace evloc::replay
