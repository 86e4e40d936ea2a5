#include "tools/replay/reconnect.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "core/common/error.h"
#include "evloc/localizer.grpc.pb.h"
#include "localizer/service/testing/service_fixture.h"
#include "tools/replay/replay.h"

namespace evloc::replay {
namespace {

using Clock = ReconnectBackoff::Clock;
using std::chrono::milliseconds;
using std::chrono::seconds;

double Ms(Clock::duration duration) {
  return std::chrono::duration<double, std::milli>(duration).count();
}

ReconnectOptions TestOptions() {
  ReconnectOptions options;
  options.max_attempts = 1000;
  options.base_ms = 100;
  options.cap_ms = 800;
  options.max_total_s = 3600;
  options.stable_s = 10;
  options.seed = 7;
  return options;
}

// The velocity a resumed session starts with: over the trailing TRACKING poses within the window,
// as the tracker measures it; none when the last two poses are not both TRACKING.
TEST(ResumeVelocity, IsTheTwistOfTheLastTrackingPosesWithinTheWindow) {
  Vector6d twist;
  twist << 0.4, -0.2, 0.1, 0.3, 0.2, -0.5;
  const Rigid3d start(ExpSO3(Eigen::Vector3d(0.1, -0.2, 0.3)), Eigen::Vector3d(1, 0, 2));
  std::vector<TimedPose> poses;
  std::vector<bool> tracking;
  for (int i = 0; i < 60; ++i) {
    const int64_t t_ns = int64_t{i} * 5'000'000;
    // A different motion before the window: it must not enter the measure.
    const Vector6d motion = i < 20 ? Vector6d(-twist) : twist;
    const Rigid3d pose = i == 0 ? start : poses.back().world_from_cam * ExpSE3(motion * 0.005);
    poses.push_back({t_ns, pose});
    tracking.push_back(true);
  }
  const std::optional<Vector6d> velocity = ResumeVelocity(poses, tracking, 100'000'000);
  ASSERT_TRUE(velocity.has_value());
  EXPECT_LT((*velocity - twist).norm(), 1e-9);
  // A LOST pose inside the window shortens the run to the poses after it.
  tracking[55] = false;
  ASSERT_TRUE(ResumeVelocity(poses, tracking, 100'000'000).has_value());
  EXPECT_LT((*ResumeVelocity(poses, tracking, 100'000'000) - twist).norm(), 1e-9);
  // Ending on a LOST pose, or on one TRACKING pose after a LOST one: at rest.
  tracking[58] = false;
  EXPECT_FALSE(ResumeVelocity(poses, tracking, 100'000'000).has_value());
  tracking[58] = true;
  tracking[59] = false;
  EXPECT_FALSE(ResumeVelocity(poses, tracking, 100'000'000).has_value());
  EXPECT_FALSE(ResumeVelocity({}, {}, 100'000'000).has_value());
  EXPECT_THROW(ResumeVelocity(poses, {}, 100'000'000), InvalidArgumentError);
}

TEST(ReconnectBackoff, DelaysAreFullJitterUnderTheCappedExponential) {
  // Attempt k waits within [0, min(cap, base * 2^(k-1))], and the same seed gives the same
  // delays (fake clock: each attempt fails when its delay has passed).
  std::vector<double> first_run;
  for (int run = 0; run < 2; ++run) {
    ReconnectBackoff backoff(TestOptions());
    Clock::time_point now{};
    for (int k = 1; k <= 10; ++k) {
      const ReconnectDecision decision = backoff.OnFailure(now, FailureKind::kTransient, {});
      ASSERT_TRUE(decision.retry) << decision.reason;
      EXPECT_EQ(decision.attempt, k);
      const double ceiling_ms = std::min(800.0, 100.0 * (1 << (k - 1)));
      EXPECT_GE(Ms(decision.delay), 0.0);
      EXPECT_LE(Ms(decision.delay), ceiling_ms) << "attempt " << k;
      if (run == 0) {
        first_run.push_back(Ms(decision.delay));
      } else {
        EXPECT_EQ(Ms(decision.delay), first_run[k - 1]) << "same seed, attempt " << k;
      }
      now += decision.delay;
    }
  }
  // Full jitter spreads the clients of one failed replica over the whole interval, down to
  // (almost) zero, not around the ceiling: first-attempt delays over 200 seeds.
  double low = 1e9;
  double high = 0;
  for (uint64_t seed = 0; seed < 200; ++seed) {
    ReconnectOptions options = TestOptions();
    options.seed = seed;
    ReconnectBackoff backoff(options);
    const double delay_ms = Ms(backoff.OnFailure({}, FailureKind::kTransient, {}).delay);
    low = std::min(low, delay_ms);
    high = std::max(high, delay_ms);
  }
  EXPECT_LT(low, 10.0);
  EXPECT_GT(high, 90.0);
  EXPECT_LE(high, 100.0);
}

TEST(ReconnectBackoff, StopsAtTheAttemptBound) {
  ReconnectOptions options = TestOptions();
  options.max_attempts = 3;
  ReconnectBackoff backoff(options);
  Clock::time_point now{};
  for (int k = 1; k <= 3; ++k) {
    const ReconnectDecision decision = backoff.OnFailure(now, FailureKind::kTransient, {});
    ASSERT_TRUE(decision.retry);
    now += decision.delay;
  }
  const ReconnectDecision last = backoff.OnFailure(now, FailureKind::kTransient, {});
  EXPECT_FALSE(last.retry);
  EXPECT_NE(last.reason.find("gave up after 3 reconnect attempts"), std::string::npos)
      << last.reason;
}

TEST(ReconnectBackoff, StopsAtTheTimeBound) {
  // Many attempts allowed, but no attempt may start more than 5 s after the outage began.
  ReconnectOptions options = TestOptions();
  options.max_total_s = 5;
  ReconnectBackoff backoff(options);
  const Clock::time_point begin{};
  Clock::time_point now = begin;
  int attempts = 0;
  for (;;) {
    const ReconnectDecision decision = backoff.OnFailure(now, FailureKind::kTransient, {});
    if (!decision.retry) {
      EXPECT_NE(decision.reason.find("--reconnect-max-s"), std::string::npos) << decision.reason;
      break;
    }
    ++attempts;
    ASSERT_LT(attempts, 100) << "no time bound";
    now += decision.delay;
    EXPECT_LE(now - begin, seconds(5));
  }
  EXPECT_GE(attempts, 5);
  // A server delay past the bound ends the outage too.
  ReconnectBackoff pushed(options);
  EXPECT_FALSE(pushed.OnFailure(begin, FailureKind::kTransient, seconds(6)).retry);
}

TEST(ReconnectBackoff, ShortLivedSessionsDoNotResetTheBackoff) {
  ReconnectOptions options = TestOptions();
  options.max_attempts = 4;
  options.stable_s = 10;
  ReconnectBackoff backoff(options);
  Clock::time_point now{};
  // A replica that admits every session and drops it a second later: the attempts keep
  // counting and the ceiling keeps growing until the bound.
  for (int k = 1; k <= 4; ++k) {
    const ReconnectDecision decision = backoff.OnFailure(now, FailureKind::kTransient, {});
    ASSERT_TRUE(decision.retry) << "attempt " << k << ": " << decision.reason;
    EXPECT_EQ(decision.attempt, k);
    now += decision.delay;
    backoff.SessionStarted(now);
    now += seconds(1);
  }
  EXPECT_FALSE(backoff.OnFailure(now, FailureKind::kTransient, {}).retry);

  // A session that stayed up for the stable time starts a new outage at attempt 1.
  ReconnectBackoff stable(options);
  now = {};
  for (int k = 1; k <= 3; ++k) {
    const ReconnectDecision decision = stable.OnFailure(now, FailureKind::kTransient, {});
    ASSERT_TRUE(decision.retry);
    now += decision.delay + seconds(1);
  }
  stable.SessionStarted(now);
  now += seconds(10);
  const ReconnectDecision fresh = stable.OnFailure(now, FailureKind::kTransient, {});
  ASSERT_TRUE(fresh.retry);
  EXPECT_EQ(fresh.attempt, 1);
  EXPECT_LE(Ms(fresh.delay), 100.0);
}

TEST(ReconnectBackoff, OverloadSlowsDownInsteadOfRetryingAtOnce) {
  // RESOURCE_EXHAUSTED waits at least half the attempt's ceiling.
  for (uint64_t seed = 0; seed < 100; ++seed) {
    ReconnectOptions options = TestOptions();
    options.seed = seed;
    ReconnectBackoff backoff(options);
    Clock::time_point now{};
    for (int k = 1; k <= 5; ++k) {
      const ReconnectDecision decision = backoff.OnFailure(now, FailureKind::kOverloaded, {});
      ASSERT_TRUE(decision.retry);
      const double ceiling_ms = std::min(800.0, 100.0 * (1 << (k - 1)));
      EXPECT_GE(Ms(decision.delay), ceiling_ms / 2) << "seed " << seed << " attempt " << k;
      EXPECT_LE(Ms(decision.delay), ceiling_ms);
      now += decision.delay;
    }
  }
}

TEST(ReconnectBackoff, ServerDelayIsHonoured) {
  ReconnectBackoff backoff(TestOptions());
  const ReconnectDecision decision =
      backoff.OnFailure({}, FailureKind::kTransient, milliseconds(1500));
  ASSERT_TRUE(decision.retry);
  EXPECT_GE(Ms(decision.delay), 1500.0);
  // A negative pushback: the server asks not to retry.
  ReconnectBackoff refused(TestOptions());
  const ReconnectDecision no = refused.OnFailure({}, FailureKind::kTransient, milliseconds(-1));
  EXPECT_FALSE(no.retry);
  EXPECT_NE(no.reason.find("asked not to retry"), std::string::npos) << no.reason;
}

TEST(ReconnectBackoff, OptionsAreChecked) {
  ReconnectOptions options = TestOptions();
  options.cap_ms = 50;  // below the base
  EXPECT_THROW(ReconnectBackoff{options}, InvalidArgumentError);
  options = TestOptions();
  options.max_total_s = 0;
  EXPECT_THROW(ReconnectBackoff{options}, InvalidArgumentError);
  options = TestOptions();
  options.max_attempts = -1;
  EXPECT_THROW(ReconnectBackoff{options}, InvalidArgumentError);
}

// Protobuf wire format for the RetryInfo tests.
std::string Varint(uint64_t value) {
  std::string bytes;
  while (value >= 0x80) {
    bytes.push_back(static_cast<char>((value & 0x7f) | 0x80));
    value >>= 7;
  }
  bytes.push_back(static_cast<char>(value));
  return bytes;
}
std::string Field(int number, const std::string& bytes) {
  return Varint(static_cast<uint64_t>(number) << 3 | 2) + Varint(bytes.size()) + bytes;
}

// A serialized google.rpc.Status {code, message, details: [other Any, RetryInfo{delay}]}.
std::string StatusWithRetryInfo(int64_t seconds_part, int32_t nanos) {
  const std::string duration = Varint(1 << 3) + Varint(static_cast<uint64_t>(seconds_part)) +
                               Varint(2 << 3) + Varint(static_cast<uint64_t>(nanos));
  const std::string retry_info = Field(1, duration);
  const std::string other = Field(1, "type.googleapis.com/google.rpc.DebugInfo") + Field(2, "x");
  const std::string retry =
      Field(1, "type.googleapis.com/google.rpc.RetryInfo") + Field(2, retry_info);
  return Varint(1 << 3) + Varint(14) + Field(2, "draining") + Field(3, other) + Field(3, retry);
}

TEST(ServerRetryDelay, ReadsPushbackAndRetryInfo) {
  EXPECT_EQ(ServerRetryDelay("", ""), std::nullopt);
  EXPECT_EQ(Ms(*ServerRetryDelay("250", "")), 250.0);
  EXPECT_LT(*ServerRetryDelay("-1", ""), Clock::duration::zero());
  EXPECT_LT(*ServerRetryDelay("soon", ""), Clock::duration::zero()) << "unparseable: no retry";
  EXPECT_EQ(Ms(*ServerRetryDelay("", StatusWithRetryInfo(1, 500'000'000))), 1500.0);
  // The pushback trailer wins over the RetryInfo.
  EXPECT_EQ(Ms(*ServerRetryDelay("20", StatusWithRetryInfo(1, 0))), 20.0);
  // Truncated details carry no delay.
  const std::string details = StatusWithRetryInfo(2, 0);
  EXPECT_EQ(ServerRetryDelay("", details.substr(0, details.size() - 3)), std::nullopt);
  EXPECT_EQ(ServerRetryDelay("", "\xff\xff\xff"), std::nullopt);
}

// A scripted Localizer: a real gRPC server on loopback whose Track calls do what `script` says
// for the n-th call (0-based); it records when each call arrived.
class ScriptedLocalizer final : public api::Localizer::Service {
 public:
  using Stream = grpc::ServerReaderWriter<api::TrackResponse, api::TrackRequest>;
  using Script = std::function<grpc::Status(int call, grpc::ServerContext*, Stream*)>;

  explicit ScriptedLocalizer(Script script) : script_(std::move(script)) {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(this);
    server_ = builder.BuildAndStart();
  }
  ~ScriptedLocalizer() override { server_->Shutdown(); }

  int port() const { return port_; }
  std::vector<Clock::time_point> calls() {
    std::lock_guard<std::mutex> lock(mutex_);
    return calls_;
  }

  grpc::Status Track(grpc::ServerContext* context, Stream* stream) override {
    int call = 0;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      call = static_cast<int>(calls_.size());
      calls_.push_back(Clock::now());
    }
    return script_(call, context, stream);
  }

 private:
  Script script_;
  std::mutex mutex_;
  std::vector<Clock::time_point> calls_;
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
};

// Reads the SessionStart and answers SessionStarted.
api::SessionStart Admit(ScriptedLocalizer::Stream* stream) {
  api::TrackRequest request;
  EXPECT_TRUE(stream->Read(&request));
  api::TrackResponse started;
  started.mutable_started()->set_session_id(1);
  started.mutable_started()->mutable_map()->set_name(service::testing::kTestMapName);
  started.mutable_started()->set_step_rate_hz(200);
  started.mutable_started()->set_variant("EVT");
  started.mutable_started()->set_queue_capacity(64);
  stream->Write(started);
  return request.start();
}

class ReplayReconnectTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dataset_ = service::testing::WriteTestDataset(folder_.path(), 300'000'000);
  }
  ReplayOptions Options(int port) const {
    ReplayOptions options;
    options.server = "127.0.0.1:" + std::to_string(port);
    options.map_name = service::testing::kTestMapName;
    options.dataset = dataset_;
    options.output = folder_.path() / "trajectory.txt";
    options.speed = std::nullopt;
    options.reconnect_backoff_ms = 5;
    options.reconnect_seed = 1;
    return options;
  }
  service::testing::TemporaryFolder folder_;
  std::filesystem::path dataset_;
};

TEST_F(ReplayReconnectTest, ServerPushbackAndRetryInfoAreHonoured) {
  // Every call is refused UNAVAILABLE: the first asks for 400 ms (grpc-retry-pushback-ms), the
  // others for 300 ms (a RetryInfo in the status details, as a draining server may send).
  ScriptedLocalizer server([](int call, grpc::ServerContext* context, ScriptedLocalizer::Stream*) {
    if (call == 0) {
      context->AddTrailingMetadata("grpc-retry-pushback-ms", "400");
      return grpc::Status(grpc::StatusCode::UNAVAILABLE, "busy");
    }
    return grpc::Status(grpc::StatusCode::UNAVAILABLE, "draining",
                        StatusWithRetryInfo(0, 300'000'000));
  });
  ReplayOptions options = Options(server.port());
  options.reconnect = 2;
  std::ostringstream log;
  EXPECT_THROW(RunReplay(options, log), Error);
  const std::vector<Clock::time_point> calls = server.calls();
  ASSERT_EQ(calls.size(), 3u) << log.str();
  EXPECT_GE(Ms(calls[1] - calls[0]), 400.0) << log.str();
  EXPECT_GE(Ms(calls[2] - calls[1]), 300.0) << log.str();
  EXPECT_NE(log.str().find("the server asked for 400"), std::string::npos) << log.str();
}

TEST_F(ReplayReconnectTest, SessionsThatFailSoonAfterReconnectingDoNotResetTheBackoff) {
  // A replica that admits each session, sends one pose and drops it: without the stable-time
  // rule every pose reset the attempts and the client retried forever, in step with the others.
  std::atomic<int> dropped{0};
  ScriptedLocalizer server([&](int call, grpc::ServerContext*, ScriptedLocalizer::Stream* stream) {
    if (call >= 12) return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, "call limit");
    const api::SessionStart start = Admit(stream);
    api::TrackRequest packet;
    stream->Read(&packet);
    api::TrackResponse pose;
    pose.mutable_pose()->set_t_ns(start.initial_t_ns() + 5'000'000 * (call + 1));
    *pose.mutable_pose()->mutable_world_from_cam() = start.initial_world_from_cam();
    pose.mutable_pose()->set_status(api::TRACKING);
    stream->Write(pose);
    ++dropped;
    return grpc::Status(grpc::StatusCode::UNAVAILABLE, "dropped");
  });
  ReplayOptions options = Options(server.port());
  options.reconnect = 3;
  options.reconnect_stable_s = 10;
  std::ostringstream log;
  try {
    RunReplay(options, log);
    FAIL() << "expected an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("gave up after 3 reconnect attempts"),
              std::string::npos)
        << error.what() << "\n"
        << log.str();
  }
  EXPECT_EQ(server.calls().size(), 4u) << log.str();
  EXPECT_EQ(dropped.load(), 4);
}

TEST_F(ReplayReconnectTest, SessionEndedEarlyByADrainingServerIsResumed) {
  // The first call ends with a SessionEnd and OK after one packet (a draining server); the
  // replay is not finished, so it resumes on a new session, which runs to the end.
  ScriptedLocalizer server([](int call, grpc::ServerContext*, ScriptedLocalizer::Stream* stream) {
    Admit(stream);
    api::TrackRequest request;
    if (call == 0) {
      stream->Read(&request);
    } else {
      while (stream->Read(&request)) {
      }
    }
    api::TrackResponse end;
    end.mutable_end()->set_poses(0);
    stream->Write(end);
    return grpc::Status::OK;
  });
  ReplayOptions options = Options(server.port());
  options.reconnect = 2;
  // Unconfirmed packets wait up to 20 ms each for a pose that this server never sends.
  options.duration_s = 0.05;
  std::ostringstream log;
  const ReplayResult result = RunReplay(options, log);
  EXPECT_EQ(server.calls().size(), 2u) << log.str();
  ASSERT_EQ(result.outages.size(), 1u) << log.str();
  EXPECT_EQ(result.outages[0].status_code, grpc::StatusCode::UNAVAILABLE);
}

}  // namespace
}  // namespace evloc::replay
