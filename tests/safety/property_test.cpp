// Property: nothing but an accepted Reset turns STOP or FAULT into CLEAR. Thousands of seeded random event
// sequences (every event kind, bad input, time going backwards, resets right and wrong, shutdown) run through
// the policy, and after every event the invariants below must hold.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "world.h"

namespace ruffini::safety {
namespace {

using testing::kMs;
using testing::TwoPatchScene;

constexpr std::string_view kPatchIds[] = {"forearm", "upper_arm", "tail"};  // "tail" is not in the scene
constexpr std::string_view kRegions[] = {"", "", "", "forearm", "hand", "tail"};

struct Tally {
  long events = 0, accepted_resets = 0, refused_resets = 0, stops = 0, faults = 0, rejections = 0, clears = 0;
};

enum class Kind { kHeartbeat, kBadHeartbeat, kContact, kHello, kRefused, kFault, kProtocol, kDisconnect,
                  kJoint, kTick, kPublish, kReset, kWrongReset, kUnauthorizedReset, kShutdown };

Kind Draw(std::mt19937_64& rng) {
  // Weights per mille.
  static constexpr std::pair<Kind, int> kTable[] = {
      {Kind::kHeartbeat, 330}, {Kind::kBadHeartbeat, 15}, {Kind::kContact, 170}, {Kind::kHello, 40},
      {Kind::kRefused, 5},     {Kind::kFault, 10},        {Kind::kProtocol, 5},  {Kind::kDisconnect, 10},
      {Kind::kJoint, 150},     {Kind::kTick, 60},         {Kind::kPublish, 50},  {Kind::kReset, 130},
      {Kind::kWrongReset, 15}, {Kind::kUnauthorizedReset, 8}, {Kind::kShutdown, 2}};
  int r = std::uniform_int_distribution<int>(0, 999)(rng);
  for (const auto& [k, w] : kTable) {
    if (r < w) return k;
    r -= w;
  }
  return Kind::kTick;
}

float DrawForce(std::mt19937_64& rng) {
  const int r = std::uniform_int_distribution<int>(0, 99)(rng);
  if (r == 0) return std::numeric_limits<float>::quiet_NaN();
  if (r == 1) return -std::uniform_real_distribution<float>(0.0f, 5.0f)(rng);
  if (r == 2) return std::numeric_limits<float>::infinity();
  if (r < 10) return 160.0f;  // exactly forearm's threshold
  return std::uniform_real_distribution<float>(0.0f, 200.0f)(rng);
}

void RunSequence(std::uint64_t seed, int length, Tally& tally) {
  std::mt19937_64 rng(seed);
  Config config = TwoPatchScene();
  config.healthy_before_reset_ns = 20 * kMs;  // short, so that sequences clear often
  config.new_epoch_per_cause = (seed % 2) == 1;
  config.joint_states_required = (seed % 3) != 0;
  const Policy policy(config);
  std::int64_t t = testing::kT0;
  Data d(policy, t);
  auto pick = [&](int n) { return std::uniform_int_distribution<int>(0, n - 1)(rng); };

  for (int step = 0; step < length; ++step) {
    // Time: mostly forward by 0..3 ms, sometimes backwards.
    if (pick(100) == 0) {
      t -= pick(5) * kMs + 1;
    } else {
      t += pick(3 * 1000 + 1) * 1000;
    }
    const Data before = d;
    const Kind kind = Draw(rng);
    const std::string_view patch = kPatchIds[pick(pick(20) == 0 ? 3 : 2)];
    Step s{};
    std::optional<ResetResult> reset;
    bool over_threshold_contact = false;
    switch (kind) {
      case Kind::kHeartbeat: s = policy.OnHeartbeat(d, patch, {.healthy = true, .in_contact = pick(4) == 0}, t); break;
      case Kind::kBadHeartbeat:
        s = policy.OnHeartbeat(d, patch, {.healthy = pick(2) == 0, .active_fault = PatchFaultCode::kFramesLost}, t);
        break;
      case Kind::kContact: {
        const Contact c{.force_n = DrawForce(rng), .region = kRegions[pick(6)], .released = pick(5) == 0};
        s = policy.OnContact(d, patch, c, t);
        const std::int32_t i = policy.FindPatch(patch);
        const std::int32_t region = c.region.empty() && i != kNoPatch
                                        ? policy.FindRegion(config.patches[static_cast<std::size_t>(i)].region)
                                        : policy.FindRegion(c.region);
        over_threshold_contact = region != kNoRegion && c.force_n > config.regions[static_cast<std::size_t>(region)].threshold_n;
        break;
      }
      case Kind::kHello: s = policy.OnHelloAccepted(d, patch, t); break;
      case Kind::kRefused: s = policy.OnHelloRefused(d, patch, t); break;
      case Kind::kFault: s = policy.OnPatchFault(d, patch, PatchFaultCode::kBaselineStale, t); break;
      case Kind::kProtocol: s = policy.OnProtocolError(d, patch, t); break;
      case Kind::kDisconnect: s = policy.OnDisconnect(d, patch, t); break;
      case Kind::kJoint: s = policy.OnJointState(d, t); break;
      case Kind::kTick: s = policy.Tick(d, t); break;
      case Kind::kPublish: s = policy.Publish(d, t); break;
      case Kind::kReset: reset = policy.Reset(d, {.stop_epoch = d.state().stop_epoch, .authorized = true}, t); break;
      case Kind::kWrongReset:
        reset = policy.Reset(d, {.stop_epoch = d.state().stop_epoch + 1 - static_cast<std::uint64_t>(pick(3)),
                                 .authorized = true}, t);
        break;
      case Kind::kUnauthorizedReset:
        reset = policy.Reset(d, {.stop_epoch = d.state().stop_epoch, .authorized = false}, t);
        break;
      case Kind::kShutdown: s = policy.Shutdown(d, t); break;
    }
    ++tally.events;
    const SafetyState& a = d.state();
    const SafetyState& b = before.state();
    const std::string where = "seed " + std::to_string(seed) + " step " + std::to_string(step) + " kind " +
                              std::to_string(static_cast<int>(kind)) + " patch " + std::string(patch);
    const bool accepted = reset && reset->accepted;

    // 1. Nothing but an accepted Reset turns STOP or FAULT into CLEAR.
    if (b.state != State::kClear && a.state == State::kClear) {
      ASSERT_TRUE(accepted) << where;
    }
    // 2. Never de-escalates: FAULT stays FAULT unless reset.
    if (b.state == State::kFault && !accepted) {
      ASSERT_EQ(a.state, State::kFault) << where;
    }
    // 3. The epoch only grows; a new epoch is never CLEAR; a reset keeps the epoch.
    ASSERT_GE(a.stop_epoch, b.stop_epoch) << where;
    if (a.stop_epoch != b.stop_epoch) {
      ASSERT_NE(a.state, State::kClear) << where;
    }
    if (reset) {
      ASSERT_EQ(a.stop_epoch, b.stop_epoch) << where;
    }
    // 4. seq: +1 exactly when the event says publish (or a reset is accepted); it counts publications.
    ASSERT_EQ(a.seq, b.seq + ((s.publish || accepted) ? 1u : 0u)) << where;
    ASSERT_EQ(a.seq, d.counters().publications) << where;
    if (a.state != b.state || a.stop_epoch != b.stop_epoch || !(a.cause == b.cause)) {
      ASSERT_EQ(a.seq, b.seq + 1) << where;
    }
    // 5. A refused reset changes nothing but its counter.
    if (reset && !reset->accepted) {
      ++tally.refused_resets;
      ASSERT_EQ(a, b) << where;
      ASSERT_TRUE(std::equal(d.patches().begin(), d.patches().end(), before.patches().begin(), before.patches().end()))
          << where;
      ASSERT_EQ(d.latest_cause(), before.latest_cause()) << where;
      ASSERT_EQ(d.now_ns(), before.now_ns()) << where;
      ASSERT_EQ(d.counters().resets_refused[static_cast<std::size_t>(reset->reason)],
                before.counters().resets_refused[static_cast<std::size_t>(reset->reason)] + 1)
          << where;
    }
    // 6. An accepted reset named the epoch of a latched state.
    if (accepted) {
      ++tally.accepted_resets;
      ASSERT_NE(b.state, State::kClear) << where;
      ASSERT_EQ(a.state, State::kClear) << where;
      ASSERT_FALSE(before.shutting_down()) << where;
    }
    // 7. Doubt is never a clear: a contact above threshold or any refused input leaves the state latched.
    if (over_threshold_contact || s.rejection != Rejection::kNone) {
      ASSERT_NE(a.state, State::kClear) << where;
    }
    // 8. CLEAR holds no cause and no known trouble on any patch.
    if (a.state == State::kClear) {
      ASSERT_EQ(a.cause.kind, CauseKind::kNone) << where;
      for (const PatchState& p : d.patches()) {
        ASSERT_EQ(p.link, LinkState::kHealthy) << where;
        ASSERT_FALSE(p.fault_in_force || p.protocol_fault || p.contact_over) << where;
      }
    } else {
      ASSERT_NE(a.cause.kind, CauseKind::kNone) << where;
    }
    // 9. Shutdown is forever.
    if (before.shutting_down()) {
      ASSERT_EQ(a.state, State::kFault) << where;
      ASSERT_EQ(a.cause.kind, CauseKind::kShuttingDown) << where;
    }
    tally.stops += a.state == State::kStop && b.state != State::kStop;
    tally.faults += a.state == State::kFault && b.state != State::kFault;
    tally.clears += a.state == State::kClear && b.state != State::kClear;
    tally.rejections += s.rejection != Rejection::kNone;
  }
}

TEST(SafetyProperty, NothingButResetClears) {
  Tally tally;
  constexpr int kSequences = 3000;
  for (std::uint64_t seed = 1; seed <= kSequences; ++seed) {
    RunSequence(seed, 400, tally);
    if (HasFatalFailure()) return;
  }
  // The sequences really exercise the machine: many latches, many clears, many refusals.
  EXPECT_EQ(tally.events, kSequences * 400L);
  EXPECT_GT(tally.accepted_resets, 3000);
  EXPECT_GT(tally.refused_resets, 10000);
  EXPECT_GT(tally.stops, 1000);
  EXPECT_GT(tally.faults, 1000);
  EXPECT_GT(tally.rejections, 1000);
  EXPECT_EQ(tally.clears, tally.accepted_resets);
  std::printf("events %ld, accepted resets %ld, refused %ld, stops %ld, faults %ld, rejections %ld\n", tally.events,
              tally.accepted_resets, tally.refused_resets, tally.stops, tally.faults, tally.rejections);
}

}  // namespace
}  // namespace ruffini::safety
