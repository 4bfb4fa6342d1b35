// The safety client's state machine (SafetyMonitor) without a network: every event carries an injected
// steady-clock time, so the watchdog's 30 ms is exact here.
#include <gtest/gtest.h>

#include <functional>

#include "ruffini/channel/crc.h"
#include "safety_client.h"

namespace {

using namespace std::chrono_literals;
namespace rc = ruffini::controller;
namespace v1 = ruffini::v1;
using Kind = rc::SafetyMonitor::Action::Kind;

const rc::SteadyClock::time_point kT0{std::chrono::seconds(1000)};

const std::string kRobot = "cobot";
const rc::MonitorConfig kConfig{.robot_name = kRobot};

v1::SafetyState State(v1::SafetyState::State s, std::uint64_t epoch, std::uint64_t seq, std::int64_t run = 42,
                      const std::string& robot = kRobot) {
  v1::SafetyState m;
  m.set_state(s);
  m.set_stop_epoch(epoch);
  m.set_seq(seq);
  m.set_aggregator_start_t_ns(run);
  m.set_aggregator_run_id(static_cast<std::uint64_t>(run) * 1000 + 7);
  m.set_robot_name(robot);
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
// The aggregator's part of the safety layer: a state sent at `t` (the test's clock stands for the
// aggregator's steady clock, so the learned offset is 0), sealed, and handed to the monitor at `t`.
rc::SafetyMonitor::Action Feed(rc::SafetyMonitor& m, v1::SafetyState s, rc::SteadyClock::time_point t) {
  s.set_sender_steady_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count());
  ruffini::channel::Seal(s);
  return m.OnState(s, t);
}
constexpr auto kClear = v1::SafetyState::STATE_CLEAR;
constexpr auto kStop = v1::SafetyState::STATE_STOP;
constexpr auto kFault = v1::SafetyState::STATE_FAULT;

// Feeds CLEAR states 10 ms apart until the monitor clears; returns the time of the clear.
rc::SteadyClock::time_point ClearUp(rc::SafetyMonitor& m, rc::SteadyClock::time_point t, std::uint64_t epoch,
                                    std::uint64_t& seq) {
  for (int i = 0; i < 10; ++i) {
    t += 10ms;
    if (Feed(m, State(kClear, epoch, ++seq), t).kind == Kind::kClear) return t;
  }
  ADD_FAILURE() << "never cleared";
  return t;
}

TEST(SafetyMonitor, StartsHaltedAndClearsOnlyAfterThreeClearStatesOnALiveStream) {
  rc::SafetyMonitor m(kConfig, kT0);
  EXPECT_TRUE(m.halted());
  EXPECT_EQ(m.reason(), rc::HaltReason::kNotStarted);
  m.OnStreamOpened(kT0);
  EXPECT_EQ(Feed(m, State(kClear, 1, 1), kT0 + 1ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, 2), kT0 + 11ms).kind, Kind::kNone);
  const auto a = Feed(m, State(kClear, 1, 3), kT0 + 21ms);
  ASSERT_EQ(a.kind, Kind::kClear);
  EXPECT_EQ(a.clear.halted_for, 21ms);
  EXPECT_FALSE(m.halted());
  EXPECT_EQ(m.Stats(kT0 + 30ms).clears, 1u);
}

TEST(SafetyMonitor, AStreamEndInTheMiddleOfTheClearStreakStartsItAgain) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  Feed(m, State(kClear, 1, 1), kT0 + 1ms);
  Feed(m, State(kClear, 1, 2), kT0 + 11ms);
  EXPECT_EQ(m.OnStreamEnded("UNAVAILABLE", kT0 + 12ms).kind, Kind::kHalt);
  m.OnStreamOpened(kT0 + 112ms);
  EXPECT_EQ(Feed(m, State(kClear, 1, 5), kT0 + 113ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, 6), kT0 + 123ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, 7), kT0 + 133ms).kind, Kind::kClear);
}

TEST(SafetyMonitor, StopHaltsAtOnceAndNamesTheCause) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 2, seq);
  const auto a = Feed(m, State(kStop, 3, ++seq), t + 10ms);
  ASSERT_EQ(a.kind, Kind::kHalt);
  EXPECT_EQ(a.halt.reason, rc::HaltReason::kStop);
  EXPECT_EQ(a.halt.detail, "STOP epoch 3 cause contact upper_arm_a 1.60 N > 1.50 N");
  EXPECT_EQ(a.halt.state.stop_epoch(), 3u);
  // The same STOP again (a heartbeat) is no new decision; a FAULT under a new epoch is.
  EXPECT_EQ(Feed(m, State(kStop, 3, ++seq), t + 20ms).kind, Kind::kNone);
  const auto f = Feed(m, State(kFault, 4, ++seq), t + 30ms);
  ASSERT_EQ(f.kind, Kind::kHalt);
  EXPECT_EQ(f.halt.reason, rc::HaltReason::kFault);
  // Another STOP epoch while halted for STOP is reported too.
  EXPECT_EQ(Feed(m, State(kStop, 5, ++seq), t + 40ms).halt.reason, rc::HaltReason::kStop);
  EXPECT_EQ(Feed(m, State(kStop, 6, ++seq), t + 50ms).kind, Kind::kHalt);
  const auto st = m.Stats(t + 50ms);
  EXPECT_EQ(st.halts[static_cast<int>(rc::HaltReason::kStop)], 3u);
  EXPECT_EQ(st.halts[static_cast<int>(rc::HaltReason::kFault)], 1u);
}

TEST(SafetyMonitor, AnUnknownStateIsAStop) {
  // Each value from a moving robot (a fresh, cleared monitor each): the halt is asserted for every value.
  for (int v : {0, 17, -3}) {
    SCOPED_TRACE(v);
    rc::SafetyMonitor m(kConfig, kT0);
    m.OnStreamOpened(kT0);
    std::uint64_t seq = 0;
    const auto t = ClearUp(m, kT0, 1, seq);
    ASSERT_FALSE(m.halted());
    v1::SafetyState s = State(kClear, 1, ++seq);
    // Through reflection: the setter refuses a value the enum does not name; the wire does not.
    s.GetReflection()->SetEnumValue(&s, s.GetDescriptor()->FindFieldByName("state"), v);
    const auto a = Feed(m, s, t + 10ms);
    EXPECT_TRUE(m.halted());
    ASSERT_EQ(a.kind, Kind::kHalt);
    EXPECT_EQ(a.halt.reason, rc::HaltReason::kUnknownState);
  }
}

TEST(SafetyMonitor, SilenceLongerThan30MsHaltsOnceThenAStateChangesTheReason) {
  rc::SafetyMonitor m(kConfig, kT0);
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
  // Heartbeats again: CLEAR needs its streak on the live stream, after the state that ended the silence.
  t += 200ms;
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t + 10ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t + 20ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t + 30ms).kind, Kind::kClear);
  EXPECT_EQ(m.Stats(t + 30ms).max_state_gap, 200ms);
}

TEST(SafetyMonitor, WhileHaltedForFaultSilenceIsReportedAndTheNextFaultIsToo) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  EXPECT_EQ(Feed(m, State(kFault, 1, 1), kT0 + 1ms).halt.reason, rc::HaltReason::kFault);
  EXPECT_EQ(Feed(m, State(kFault, 1, 2), kT0 + 11ms).kind, Kind::kNone);
  EXPECT_EQ(m.OnTick(kT0 + 42ms).halt.reason, rc::HaltReason::kNoHeartbeat);
  EXPECT_EQ(Feed(m, State(kFault, 1, 3), kT0 + 100ms).halt.reason, rc::HaltReason::kFault);
  EXPECT_TRUE(m.halted());
}

TEST(SafetyMonitor, AStreamThatNeverDeliversIsSilenceToo) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  EXPECT_EQ(m.OnTick(kT0 + 31ms).halt.reason, rc::HaltReason::kNoHeartbeat);
}

TEST(SafetyMonitor, StreamEndAndConnectFailureAreTold) {
  rc::SafetyMonitor m(kConfig, kT0);
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
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 2, seq);
  // The states of epoch 3 (STOP, then its reset) were skipped: seq jumps, the epoch grew.
  seq += 5;
  const auto a = Feed(m, State(kClear, 3, ++seq), t + 10ms);
  ASSERT_EQ(a.kind, Kind::kHalt);
  EXPECT_EQ(a.halt.reason, rc::HaltReason::kMissedStop);
  EXPECT_EQ(m.Stats(t + 10ms).skipped_states, 5u);
  t = ClearUp(m, t + 10ms, 3, seq);
  EXPECT_FALSE(m.halted());
}

TEST(SafetyMonitor, ARestartedAggregatorCountsEpochsAgainWithoutAFalseMissedStop) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 5, seq);
  m.OnStreamEnded("UNAVAILABLE", t + 1ms);
  m.OnStreamOpened(t + 100ms);
  EXPECT_EQ(Feed(m, State(kFault, 1, 1, /*run=*/43), t + 101ms).halt.reason, rc::HaltReason::kFault);
  std::uint64_t seq2 = 1;
  t = t + 101ms;
  for (int i = 0; i < 2; ++i) EXPECT_EQ(Feed(m, State(kClear, 1, ++seq2, 43), t += 10ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq2, 43), t += 10ms).kind, Kind::kClear);
  EXPECT_EQ(m.Stats(t).skipped_states, 0u);
}

TEST(SafetyMonitor, TimeHaltedAddsUp) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 1, seq);  // halted 30 ms
  EXPECT_EQ(t, kT0 + 30ms);
  Feed(m, State(kStop, 2, ++seq), t + 100ms);
  EXPECT_EQ(m.Stats(t + 150ms).time_halted, 30ms + 50ms);
}

TEST(SafetyMonitor, TheTimeoutAndTheStreakAreConfigurable) {
  rc::SafetyMonitor m({.robot_name = kRobot, .heartbeat_timeout = 50ms, .states_before_clear = 1}, kT0);
  m.OnStreamOpened(kT0);
  EXPECT_EQ(Feed(m, State(kClear, 1, 1), kT0 + 1ms).kind, Kind::kClear);
  EXPECT_EQ(m.OnTick(kT0 + 40ms).kind, Kind::kNone);
  EXPECT_EQ(m.OnTick(kT0 + 52ms).kind, Kind::kHalt);
}

// Finding 8: the three-clean-states rule after every halt, a halt for the link included. Before, OnTick
// returned early while halted for NO_HEARTBEAT, so the streak survived the silence and three CLEARs spread
// over seconds released the robot.
TEST(SafetyMonitor, AfterALinkHaltCleanStatesMustFollowEachOtherWithinTheWatchdog) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 1, seq);
  EXPECT_EQ(m.OnTick(t + 31ms).halt.reason, rc::HaltReason::kNoHeartbeat);
  // CLEARs one second apart, the watchdog ticking in between as the client's does: never a clear.
  for (int i = 0; i < 6; ++i) {
    t += 1s;
    EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t).kind, Kind::kNone) << i;
    EXPECT_EQ(m.OnTick(t + 31ms).kind, Kind::kNone);  // told once
  }
  EXPECT_TRUE(m.halted());
  // Then three within the watchdog after the late one: released.
  t += 1s;
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t + 10ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t + 20ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t + 30ms).kind, Kind::kClear);
}

// The same rule when no watchdog tick came in between (a starved watchdog thread): a late CLEAR starts the
// streak again by itself.
TEST(SafetyMonitor, LateCleanStatesDoNotAddUpEvenWithoutAWatchdogTick) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 1, seq);
  EXPECT_EQ(Feed(m, State(kStop, 2, ++seq), t + 10ms).halt.reason, rc::HaltReason::kStop);
  t += 10ms;
  for (int i = 0; i < 10; ++i) EXPECT_NE(Feed(m, State(kClear, 2, ++seq), t += 31ms).kind, Kind::kClear) << i;
  EXPECT_EQ(m.reason(), rc::HaltReason::kNoHeartbeat);  // the late state itself tells of the silence
  // The late CLEAR is not clean itself; three more within the watchdog (30 ms exactly is within) release.
  EXPECT_EQ(Feed(m, State(kClear, 2, ++seq), t += 30ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 2, ++seq), t += 30ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 2, ++seq), t += 30ms).kind, Kind::kClear);
}

TEST(SafetyMonitor, AStateForAnotherRobotIsDiscardedCountedAndHalts) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 1, seq);
  const auto a = Feed(m, State(kClear, 1, ++seq, 42, "other-cell"), t += 10ms);
  ASSERT_EQ(a.kind, Kind::kHalt);
  EXPECT_EQ(a.halt.reason, rc::HaltReason::kWrongRobot);
  EXPECT_EQ(a.halt.state.robot_name(), "other-cell");
  EXPECT_EQ(a.halt.detail, "a state for robot 'other-cell', not this controller's 'cobot'");
  // An empty name (an aggregator that does not fill it) is another robot too; CLEARs from it never release.
  for (int i = 0; i < 10; ++i) {
    const auto b = Feed(m, State(kClear, 1, ++seq, 42, ""), t += 10ms);
    EXPECT_NE(b.kind, Kind::kClear);
  }
  EXPECT_TRUE(m.halted());
  EXPECT_EQ(m.reason(), rc::HaltReason::kWrongRobot);
  auto st = m.Stats(t);
  EXPECT_EQ(st.discarded, 11u);
  EXPECT_EQ(st.discarded_by[static_cast<int>(rc::HaltReason::kWrongRobot)], 11u);
  // Told when it began and once more when the second one latched the error-rate rule, not for every state.
  EXPECT_EQ(st.halts[static_cast<int>(rc::HaltReason::kWrongRobot)], 2u);
  EXPECT_EQ(st.last_state.robot_name(), kRobot);                          // discarded states are not kept
  // A discarded state is no heartbeat: the watchdog counts from the last accepted one.
  EXPECT_GT(m.Silence(t), 30ms);
  // Misaddressed states are identity errors of the safety layer: past the error-rate limit (two within the
  // window) no state of this stream is used, our robot's included (docs/safety-channel.md).
  EXPECT_NE(Feed(m, State(kClear, 1, ++seq), t += 10ms).kind, Kind::kClear);
  EXPECT_TRUE(m.halted());
  EXPECT_EQ(m.Stats(t).discarded_by[static_cast<int>(rc::HaltReason::kLinkError)], 1u);
  // A new stream does not release it (the latch outlives streams); an operator's acknowledgement does, then
  // three clean states.
  m.OnStreamEnded("CANCELLED", t += 1ms);
  m.OnStreamOpened(t += 100ms);
  for (int i = 0; i < 5; ++i) EXPECT_NE(Feed(m, State(kClear, 1, ++seq), t += 10ms).kind, Kind::kClear);
  EXPECT_TRUE(m.link_errors_latched());
  m.AcknowledgeLinkErrors();
  t = ClearUp(m, t, 1, seq);
  EXPECT_FALSE(m.halted());
  st = m.Stats(t);
  EXPECT_EQ(st.discarded, 17u);
  EXPECT_EQ(st.states, seq);
  EXPECT_EQ(st.link_errors[ruffini::channel::Error::kAddressing], 11u);
}

TEST(SafetyMonitor, TheRobotNameIsRequired) {
  EXPECT_THROW(rc::SafetyMonitor(rc::MonitorConfig{}, kT0), std::invalid_argument);
}

// A new aggregator_run_id is a restart even if the start time is the same (and the other way round): the
// epochs start again, and the robot halts until three clean states of the new run.
TEST(SafetyMonitor, ACleanStateFromANewRunHaltsUntilThreeCleanStatesOfThatRun) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 6, seq);
  v1::SafetyState s = State(kClear, 6, ++seq);
  s.set_aggregator_run_id(s.aggregator_run_id() + 1);
  // Within one stream another run's state is an insertion (the safety layer discards it); a new run comes
  // on a new stream (the old aggregator's stream ended).
  EXPECT_EQ(Feed(m, s, t += 10ms).halt.reason, rc::HaltReason::kLinkError);
  m.OnStreamEnded("UNAVAILABLE", t += 1ms);
  m.OnStreamOpened(t += 1ms);
  t = ClearUp(m, t, 6, seq);
  EXPECT_FALSE(m.halted()) << "the same run on a new stream: three clean states";
  m.OnStreamEnded("UNAVAILABLE", t += 1ms);
  m.OnStreamOpened(t += 1ms);
  s.set_seq(++seq);
  const auto a = Feed(m, s, t += 10ms);
  ASSERT_EQ(a.kind, Kind::kHalt);
  EXPECT_EQ(a.halt.reason, rc::HaltReason::kNewRun);
  for (int i = 0; i < 2; ++i) {
    s.set_seq(++seq);
    EXPECT_EQ(Feed(m, s, t += 10ms).kind, Kind::kNone);
  }
  s.set_seq(++seq);
  EXPECT_EQ(Feed(m, s, t += 10ms).kind, Kind::kClear);  // three clean states of the new run after the halt
  // Now the start time alone changes.
  s.set_aggregator_start_t_ns(s.aggregator_start_t_ns() + 1);
  s.set_stop_epoch(1);
  s.set_seq(++seq);
  EXPECT_EQ(Feed(m, s, t += 10ms).halt.reason, rc::HaltReason::kNewRun);
}

TEST(SafetyMonitor, AClearUnderANewEpochIsAMissedStopWhileHaltedToo) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 2, seq);
  EXPECT_EQ(Feed(m, State(kStop, 3, ++seq), t += 10ms).halt.reason, rc::HaltReason::kStop);
  // Epoch 4's STOP and its reset were skipped: the CLEAR of epoch 4 is a missed stop, and the streak starts after it.
  EXPECT_EQ(Feed(m, State(kClear, 4, ++seq), t += 10ms).halt.reason, rc::HaltReason::kMissedStop);
  EXPECT_EQ(Feed(m, State(kClear, 4, ++seq), t += 10ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 4, ++seq), t += 10ms).kind, Kind::kNone);
  EXPECT_EQ(Feed(m, State(kClear, 4, ++seq), t += 10ms).kind, Kind::kClear);
}

TEST(SafetyMonitor, ReasonNames) {
  EXPECT_EQ(rc::HaltReasonName(rc::HaltReason::kWrongRobot), "WRONG_ROBOT");
  EXPECT_EQ(rc::HaltReasonName(rc::HaltReason::kNewRun), "NEW_RUN");
  EXPECT_EQ(rc::HaltReasonName(rc::HaltReason::kNoHeartbeat), "NO_HEARTBEAT");
  EXPECT_EQ(rc::HaltReasonName(rc::HaltReason::kConnectFailed), "CONNECT_FAILED");
  EXPECT_EQ(rc::DescribeState(State(kFault, 1, 1)), "FAULT epoch 1 cause startup");
  EXPECT_EQ(rc::DescribeState(State(kClear, 4, 1)), "CLEAR epoch 4");
}

}  // namespace

// The safety layer at the controller (docs/safety-channel.md), one row per error: what the client does.
TEST(SafetyMonitorLink, EachErrorOnTheStateLinkIsDetectedCountedAndAnsweredAsStated) {
  using ruffini::channel::Error;
  struct Row {
    const char* what;
    Error error;
    rc::HaltReason halt;  // kNotStarted: no halt (tolerated)
    std::function<v1::SafetyState(v1::SafetyState, std::uint64_t& seq, rc::SteadyClock::time_point t)> alter;
  };
  auto sealed_at = [](v1::SafetyState s, rc::SteadyClock::time_point sent) {
    s.set_sender_steady_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(sent.time_since_epoch()).count());
    ruffini::channel::Seal(s);
    return s;
  };
  const std::vector<Row> rows = {
      {"a STOP corrupted into a CLEAR", Error::kCorruption, rc::HaltReason::kLinkError,
       [&](v1::SafetyState s, std::uint64_t&, rc::SteadyClock::time_point t) {
         s.set_state(kStop);
         s = sealed_at(s, t);
         s.set_state(kClear);
         return s;
       }},
      {"the previous state again", Error::kRepetition, rc::HaltReason::kLinkError,
       [&](v1::SafetyState s, std::uint64_t& seq, rc::SteadyClock::time_point t) {
         s.set_seq(seq);  // not advanced
         return sealed_at(s, t);
       }},
      {"an older state", Error::kIncorrectSequence, rc::HaltReason::kLinkError,
       [&](v1::SafetyState s, std::uint64_t& seq, rc::SteadyClock::time_point t) {
         s.set_seq(seq - 1);
         return sealed_at(s, t);
       }},
      {"states skipped", Error::kLoss, rc::HaltReason::kNotStarted,
       [&](v1::SafetyState s, std::uint64_t& seq, rc::SteadyClock::time_point t) {
         seq += 3;
         s.set_seq(seq);
         return sealed_at(s, t);
       }},
      {"a CLEAR 25 ms old", Error::kDelay, rc::HaltReason::kLate,
       [&](v1::SafetyState s, std::uint64_t& seq, rc::SteadyClock::time_point t) {
         s.set_seq(++seq);
         return sealed_at(s, t - 25ms);
       }},
      {"a state of another aggregator run", Error::kInsertion, rc::HaltReason::kLinkError,
       [&](v1::SafetyState s, std::uint64_t& seq, rc::SteadyClock::time_point t) {
         s.set_seq(seq + 1);
         s.set_aggregator_run_id(s.aggregator_run_id() ^ 0xFF);
         return sealed_at(s, t);
       }},
      {"a state for another robot", Error::kAddressing, rc::HaltReason::kWrongRobot,
       [&](v1::SafetyState s, std::uint64_t& seq, rc::SteadyClock::time_point t) {
         s.set_seq(seq + 1);
         s.set_robot_name("other-cell");
         return sealed_at(s, t);
       }},
  };
  for (const Row& row : rows) {
    SCOPED_TRACE(row.what);
    rc::SafetyMonitor m(kConfig, kT0);
    m.OnStreamOpened(kT0);
    std::uint64_t seq = 0;
    auto t = ClearUp(m, kT0, 1, seq);
    ASSERT_FALSE(m.halted());
    const v1::SafetyState bad = row.alter(State(kClear, 1, seq), seq, t += 10ms);
    const auto a = m.OnState(bad, t);
    EXPECT_EQ(m.Stats(t).link_errors[row.error], 1u);
    if (row.halt == rc::HaltReason::kNotStarted) {
      EXPECT_FALSE(m.halted()) << "tolerated";
      EXPECT_NE(a.kind, Kind::kHalt);
    } else {
      ASSERT_EQ(a.kind, Kind::kHalt);
      EXPECT_EQ(a.halt.reason, row.halt);
      EXPECT_TRUE(m.halted());
      // Three good states later (not counting the one seq the error may have used) the robot may move.
      seq = std::max(seq, bad.seq());
      t = ClearUp(m, t, 1, seq);
      EXPECT_FALSE(m.halted());
    }
  }
}

TEST(SafetyMonitorLink, TwoErrorsWithinTheWindowLatchUntilAnOperatorAcknowledgesEvenAcrossStreams) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 1, seq);
  EXPECT_EQ(Feed(m, State(kClear, 1, seq), t += 10ms).halt.reason, rc::HaltReason::kLinkError);
  t = ClearUp(m, t, 1, seq);
  EXPECT_FALSE(m.halted()) << "one error: discarded, three clean states release";
  EXPECT_EQ(Feed(m, State(kClear, 1, seq), t += 10ms).halt.reason, rc::HaltReason::kLinkError);
  for (int i = 0; i < 10; ++i) EXPECT_NE(Feed(m, State(kClear, 1, ++seq), t += 10ms).kind, Kind::kClear);
  EXPECT_TRUE(m.halted()) << "the second error within the window: no state is used";
  m.OnStreamEnded("CANCELLED", t += 1ms);
  m.OnStreamOpened(t += 1ms);
  for (int i = 0; i < 5; ++i) EXPECT_NE(Feed(m, State(kClear, 1, ++seq), t += 10ms).kind, Kind::kClear);
  EXPECT_TRUE(m.halted()) << "a new stream does not forget: the latch waits for an operator";
  m.AcknowledgeLinkErrors();
  t = ClearUp(m, t, 1, seq);
  EXPECT_FALSE(m.halted());
}

// The latch is told even when the halt's reason does not change (two errors in a row), and the operator's
// acknowledgement says whether a latch was held (ruffini-controller's SIGUSR1 prints it).
TEST(SafetyMonitorLink, TheLatchIsToldAndTheAcknowledgementSaysWhetherOneWasHeld) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 0;
  auto t = ClearUp(m, kT0, 1, seq);
  const auto first = Feed(m, State(kClear, 1, seq), t += 10ms);  // a repetition
  ASSERT_EQ(first.kind, Kind::kHalt);
  EXPECT_FALSE(first.halt.link_errors_latched);
  const auto second = Feed(m, State(kClear, 1, seq), t += 10ms);  // again: LINK_ERROR again, now latched
  ASSERT_EQ(second.kind, Kind::kHalt) << "the latch is a new decision although the reason is the same";
  EXPECT_EQ(second.halt.reason, rc::HaltReason::kLinkError);
  EXPECT_TRUE(second.halt.link_errors_latched);
  EXPECT_EQ(Feed(m, State(kClear, 1, ++seq), t += 10ms).kind, Kind::kNone) << "told once";
  EXPECT_TRUE(m.Stats(t).link_errors_latched);
  EXPECT_TRUE(m.AcknowledgeLinkErrors());
  EXPECT_FALSE(m.AcknowledgeLinkErrors()) << "nothing held any more";
  const auto st = m.Stats(t);
  EXPECT_FALSE(st.link_errors_latched);
  EXPECT_EQ(st.link_acknowledgements, 1u);
  t = ClearUp(m, t, 1, seq);
  EXPECT_FALSE(m.halted());
}

// Review (helper-5) finding 2: a replay of older states of the same aggregator run on a new stream (STOP in
// force at a newer seq) is an incorrect sequence, never three clean CLEARs.
// A state sent at `sent`, arriving at `arrival` (a delayed link).
rc::SafetyMonitor::Action FeedLate(rc::SafetyMonitor& m, v1::SafetyState s, rc::SteadyClock::time_point sent,
                                   rc::SteadyClock::time_point arrival) {
  s.set_sender_steady_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(sent.time_since_epoch()).count());
  ruffini::channel::Seal(s);
  return m.OnState(s, arrival);
}

// Review of issue 15, F2: a delay that halted one stream must not become the next stream's "on time". The
// client re-creates its stream after the halt; the aggregator run is the same, so its clock offset is kept and
// the still-delayed states are still late.
TEST(SafetyMonitorLink, ADelayIsNotRelearnedAsOnTimeOnTheNextStreamOfTheSameRun) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 100;
  auto t = ClearUp(m, kT0, 1, seq);
  // From here every state arrives 80 ms after it was sent (budget 20 ms).
  EXPECT_EQ(FeedLate(m, State(kClear, 1, ++seq), t, t + 80ms).halt.reason, rc::HaltReason::kLate);
  t += 80ms;
  m.OnStreamEnded("CANCELLED", t += 1ms);
  m.OnStreamOpened(t += 1ms);
  for (int i = 0; i < 6; ++i) {
    t += 10ms;
    EXPECT_NE(FeedLate(m, State(kClear, 1, ++seq), t - 80ms, t).kind, Kind::kClear) << i;
  }
  EXPECT_TRUE(m.halted());
  // A new aggregator run (a restart) starts its clock anew: on time from its first state.
  m.AcknowledgeLinkErrors();
  m.OnStreamEnded("UNAVAILABLE", t += 1ms);
  m.OnStreamOpened(t += 1ms);
  std::uint64_t seq2 = 1;
  for (int i = 0; i < 5; ++i) Feed(m, State(kClear, 1, seq2++, 43), t += 10ms);
  EXPECT_FALSE(m.halted());
}

// Review of issue 15, F3: after a restart, a recording of the older run replayed (the live run in FAULT)
// never releases the robot: a run a newer run replaced is never believed again.
TEST(SafetyMonitorLink, ARecordedOlderRunReplayedAfterARestartNeverReleases) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 100;
  auto t = ClearUp(m, kT0, 2, seq);  // run 42, CLEAR epoch 2
  m.OnStreamEnded("UNAVAILABLE", t += 1ms);
  m.OnStreamOpened(t += 1ms);
  std::uint64_t seq_b = 1;
  Feed(m, State(kFault, 1, seq_b++, 43), t += 10ms);  // the restarted aggregator: FAULT (start-up)
  Feed(m, State(kFault, 1, seq_b++, 43), t += 10ms);
  EXPECT_TRUE(m.halted());
  m.OnStreamEnded("CANCELLED", t += 1ms);
  m.OnStreamOpened(t += 1ms);
  // Run 42's CLEARs, sealed and fresh-looking, with seqs it never sent before.
  for (int i = 0; i < 8; ++i) EXPECT_NE(Feed(m, State(kClear, 2, ++seq, 42), t += 10ms).kind, Kind::kClear) << i;
  EXPECT_TRUE(m.halted());
  EXPECT_GE(m.Stats(t).link_errors[ruffini::channel::Error::kInsertion], 1u);
}

TEST(SafetyMonitorLink, AReplayOfOlderStatesOnANewStreamIsRefused) {
  rc::SafetyMonitor m(kConfig, kT0);
  m.OnStreamOpened(kT0);
  std::uint64_t seq = 100;
  auto t = ClearUp(m, kT0, 1, seq);
  EXPECT_EQ(Feed(m, State(kStop, 2, ++seq), t += 10ms).halt.reason, rc::HaltReason::kStop);
  m.OnStreamEnded("CANCELLED", t += 1ms);
  m.OnStreamOpened(t += 1ms);
  // The recorded CLEARs of epoch 1 (seq 101..) replayed.
  std::uint64_t old_seq = 100;
  for (int i = 0; i < 6; ++i) EXPECT_NE(Feed(m, State(kClear, 1, ++old_seq), t += 10ms).kind, Kind::kClear);
  EXPECT_TRUE(m.halted());
  EXPECT_GE(m.Stats(t).link_errors[ruffini::channel::Error::kIncorrectSequence], 1u);
}
