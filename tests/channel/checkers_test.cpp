// The safety layer's receivers, one test per rule: sequence, freshness, the error-rate rule, and each of
// the eight communication errors on both links with its stated reaction (docs/safety-channel.md).
#include <limits>
#include <stdexcept>

#include <gtest/gtest.h>

#include "ruffini/channel/checkers.h"
#include "ruffini/channel/crc.h"

namespace ruffini::channel {
namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr std::uint64_t kAggRun = 0xA66A66;
constexpr std::uint64_t kDecRun = 0xDEC0DE;

TEST(Sequence, NextGapRepeatOld) {
  SequenceCheck s;
  EXPECT_EQ(s.Check(1), SeqVerdict::kNext);
  EXPECT_EQ(s.Check(2), SeqVerdict::kNext);
  EXPECT_EQ(s.Check(2), SeqVerdict::kRepeat);
  EXPECT_EQ(s.Check(1), SeqVerdict::kOld);
  EXPECT_EQ(s.Check(0), SeqVerdict::kOld);
  EXPECT_EQ(s.last(), 2u);
  EXPECT_EQ(s.Check(5), SeqVerdict::kGap);
  EXPECT_EQ(s.skipped(), 2u);
  EXPECT_EQ(s.Check(6), SeqVerdict::kNext);
  EXPECT_EQ(s.Check(std::numeric_limits<std::uint64_t>::max()), SeqVerdict::kGap);
  EXPECT_EQ(s.Check(7), SeqVerdict::kOld);
}

TEST(Sequence, AJoiningStreamStartsAnywhere) {
  SequenceCheck s;
  EXPECT_EQ(s.CheckJoining(1000), SeqVerdict::kNext);
  EXPECT_EQ(s.CheckJoining(1001), SeqVerdict::kNext);
  EXPECT_EQ(s.CheckJoining(1001), SeqVerdict::kRepeat);
  SequenceCheck z;
  EXPECT_EQ(z.CheckJoining(0), SeqVerdict::kOld);
}

TEST(Freshness, ConstantLatencyIsAgeZeroAndQueueingIsAge) {
  FreshnessCheck f({.budget_ns = 20 * kMs, .max_drift_ppm = 0});
  // Sender clock 1e12 ahead of the receiver's; a constant 0.3 ms wire.
  const std::int64_t skew = 1'000'000'000'000;
  EXPECT_EQ(f.Age(skew + 0, 300'000), 0);
  EXPECT_EQ(f.Age(skew + 1 * kMs, 1 * kMs + 300'000), 0);
  EXPECT_EQ(f.Age(skew + 2 * kMs, 2 * kMs + 300'000 + 25 * kMs), 25 * kMs);
  EXPECT_TRUE(f.Late(25 * kMs));
  EXPECT_FALSE(f.Late(20 * kMs));
  // A faster message lowers the learned offset.
  EXPECT_EQ(f.Age(skew + 3 * kMs, 3 * kMs + 100'000), 0);
  EXPECT_EQ(f.Age(skew + 4 * kMs, 4 * kMs + 300'000), 200'000);
}

TEST(Freshness, AThrottledLinkGrowsOlderUntilLate) {
  FreshnessCheck f({.budget_ns = 20 * kMs, .max_drift_ppm = 200});
  // Messages every 1 ms, each delivered 10 % slower than sent (a link that falls behind).
  bool late = false;
  int late_at = -1;
  for (int i = 0; i < 1000 && !late; ++i) {
    const std::int64_t sent = i * kMs;
    const std::int64_t arrival = static_cast<std::int64_t>(i * kMs * 1.1) + 500'000;
    late = f.Late(f.Age(sent, arrival));
    if (late) late_at = i;
  }
  ASSERT_TRUE(late);
  EXPECT_NEAR(late_at, 201, 3) << "20 ms of lag at 0.1 ms per message (less the allowed creep)";
}

TEST(Freshness, AllowedDriftIsNotAge) {
  FreshnessCheck f({.budget_ns = 20 * kMs, .max_drift_ppm = 200});
  // The sender's clock runs 150 ppm slow for an hour of messages at 10 Hz: never late.
  std::int64_t worst = 0;
  for (int i = 0; i < 36'000; ++i) {
    const std::int64_t arrival = static_cast<std::int64_t>(i) * 100 * kMs;
    const auto sent = static_cast<std::int64_t>(static_cast<double>(arrival) * (1 - 150e-6));
    worst = std::max(worst, f.Age(sent, arrival));
  }
  EXPECT_LT(worst, 1 * kMs);
}

TEST(Freshness, ExtremesSaturateInsteadOfOverflowing) {
  constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
  constexpr std::int64_t kMin = std::numeric_limits<std::int64_t>::min();
  FreshnessCheck f({.budget_ns = 20 * kMs});
  EXPECT_EQ(f.Age(kMin, kMax), 0) << "the first message sets the offset (saturated)";
  EXPECT_EQ(f.Age(0, 0), 0) << "a faster message than a far-past stamp lowers the offset: not late";
  // A forged stamp from the far future looks like the fastest message ever: every genuine message after it
  // is then late (fails safe), and nothing overflows.
  FreshnessCheck g({.budget_ns = 20 * kMs});
  EXPECT_EQ(g.Age(0, 0), 0);
  EXPECT_EQ(g.Age(kMax, 1), 0);
  EXPECT_EQ(g.offset_ns(), 1 - kMax);
  EXPECT_EQ(g.Age(2, 2), kMax - 1);
  EXPECT_TRUE(g.Late(g.Age(3, 3)));
}

TEST(Freshness, BadConfigIsRefused) {
  EXPECT_THROW(FreshnessCheck({.budget_ns = 0}), std::invalid_argument);
  EXPECT_THROW(FreshnessCheck({.budget_ns = 1, .max_drift_ppm = -1}), std::invalid_argument);
  EXPECT_THROW(ErrorRate({.window_ns = 0}), std::invalid_argument);
  EXPECT_THROW(ErrorRate({.window_ns = 1, .limit = 9}), std::invalid_argument);
}

TEST(ErrorRate, TwoWithinTheWindowLatch) {
  ErrorRate r({.window_ns = 1000 * kMs, .limit = 2});
  EXPECT_FALSE(r.Record(0));
  EXPECT_FALSE(r.Record(1500 * kMs)) << "1.5 s after the first: outside the window";
  EXPECT_TRUE(r.Record(2000 * kMs));
  ErrorRate one({.window_ns = kMs, .limit = 1});
  EXPECT_TRUE(one.Record(5));
  ErrorRate three({.window_ns = 10 * kMs, .limit = 3});
  EXPECT_FALSE(three.Record(0));
  EXPECT_FALSE(three.Record(1 * kMs));
  EXPECT_TRUE(three.Record(2 * kMs));
  for (int i = 0; i < 20; ++i) three.Record(100 * kMs * (i + 1));  // the ring wraps
  EXPECT_FALSE(three.Record(5000 * kMs));
}

// ---- the decoder -> aggregator link -------------------------------------------------------------------
class PatchLink : public ::testing::Test {
 protected:
  v1::PatchMessage Msg(std::uint64_t seq, std::int64_t sent_ns, bool hello = false) {
    v1::PatchMessage m;
    m.set_patch_id("forearm_a");
    m.set_seq(seq);
    m.set_sender_run_id(kDecRun);
    m.set_sender_steady_ns(sent_ns);
    if (hello) {
      m.mutable_hello()->set_patch_name("forearm");
    } else {
      m.set_aggregator_run_id(kAggRun);
      m.mutable_heartbeat()->set_healthy(true);
    }
    Seal(m);
    return m;
  }
  // A healthy start: hello then two heartbeats, 1 ms apart, 0.2 ms on the wire.
  void Start() {
    ASSERT_FALSE(check.Receive(Msg(1, 0, true), 200'000).error);
    ASSERT_FALSE(check.Receive(Msg(2, kMs), kMs + 200'000).error);
    ASSERT_FALSE(check.Receive(Msg(3, 2 * kMs), 2 * kMs + 200'000).error);
  }
  PatchLinkCheck check{LinkConfig{.freshness = {.budget_ns = 20 * kMs}, .error_rate = {.window_ns = 1000 * kMs}},
                       kAggRun, "forearm_a"};
};

TEST_F(PatchLink, AHealthyStreamHasNoError) {
  Start();
  for (int i = 4; i < 100; ++i) {
    const Verdict v = check.Receive(Msg(static_cast<std::uint64_t>(i), i * kMs), i * kMs + 300'000);
    EXPECT_TRUE(v.use);
    EXPECT_FALSE(v.error);
  }
  EXPECT_EQ(check.counts().total(), 0u);
  EXPECT_EQ(check.sender_run_id(), kDecRun);
}

TEST_F(PatchLink, Corruption) {
  Start();
  v1::PatchMessage m = Msg(4, 3 * kMs);
  m.mutable_heartbeat()->set_healthy(false);  // a flipped field, CRC not resealed
  const Verdict v = check.Receive(m, 3 * kMs + 200'000);
  EXPECT_FALSE(v.use);
  EXPECT_EQ(v.kind, Error::kCorruption);
  EXPECT_FALSE(v.latch) << "one error: discard and count";
  EXPECT_EQ(check.counts()[Error::kCorruption], 1u);
  // The discarded message leaves a gap: the next one is a loss, and a loss latches.
  const Verdict next = check.Receive(Msg(5, 4 * kMs), 4 * kMs + 200'000);
  EXPECT_TRUE(next.use);
  EXPECT_EQ(next.kind, Error::kLoss);
  EXPECT_TRUE(next.latch);
  EXPECT_TRUE(next.rate_latch) << "two errors within the window";
}

TEST_F(PatchLink, RepetitionThenTheErrorRateRule) {
  Start();
  const Verdict v = check.Receive(Msg(3, 2 * kMs), 3 * kMs);
  EXPECT_FALSE(v.use);
  EXPECT_EQ(v.kind, Error::kRepetition);
  EXPECT_FALSE(v.latch);
  EXPECT_FALSE(check.Receive(Msg(4, 3 * kMs), 3 * kMs + 200'000).error) << "the stream goes on";
  const Verdict second = check.Receive(Msg(4, 3 * kMs), 4 * kMs);
  EXPECT_EQ(second.kind, Error::kRepetition);
  EXPECT_TRUE(second.latch) << "two errors within 1 s latch";
  EXPECT_TRUE(second.rate_latch);
}

TEST_F(PatchLink, IncorrectSequence) {
  Start();
  const Verdict v = check.Receive(Msg(2, kMs), 3 * kMs);
  EXPECT_FALSE(v.use);
  EXPECT_EQ(v.kind, Error::kIncorrectSequence);
}

TEST_F(PatchLink, LossLatchesAndTheContentIsStillUsed) {
  Start();
  const Verdict v = check.Receive(Msg(6, 5 * kMs), 5 * kMs + 200'000);
  EXPECT_TRUE(v.use) << "this message may be the STOP: act on it";
  EXPECT_EQ(v.kind, Error::kLoss);
  EXPECT_TRUE(v.latch) << "a lost contact message is not tolerable";
}

TEST_F(PatchLink, DelayLatchesAndTheContentIsStillUsed) {
  Start();
  const Verdict ok = check.Receive(Msg(4, 3 * kMs), 3 * kMs + 200'000 + 19 * kMs);
  EXPECT_FALSE(ok.error) << "19 ms old: within the 20 ms budget";
  const Verdict v = check.Receive(Msg(5, 4 * kMs), 4 * kMs + 200'000 + 21 * kMs);
  EXPECT_TRUE(v.use);
  EXPECT_EQ(v.kind, Error::kDelay);
  EXPECT_TRUE(v.latch);
  EXPECT_NEAR(static_cast<double>(v.age_ns), 21e6, 10e3) << "less the allowed 200 ppm creep";
}

// Review of issue 15, F1: the stream a delay ended hands its sender's clock to the next stream of the same
// sender run; the delayed hello that opens it is late, not the new "on time". Another sender run (a restarted
// decoder) starts anew.
TEST_F(PatchLink, TheNextStreamOfTheSameSenderKeepsTheLearnedClock) {
  Start();
  const std::int64_t offset = check.freshness().offset_ns(), last = check.freshness().last_arrival_ns();
  PatchLinkCheck next{LinkConfig{.freshness = {.budget_ns = 20 * kMs}, .error_rate = {.window_ns = 1000 * kMs}},
                      kAggRun, "forearm_a"};
  next.RememberSender(kDecRun, offset, last);
  const Verdict v = next.Receive(Msg(1, 500 * kMs, true), 500 * kMs + 200'000 + 300 * kMs);  // 300 ms on the wire
  EXPECT_EQ(v.kind, Error::kDelay);
  EXPECT_NEAR(static_cast<double>(v.age_ns), 300e6, 1e6);

  PatchLinkCheck other{LinkConfig{.freshness = {.budget_ns = 20 * kMs}, .error_rate = {.window_ns = 1000 * kMs}},
                       kAggRun, "forearm_a"};
  other.RememberSender(kDecRun + 1, offset, last);  // not this sender's run
  EXPECT_FALSE(other.Receive(Msg(1, 500 * kMs, true), 500 * kMs + 200'000 + 300 * kMs).error);
}

TEST_F(PatchLink, Insertion) {
  Start();
  v1::PatchMessage m = Msg(4, 3 * kMs);
  m.set_sender_run_id(kDecRun + 1);  // another decoder process's message
  Seal(m);
  const Verdict v = check.Receive(m, 3 * kMs + 200'000);
  EXPECT_FALSE(v.use);
  EXPECT_EQ(v.kind, Error::kInsertion);
  v1::PatchMessage zero = Msg(4, 3 * kMs);
  zero.set_sender_run_id(0);
  Seal(zero);
  EXPECT_EQ(check.Receive(zero, 3 * kMs + 200'000).kind, Error::kInsertion);
}

TEST_F(PatchLink, Masquerade) {
  Start();
  v1::PatchMessage m = Msg(4, 3 * kMs);
  m.set_patch_id("forearm_b");
  Seal(m);
  const Verdict v = check.Receive(m, 3 * kMs + 200'000);
  EXPECT_FALSE(v.use);
  EXPECT_EQ(v.kind, Error::kMasquerade);
}

TEST_F(PatchLink, Addressing) {
  Start();
  v1::PatchMessage m = Msg(4, 3 * kMs);
  m.set_aggregator_run_id(kAggRun + 1);  // meant for another aggregator run
  Seal(m);
  const Verdict v = check.Receive(m, 3 * kMs + 200'000);
  EXPECT_FALSE(v.use);
  EXPECT_EQ(v.kind, Error::kAddressing);
  // A hello may be addressed to nobody in particular (0) or to this run, not to another.
  PatchLinkCheck fresh{LinkConfig{}, kAggRun, "forearm_a"};
  v1::PatchMessage hello = Msg(1, 0, true);
  hello.set_aggregator_run_id(7);
  Seal(hello);
  EXPECT_EQ(fresh.Receive(hello, 0).kind, Error::kAddressing);
}

// ---- the aggregator -> controller link ----------------------------------------------------------------
class StateLink : public ::testing::Test {
 protected:
  v1::SafetyState State(std::uint64_t seq, std::int64_t sent_ns, v1::SafetyState::State st = v1::SafetyState::STATE_CLEAR) {
    v1::SafetyState s;
    s.set_state(st);
    s.set_stop_epoch(2);
    s.set_seq(seq);
    s.set_aggregator_run_id(kAggRun);
    s.set_robot_name("cobot");
    s.set_sender_steady_ns(sent_ns);
    Seal(s);
    return s;
  }
  void Start() {
    ASSERT_FALSE(check.Receive(State(500, 0), 100'000).error);
    ASSERT_FALSE(check.Receive(State(501, 10 * kMs), 10 * kMs + 100'000).error);
  }
  StateLinkCheck check{LinkConfig{.freshness = {.budget_ns = 20 * kMs}, .error_rate = {.window_ns = 1000 * kMs}}, "cobot"};
};

TEST_F(StateLink, Corruption) {
  Start();
  v1::SafetyState s = State(502, 20 * kMs, v1::SafetyState::STATE_STOP);
  s.set_state(v1::SafetyState::STATE_CLEAR);  // a STOP corrupted into a CLEAR
  const Verdict v = check.Receive(s, 20 * kMs + 100'000);
  EXPECT_FALSE(v.use);
  EXPECT_EQ(v.kind, Error::kCorruption);
}

TEST_F(StateLink, RepetitionAndIncorrectSequenceAreDiscarded) {
  Start();
  EXPECT_EQ(check.Receive(State(501, 10 * kMs), 11 * kMs).kind, Error::kRepetition);
  const Verdict v = check.Receive(State(500, 0), 12 * kMs);
  EXPECT_EQ(v.kind, Error::kIncorrectSequence);
  EXPECT_FALSE(v.use);
  EXPECT_TRUE(v.latch) << "the second error within the window";
}

TEST_F(StateLink, LossIsTolerable) {
  Start();
  const Verdict v = check.Receive(State(505, 20 * kMs), 20 * kMs + 100'000);
  EXPECT_TRUE(v.use);
  EXPECT_EQ(v.kind, Error::kLoss);
  EXPECT_FALSE(v.latch);
  EXPECT_EQ(check.counts()[Error::kLoss], 1u);
}

TEST_F(StateLink, DelayIsDiscardedAndHalts) {
  Start();
  const Verdict v = check.Receive(State(502, 20 * kMs), 20 * kMs + 100'000 + 25 * kMs);
  EXPECT_FALSE(v.use) << "a late CLEAR must not release the robot";
  EXPECT_EQ(v.kind, Error::kDelay);
  EXPECT_TRUE(v.latch);
}

TEST_F(StateLink, InsertionFromAnotherRunWithinAStream) {
  Start();
  v1::SafetyState s = State(502, 20 * kMs);
  s.set_aggregator_run_id(kAggRun + 1);
  Seal(s);
  const Verdict v = check.Receive(s, 20 * kMs + 100'000);
  EXPECT_FALSE(v.use);
  EXPECT_EQ(v.kind, Error::kInsertion);
}

TEST_F(StateLink, AddressingAnotherRobotIsRefusedEvenFirst) {
  StateLinkCheck fresh{LinkConfig{}, "cobot"};
  v1::SafetyState s = State(1, 0);
  s.set_robot_name("other-cell");
  Seal(s);
  const Verdict v = fresh.Receive(s, 0);
  EXPECT_FALSE(v.use);
  EXPECT_EQ(v.kind, Error::kAddressing);
  s.set_robot_name("");
  Seal(s);
  EXPECT_EQ(fresh.Receive(s, 1).kind, Error::kAddressing) << "an aggregator that names no robot is refused";
}

TEST_F(StateLink, MasqueradeAsAnotherAggregatorIsAnotherRunOrAnotherRobot) {
  // A SafetyState's sender is the aggregator run: a forged state either names a run the stream did not
  // start with (insertion, above), another robot (addressing, above), or fails the CRC (corruption).
  Start();
  v1::SafetyState s = State(502, 20 * kMs);
  s.set_safety_crc32(s.safety_crc32() ^ 0x1);
  EXPECT_EQ(check.Receive(s, 20 * kMs + 100'000).kind, Error::kCorruption);
}

TEST(Names, EveryErrorHasAMetricLabel) {
  for (std::size_t i = 0; i < kErrorKinds; ++i) EXPECT_NE(Name(static_cast<Error>(i)), "unknown");
  EXPECT_NE(DrawRunId(), 0u);
  EXPECT_NE(DrawRunId(), DrawRunId());
}

}  // namespace
}  // namespace ruffini::channel
