// The safety client's state machine (SafetyMonitor) without a network: every event carries an injected
// steady-clock time, so the watchdog's 30 ms is exact here.
#include <gtest/gtest.h>

#include "safety_client.h"

namespace {

using namespace std::chrono_literals;
namespace rc = ruffini::controller;
namespace v1 = ruffini::v1;
using Kind = rc::SafetyMonitor::Action::Kind;

const rc::SteadyClock::time_point kT0{std::chrono::seconds(1000)};

v1::SafetyState State(v1::SafetyState::State s, std::uint64_t epoch, std::uint64_t seq, std::int64_t run = 42) {
  v1::SafetyState m;
  m.set_state(s);
  m.set_stop_epoch(epoch);
  m.set_seq(seq);
  m.set_aggregator_start_t_ns(run);
  if (s == v1::SafetyState::STATE_STOP) {
    m.mutable_cause()->set_kind(v1::SafetyCause::KIND_CONTACT);
    m.mutable_cause()->set_patch_id("upper_arm_a");
    m.mutable_cause()->set_force_n(1.6f);
    m.mutable_cause()->set_threshold_n(1.5f);
  } else if (s == v1::SafetyState::STATE_FAULT) {
    m.mutable_cause()->set_kind(v1::SafetyCause::KIND_STARTUP);
  }
  return m;
}
constexpr auto kClear = v1::SafetyState::STATE_CLEAR;
constexpr auto kStop = v1::SafetyState::STATE_STOP;
constexpr auto kFault = v1::SafetyState::STATE_FAULT;

// Feeds CLEAR states 10 ms apart until the monitor clears; returns the time of the clear.
rc::SteadyClock::time_point ClearUp(rc::SafetyMonitor& m, rc::SteadyClock::time_point t, std::uint64_t epoch,
                                    std::uint64_t& seq) {
  for (int i = 0; i < 10; ++i) {
    t += 10ms;
    if (m.OnState(State(kClear, epoch, ++seq), t).kind == Kind::kClear) return t;
  }
  ADD_FAILURE() << "never cleared";
  return t;
}

TEST(SafetyMonitor, StartsHaltedAndClearsOnlyAfterThreeClearStatesOnALiveStream) {
  rc::SafetyMonitor m({}, kT0);
  EXPECT_TRUE(m.halted());
  EXPECT_EQ(m.reason(), rc::HaltReason::kNotStarted);
  m.OnStreamOpened(kT0);
  EXPECT_EQ(m.OnState(State(kClear, 1, 1), kT0 + 1ms).kind, Kind::kNone);
  EXPECT_EQ(m.OnState(State(kClear, 1, 2), kT0 + 11ms).kind, Kind::kNone);
  const auto a = m.OnState(State(kClear, 1, 3), kT0 + 21ms);
  ASSERT_EQ(a.kind, Kind::kClear);
  EXPECT_EQ(a.clear.halted_for, 21ms);
  EXPECT_FALSE(m.halted());
  EXPECT_EQ(m.Stats(kT0 + 30ms).clears, 1u);
}

TEST(SafetyMonitor, AStreamEndInTheMiddleOfTheClearStreakStartsItAgain) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  m.OnState(State(kClear, 1, 1), kT0 + 1ms);
  m.OnState(State(kClear, 1, 2), kT0 + 11ms);
  EXPECT_EQ(m.OnStreamEnded("UNAVAILABLE", kT0 + 12ms).kind, Kind::kHalt);
  m.OnStreamOpened(kT0 + 112ms);
  EXPECT_EQ(m.OnState(State(kClear, 1, 5), kT0 + 113ms).kind, Kind::kNone);
  EXPECT_EQ(m.OnState(State(kClear, 1, 6), kT0 + 123ms).kind, Kind::kNone);
  EXPECT_EQ(m.OnState(State(kClear, 1, 7), kT0 + 133ms).kind, Kind::kClear);
}

TEST(SafetyMonitor, StopHaltsAtOnceAndNamesTheCause) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 2, seq);
  const auto a = m.OnState(State(kStop, 3, ++seq), t + 10ms);
  ASSERT_EQ(a.kind, Kind::kHalt);
  EXPECT_EQ(a.halt.reason, rc::HaltReason::kStop);
  EXPECT_EQ(a.halt.detail, "STOP epoch 3 cause contact upper_arm_a 1.60 N > 1.50 N");
  EXPECT_EQ(a.halt.state.stop_epoch(), 3u);
  // The same STOP again (a heartbeat) is no new decision; a FAULT under a new epoch is.
  EXPECT_EQ(m.OnState(State(kStop, 3, ++seq), t + 20ms).kind, Kind::kNone);
  const auto f = m.OnState(State(kFault, 4, ++seq), t + 30ms);
  ASSERT_EQ(f.kind, Kind::kHalt);
  EXPECT_EQ(f.halt.reason, rc::HaltReason::kFault);
  // Another STOP epoch while halted for STOP is reported too.
  EXPECT_EQ(m.OnState(State(kStop, 5, ++seq), t + 40ms).halt.reason, rc::HaltReason::kStop);
  EXPECT_EQ(m.OnState(State(kStop, 6, ++seq), t + 50ms).kind, Kind::kHalt);
  const auto st = m.Stats(t + 50ms);
  EXPECT_EQ(st.halts[static_cast<int>(rc::HaltReason::kStop)], 3u);
  EXPECT_EQ(st.halts[static_cast<int>(rc::HaltReason::kFault)], 1u);
}

TEST(SafetyMonitor, AnUnknownStateIsAStop) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  const auto t = ClearUp(m, kT0, 1, seq);
  for (int v : {0, 17}) {
    v1::SafetyState s = State(kClear, 1, ++seq);
    // Through reflection: the setter refuses a value the enum does not name; the wire does not.
    s.GetReflection()->SetEnumValue(&s, s.GetDescriptor()->FindFieldByName("state"), v);
    const auto a = m.OnState(s, t + 10ms);
    EXPECT_TRUE(m.halted());
    if (v == 0) {
      ASSERT_EQ(a.kind, Kind::kHalt);
      EXPECT_EQ(a.halt.reason, rc::HaltReason::kUnknownState);
    }
  }
}

TEST(SafetyMonitor, SilenceLongerThan30MsHaltsOnceThenAStateChangesTheReason) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 1, seq);
  EXPECT_EQ(m.OnTick(t + 30ms).kind, Kind::kNone);  // exactly 30 ms: not yet
  const auto a = m.OnTick(t + 30ms + 1ns);
  ASSERT_EQ(a.kind, Kind::kHalt);
  EXPECT_EQ(a.halt.reason, rc::HaltReason::kNoHeartbeat);
  EXPECT_EQ(a.halt.silence, 30ms + 1ns);
  EXPECT_EQ(a.halt.detail, "no state for 30.0 ms (limit 30.0 ms)");
  EXPECT_EQ(m.OnTick(t + 60ms).kind, Kind::kNone);  // once, not every tick
  // Heartbeats again: CLEAR needs its streak on the live stream.
  t += 200ms;
  EXPECT_EQ(m.OnState(State(kClear, 1, ++seq), t).kind, Kind::kNone);
  EXPECT_EQ(m.OnState(State(kClear, 1, ++seq), t + 10ms).kind, Kind::kNone);
  EXPECT_EQ(m.OnState(State(kClear, 1, ++seq), t + 20ms).kind, Kind::kClear);
  EXPECT_EQ(m.Stats(t + 20ms).max_state_gap, 200ms);
}

TEST(SafetyMonitor, WhileHaltedForFaultSilenceIsReportedAndTheNextFaultIsToo) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  EXPECT_EQ(m.OnState(State(kFault, 1, 1), kT0 + 1ms).halt.reason, rc::HaltReason::kFault);
  EXPECT_EQ(m.OnState(State(kFault, 1, 2), kT0 + 11ms).kind, Kind::kNone);
  EXPECT_EQ(m.OnTick(kT0 + 42ms).halt.reason, rc::HaltReason::kNoHeartbeat);
  EXPECT_EQ(m.OnState(State(kFault, 1, 3), kT0 + 100ms).halt.reason, rc::HaltReason::kFault);
  EXPECT_TRUE(m.halted());
}

TEST(SafetyMonitor, AStreamThatNeverDeliversIsSilenceToo) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  EXPECT_EQ(m.OnTick(kT0 + 31ms).halt.reason, rc::HaltReason::kNoHeartbeat);
}

TEST(SafetyMonitor, StreamEndAndConnectFailureAreTold) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  const auto c = m.OnStreamEnded("UNAVAILABLE: failed to connect", kT0 + 1ms);
  ASSERT_EQ(c.kind, Kind::kHalt);
  EXPECT_EQ(c.halt.reason, rc::HaltReason::kConnectFailed);
  EXPECT_EQ(c.halt.detail, "no stream: UNAVAILABLE: failed to connect");
  // Repeated failures while already halted for that: no new decision.
  m.OnStreamOpened(kT0 + 100ms);
  EXPECT_EQ(m.OnStreamEnded("UNAVAILABLE", kT0 + 101ms).kind, Kind::kNone);
  // No watchdog while there is no stream, and none while halted for the link.
  EXPECT_EQ(m.OnTick(kT0 + 500ms).kind, Kind::kNone);
  m.OnStreamOpened(kT0 + 600ms);
  EXPECT_EQ(m.OnTick(kT0 + 700ms).kind, Kind::kNone);
  std::uint64_t seq = 0;
  const auto t = ClearUp(m, kT0 + 700ms, 1, seq);
  const auto e = m.OnStreamEnded("UNAVAILABLE: aggregator shutting down", t + 1ms);
  ASSERT_EQ(e.kind, Kind::kHalt);
  EXPECT_EQ(e.halt.reason, rc::HaltReason::kStreamEnded);
}

TEST(SafetyMonitor, AClearUnderANewEpochMeansAStopWasMissed) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 2, seq);
  // The states of epoch 3 (STOP, then its reset) were skipped: seq jumps, the epoch grew.
  seq += 5;
  const auto a = m.OnState(State(kClear, 3, ++seq), t + 10ms);
  ASSERT_EQ(a.kind, Kind::kHalt);
  EXPECT_EQ(a.halt.reason, rc::HaltReason::kMissedStop);
  EXPECT_EQ(m.Stats(t + 10ms).skipped_states, 5u);
  t = ClearUp(m, t + 10ms, 3, seq);
  EXPECT_FALSE(m.halted());
}

TEST(SafetyMonitor, ARestartedAggregatorCountsEpochsAgainWithoutAFalseMissedStop) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 5, seq);
  m.OnStreamEnded("UNAVAILABLE", t + 1ms);
  m.OnStreamOpened(t + 100ms);
  EXPECT_EQ(m.OnState(State(kFault, 1, 1, /*run=*/43), t + 101ms).halt.reason, rc::HaltReason::kFault);
  std::uint64_t seq2 = 1;
  t = t + 101ms;
  for (int i = 0; i < 2; ++i) EXPECT_EQ(m.OnState(State(kClear, 1, ++seq2, 43), t += 10ms).kind, Kind::kNone);
  EXPECT_EQ(m.OnState(State(kClear, 1, ++seq2, 43), t += 10ms).kind, Kind::kClear);
  EXPECT_EQ(m.Stats(t).skipped_states, 0u);
}

TEST(SafetyMonitor, TimeHaltedAddsUp) {
  rc::SafetyMonitor m({}, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 1, seq);  // halted 30 ms
  EXPECT_EQ(t, kT0 + 30ms);
  m.OnState(State(kStop, 2, ++seq), t + 100ms);
  EXPECT_EQ(m.Stats(t + 150ms).time_halted, 30ms + 50ms);
}

TEST(SafetyMonitor, TheTimeoutAndTheStreakAreConfigurable) {
  rc::SafetyMonitor m({.heartbeat_timeout = 50ms, .states_before_clear = 1}, kT0);
  m.OnStreamOpened(kT0);
  EXPECT_EQ(m.OnState(State(kClear, 1, 1), kT0 + 1ms).kind, Kind::kClear);
  EXPECT_EQ(m.OnTick(kT0 + 40ms).kind, Kind::kNone);
  EXPECT_EQ(m.OnTick(kT0 + 52ms).kind, Kind::kHalt);
}

TEST(SafetyMonitor, ReasonNames) {
  EXPECT_EQ(rc::HaltReasonName(rc::HaltReason::kNoHeartbeat), "NO_HEARTBEAT");
  EXPECT_EQ(rc::HaltReasonName(rc::HaltReason::kConnectFailed), "CONNECT_FAILED");
  EXPECT_EQ(rc::DescribeState(State(kFault, 1, 1)), "FAULT epoch 1 cause startup");
  EXPECT_EQ(rc::DescribeState(State(kClear, 4, 1)), "CLEAR epoch 4");
}

}  // namespace
