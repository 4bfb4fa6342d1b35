// The safety policy's rules, one table row each (docs/safety.md lists them): a script drives a two-patch
// scene on a simulated clock, then the row says what the state, the epoch, the published cause, the last
// event's rejection and the last reset's outcome must be.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <algorithm>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "ruffini/error.h"
#include "world.h"

namespace ruffini::safety {
namespace {

using testing::kMs;
using testing::kT0;
using testing::TwoPatchScene;
using testing::World;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

struct Expect {
  State state;
  std::uint64_t epoch;
  CauseKind cause = CauseKind::kNone;          // the published cause (what latched the epoch)
  std::string_view cause_patch = {};           // its patch ("" = none)
  Rejection rejection = Rejection::kNone;      // the last event's
  std::optional<ResetRefusal> reset{};         // the last reset's outcome (kNone = accepted)
  CauseKind blocking = CauseKind::kNone;       // a refused reset's blocking cause
  std::string_view blocking_patch = {};
  CauseKind latest = CauseKind::kNone;         // the newest cause, recorded or latched (kNone: not checked)
};

struct Rule {
  const char* name;
  std::function<void(World&)> script;
  Expect expect;
  std::function<Config()> scene = TwoPatchScene;
};

Config NoRobot() {
  Config c = TwoPatchScene();
  c.joint_states_required = false;
  return c;
}
Config EpochPerCause() {
  Config c = TwoPatchScene();
  c.new_epoch_per_cause = true;
  return c;
}

const std::vector<Rule>& Rules() {
  using enum State;
  using enum CauseKind;
  using RR = ResetRefusal;
  using Rj = Rejection;
  static const std::vector<Rule> rules = {
      // --- Start-up ---
      {"starts_in_fault_epoch_1", [](World&) {}, {kFault, 1, kStartup}},
      {"startup_reset_refused_while_a_patch_is_missing",
       [](World& w) {
         w.Hello("forearm");
         w.quiet = {"upper_arm"};
         w.Beat(300);
         w.Reset(1);
       },
       {kFault, 1, kStartup, {}, Rj::kNone, RR::kCausePresent, kPatchMissing, "upper_arm"}},
      {"startup_reset_refused_before_200ms_healthy",
       [](World& w) {
         w.Connect();
         w.Beat(190);
         w.Reset(1);
       },
       {kFault, 1, kStartup, {}, Rj::kNone, RR::kNotHealthyLongEnough, kNone, "forearm"}},
      {"startup_reset_accepted_after_200ms_healthy", [](World& w) { w.Clear(); }, {kClear, 1, kNone, {}, Rj::kNone, RR::kNone}},
      {"startup_never_clears_by_itself",
       [](World& w) {
         w.Connect();
         w.Beat(1000);
       },
       {kFault, 1, kStartup}},
      {"startup_needs_joint_states_when_the_scene_has_a_robot",
       [](World& w) {
         w.joints = false;
         w.Clear();
       },
       {kFault, 1, kStartup, {}, Rj::kNone, RR::kCausePresent, kJointStatesStale}},
      {"a_scene_without_a_robot_needs_no_joint_states",
       [](World& w) {
         w.joints = false;
         w.Clear();
         w.Beat(500);
       },
       {kClear, 1, kNone, {}, Rj::kNone, RR::kNone},
       NoRobot},
      // --- STOP: contacts ---
      {"contact_above_threshold_stops",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 160.5f);
       },
       {kStop, 2, kContact, "forearm"}},
      {"contact_at_threshold_never_stops",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 160.0f);
         w.Contact("upper_arm", 150.0f);
       },
       {kClear, 1}},
      {"threshold_is_the_regions",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 155.0f);    // below forearm's 160
         w.Contact("upper_arm", 155.0f);  // above upper_arm's 150
       },
       {kStop, 2, kContact, "upper_arm"}},
      {"a_named_region_overrides_the_patchs",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 145.0f, "hand");  // 145 > hand's 140
       },
       {kStop, 2, kContact, "forearm"}},
      {"a_faulty_patchs_contact_is_still_judged",  // safety never waits on health (nor on fusion)
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnPatchFault(w.data, "forearm", PatchFaultCode::kFramesLost, w.t);
         w.Contact("forearm", 500.0f);
       },
       {kFault, 2, kPatchFault, "forearm", Rj::kNone, {}, kNone, {}, kContact}},
      // --- FAULT: patches ---
      {"silence_up_to_the_deadline_is_fine",
       [](World& w) {
         w.Clear();
         w.Wait(30);
         w.last = w.policy.Tick(w.data, w.t);
       },
       {kClear, 1}},
      {"silence_past_the_deadline_faults_on_tick",
       [](World& w) {
         w.Clear();
         w.Wait(30);
         w.t += 1;
         w.last = w.policy.Tick(w.data, w.t);
       },
       {kFault, 2, kPatchSilent, "forearm"}},
      {"silence_is_found_by_any_event",
       [](World& w) {
         w.Clear();
         w.quiet = {"upper_arm"};
         w.Beat(40);
       },
       {kFault, 2, kPatchSilent, "upper_arm"}},
      {"patch_fault_faults",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnPatchFault(w.data, "upper_arm", PatchFaultCode::kBaselineStale, w.t);
       },
       {kFault, 2, kPatchFault, "upper_arm"}},
      {"unhealthy_heartbeat_faults",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnHeartbeat(w.data, "forearm", {.healthy = false}, w.t);
       },
       {kFault, 2, kPatchFault, "forearm"}},
      {"healthy_heartbeat_with_a_fault_in_force_faults",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnHeartbeat(w.data, "forearm",
                                       {.healthy = true, .active_fault = PatchFaultCode::kOverloaded}, w.t);
       },
       {kFault, 2, kPatchFault, "forearm"}},
      {"disconnect_faults",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnDisconnect(w.data, "upper_arm", w.t);
       },
       {kFault, 2, kPatchSilent, "upper_arm"}},
      {"protocol_error_faults",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnProtocolError(w.data, "forearm", w.t);
       },
       {kFault, 2, kPatchProtocol, "forearm"}},
      {"hello_refused_faults_as_missing",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnHelloRefused(w.data, "forearm", w.t);
       },
       {kFault, 2, kPatchMissing, "forearm"}},
      {"joint_states_older_than_the_limit_fault",
       [](World& w) {
         w.Clear();
         w.joints = false;
         w.Beat(60);
       },
       {kFault, 2, kJointStatesStale}},
      {"joint_states_at_the_limit_are_fresh",
       [](World& w) {
         w.Clear();
         w.joints = false;
         w.Beat(50);
       },
       {kClear, 1}},
      {"shutdown_faults_under_a_new_epoch",
       [](World& w) {
         w.Clear();
         w.last = w.policy.Shutdown(w.data, w.t);
       },
       {kFault, 2, kShuttingDown}},
      {"shutdown_can_never_be_reset",
       [](World& w) {
         w.Clear();
         w.last = w.policy.Shutdown(w.data, w.t);
         w.Beat(1000);
         w.ResetCurrent();
       },
       {kFault, 2, kShuttingDown, {}, Rj::kNone, RR::kShuttingDown}},
      {"shutdown_while_faulted_takes_a_new_epoch_too",
       [](World& w) { w.last = w.policy.Shutdown(w.data, w.t); },
       {kFault, 2, kShuttingDown}},
      // --- Latching and the epoch ---
      {"fault_while_stopped_escalates_under_a_new_epoch",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 200.0f);
         w.last = w.policy.OnPatchFault(w.data, "upper_arm", PatchFaultCode::kFramesRejected, w.t);
       },
       {kFault, 3, kPatchFault, "upper_arm"}},
      {"stop_while_faulted_stays_fault",  // never de-escalates
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnPatchFault(w.data, "upper_arm", PatchFaultCode::kFramesRejected, w.t);
         w.Contact("forearm", 200.0f);
       },
       {kFault, 2, kPatchFault, "upper_arm"}},
      {"a_second_cause_while_latched_keeps_the_epoch",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 200.0f);
         w.Contact("upper_arm", 200.0f);
       },
       {kStop, 2, kContact, "forearm"}},
      {"epoch_per_cause_option_takes_a_new_epoch_for_a_second_cause",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 200.0f);
         w.Contact("upper_arm", 200.0f);
       },
       {kStop, 3, kContact, "upper_arm"},
       EpochPerCause},
      {"a_contact_held_above_threshold_is_one_cause",
       [](World& w) {
         w.Clear();
         for (int k = 0; k < 20; ++k) {
           w.Wait(1);
           w.Contact("forearm", 200.0f + static_cast<float>(k));
         }
       },
       {kStop, 2, kContact, "forearm"},
       EpochPerCause},
      // --- Reset ---
      {"reset_naming_another_epoch_is_refused",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 200.0f);
         w.Contact("forearm", 10.0f);
         w.Beat(200);
         w.Reset(1);
       },
       {kStop, 2, kContact, "forearm", Rj::kNone, RR::kWrongEpoch}},
      {"reset_when_clear_is_refused",
       [](World& w) {
         w.Clear();
         w.Reset(1);
       },
       {kClear, 1, kNone, {}, Rj::kNone, RR::kNotLatched}},
      {"reset_while_the_contact_persists_is_refused",
       [](World& w) {
         w.Clear();
         w.touching = {"upper_arm"};
         w.Contact("upper_arm", 200.0f);
         w.Beat(300);
         w.Reset(2);
       },
       {kStop, 2, kContact, "upper_arm", Rj::kNone, RR::kCausePresent, kContact, "upper_arm"}},
      {"reset_after_release_is_accepted",
       [](World& w) {
         w.Clear();
         w.Contact("upper_arm", 200.0f);
         w.Contact("upper_arm", 20.0f, {}, true);
         w.Reset(2);
       },
       {kClear, 2, kNone, {}, Rj::kNone, RR::kNone}},
      {"a_healthy_heartbeat_out_of_contact_ends_the_contact",
       [](World& w) {
         w.Clear();
         w.Contact("upper_arm", 200.0f);
         w.Beat(10);
         w.Reset(2);
       },
       {kClear, 2, kNone, {}, Rj::kNone, RR::kNone}},
      {"reset_while_a_patch_is_still_faulty_is_refused",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnPatchFault(w.data, "forearm", PatchFaultCode::kFramesLost, w.t);
         w.quiet = {"forearm"};
         w.Beat(20);
         w.last = w.policy.OnHeartbeat(w.data, "forearm", {.healthy = false}, w.t);
         w.Reset(2);
       },
       {kFault, 2, kPatchFault, "forearm", Rj::kNone, RR::kCausePresent, kPatchFault, "forearm"}},
      {"after_a_fault_every_patch_needs_200ms_healthy_again",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnPatchFault(w.data, "forearm", PatchFaultCode::kFramesLost, w.t);
         w.Beat(190);
         w.Reset(2);
       },
       {kFault, 2, kPatchFault, "forearm", Rj::kNone, RR::kNotHealthyLongEnough, kNone, "forearm"}},
      {"after_a_fault_200ms_healthy_then_reset_clears",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnPatchFault(w.data, "forearm", PatchFaultCode::kFramesLost, w.t);
         w.Beat(210);
         w.Reset(2);
       },
       {kClear, 2, kNone, {}, Rj::kNone, RR::kNone}},
      {"a_silent_patch_that_speaks_again_recovers_after_200ms",
       [](World& w) {
         w.Clear();
         w.quiet = {"forearm"};
         w.Beat(50);
         w.quiet.clear();
         w.Beat(210);
         w.Reset(2);
       },
       {kClear, 2, kNone, {}, Rj::kNone, RR::kNone}},
      {"a_silent_patch_blocks_a_reset_even_before_a_tick_sees_it",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 200.0f);
         w.Contact("forearm", 0.0f, {}, true);
         w.Wait(40);
         w.Reset(2);
       },
       {kStop, 2, kContact, "forearm", Rj::kNone, RR::kCausePresent, kPatchSilent, "forearm"}},
      {"a_disconnected_patch_needs_a_new_hello",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnDisconnect(w.data, "forearm", w.t);
         w.quiet = {"forearm"};
         w.Beat(300);
         w.Reset(2);
       },
       {kFault, 2, kPatchSilent, "forearm", Rj::kNone, RR::kCausePresent, kPatchSilent, "forearm"}},
      {"a_protocol_fault_lasts_until_a_new_hello",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnProtocolError(w.data, "forearm", w.t);
         w.Beat(300);
         w.Reset(2);
       },
       {kFault, 2, kPatchProtocol, "forearm", Rj::kNone, RR::kCausePresent, kPatchProtocol, "forearm"}},
      {"reconnect_hello_then_200ms_healthy_then_reset_clears",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnProtocolError(w.data, "forearm", w.t);
         w.last = w.policy.OnDisconnect(w.data, "forearm", w.t);
         w.Wait(5);
         w.Hello("forearm");
         w.Beat(210);
         w.Reset(2);
       },
       {kClear, 2, kNone, {}, Rj::kNone, RR::kNone}},
      {"unauthorized_reset_is_refused",
       [](World& w) {
         w.Connect();
         w.Beat(200);
         w.reset = w.policy.Reset(w.data, {.stop_epoch = 1, .authorized = false}, w.t);
       },
       {kFault, 1, kStartup, {}, Rj::kNone, RR::kUnauthorized}},
      {"reset_from_the_past_is_refused_and_changes_nothing",
       [](World& w) {
         w.Connect();
         w.Beat(300);
         w.reset = w.policy.Reset(w.data, {.stop_epoch = 1, .authorized = true}, w.t - 1);
       },
       {kFault, 1, kStartup, {}, Rj::kNone, RR::kInvalidRequest}},
      // --- Bad input: counted, and a doubt (STOP for a contact, FAULT otherwise), never a clear ---
      {"nan_force_stops",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", kNaN);
       },
       {kStop, 2, kContact, "forearm", Rj::kNonFiniteForce}},
      {"infinite_force_stops",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", std::numeric_limits<float>::infinity());
       },
       {kStop, 2, kContact, "forearm", Rj::kNonFiniteForce}},
      {"negative_force_stops",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", -0.5f);
       },
       {kStop, 2, kContact, "forearm", Rj::kNegativeForce}},
      {"a_doubtful_contact_persists_until_a_good_frame",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", kNaN);
         w.Reset(2);
       },
       {kStop, 2, kContact, "forearm", Rj::kNonFiniteForce, RR::kCausePresent, kContact, "forearm"}},
      {"a_good_frame_below_the_release_level_ends_the_doubt_after_the_hold",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", kNaN);
         w.Contact("forearm", 3.0f);
         w.touching = {"forearm"};  // heartbeats keep the link and the contact (in_contact)
         w.Beat(100);               // ContactRelease.hold_ns (default 100 ms)
         w.Reset(2);
       },
       {kClear, 2, kNone, {}, Rj::kNone, RR::kNone}},
      {"a_good_frame_below_threshold_does_not_end_the_doubt_before_the_hold",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", kNaN);
         w.Contact("forearm", 3.0f);
         w.touching = {"forearm"};
         w.Beat(90);
         w.Reset(2);
       },
       {kStop, 2, kContact, "forearm", Rj::kNone, RR::kCausePresent, kContact, "forearm"}},
      {"a_slightly_negative_force_is_noise_judged_as_zero",  // -0.0004 N released frame: no STOP (review 10)
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 0.5f);
         w.Contact("forearm", -0.0004f, {}, true);
       },
       {kClear, 1}},
      {"a_force_below_the_negative_tolerance_stops",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", -0.06f, {}, true);  // beyond the default 0.05 N tolerance
       },
       {kStop, 2, kContact, "forearm", Rj::kNegativeForce}},
      {"a_doubt_found_by_the_caller_stops",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnContact(w.data, "forearm", {.force_n = 1.0f, .doubt = Rejection::kBadPosition}, w.t);
       },
       {kStop, 2, kContact, "forearm", Rj::kBadPosition}},
      {"a_reset_naming_another_run_is_refused",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 200.0f);
         w.Contact("forearm", 0.0f, {}, true);
         w.reset = w.policy.Reset(w.data, {.stop_epoch = 2, .authorized = true, .other_run = true}, w.t);
       },
       {kStop, 2, kContact, "forearm", Rj::kNone, RR::kWrongRun}},
      {"unknown_region_stops",
       [](World& w) {
         w.Clear();
         w.Contact("forearm", 1.0f, "tail");
       },
       {kStop, 2, kContact, "forearm", Rj::kUnknownRegion}},
      {"unknown_patch_contact_stops",
       [](World& w) {
         w.Clear();
         w.Contact("tail", 1.0f);
       },
       {kStop, 2, kContact, {}, Rj::kUnknownPatch}},
      {"unknown_patch_heartbeat_faults",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnHeartbeat(w.data, "tail", {.healthy = true}, w.t);
       },
       {kFault, 2, kInternal, {}, Rj::kUnknownPatch}},
      {"time_going_backwards_faults",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnHeartbeat(w.data, "forearm", {.healthy = true}, w.t - 1);
       },
       {kFault, 2, kInternal, {}, Rj::kTimeBackwards}},
      {"a_contact_from_the_past_faults",
       [](World& w) {
         w.Clear();
         w.last = w.policy.OnContact(w.data, "forearm", {.force_n = 1.0f}, w.t - 1);
       },
       {kFault, 2, kInternal, {}, Rj::kTimeBackwards}},
      {"heartbeat_before_hello_is_refused",
       [](World& w) { w.last = w.policy.OnHeartbeat(w.data, "forearm", {.healthy = true}, w.t); },
       {kFault, 1, kStartup, {}, Rj::kNotConnected, {}, kNone, {}, kInternal}},
      {"contact_before_hello_is_refused",
       [](World& w) { w.Contact("forearm", 1.0f); },
       {kFault, 1, kStartup, {}, Rj::kNotConnected, {}, kNone, {}, kContact}},
      {"a_refused_contact_lasts_until_healthy_heartbeats_say_untouched",
       [](World& w) {
         w.Contact("forearm", 1.0f);
         w.Connect();
         w.touching = {"forearm"};
         w.Beat(210);
         w.Reset(1);
       },
       {kFault, 1, kStartup, {}, Rj::kNone, RR::kCausePresent, kContact, "forearm"}},
  };
  return rules;
}

void PrintTo(const Rule& r, std::ostream* os) { *os << r.name; }

class SafetyRule : public ::testing::TestWithParam<Rule> {};

TEST_P(SafetyRule, Holds) {
  const Rule& rule = GetParam();
  World w(rule.scene());
  rule.script(w);
  const Expect& e = rule.expect;
  const SafetyState& s = w.data.state();
  EXPECT_EQ(StateName(s.state), StateName(e.state));
  EXPECT_EQ(s.stop_epoch, e.epoch);
  EXPECT_EQ(CauseKindName(s.cause.kind), CauseKindName(e.cause)) << Describe(w.policy, s.cause);
  EXPECT_EQ(w.policy.patch_id(s.cause.patch), e.cause_patch);
  EXPECT_EQ(RejectionName(w.last.rejection), RejectionName(e.rejection));
  if (e.latest != CauseKind::kNone) {
    EXPECT_EQ(CauseKindName(w.data.latest_cause().kind), CauseKindName(e.latest));
  }
  if (e.reset) {
    EXPECT_EQ(ResetRefusalName(w.reset.reason), ResetRefusalName(*e.reset)) << Describe(w.policy, w.reset);
    EXPECT_EQ(w.reset.accepted, *e.reset == ResetRefusal::kNone);
    EXPECT_EQ(CauseKindName(w.reset.blocking.kind), CauseKindName(e.blocking));
    EXPECT_EQ(w.policy.patch_id(w.reset.blocking.patch), e.blocking_patch);
    EXPECT_EQ(w.reset.current_epoch, e.epoch);
  }
  // Whatever happened: CLEAR holds no cause, a latch holds one, and seq counts every publication.
  EXPECT_EQ(s.state == State::kClear, s.cause.kind == CauseKind::kNone);
  EXPECT_EQ(s.seq, w.data.counters().publications);
}

INSTANTIATE_TEST_SUITE_P(Rules, SafetyRule, ::testing::ValuesIn(Rules()),
                         [](const ::testing::TestParamInfo<Rule>& i) { return std::string(i.param.name); });

// --- Details the table does not show ------------------------------------------------------------------------

TEST(SafetySeq, EveryChangeAndEveryPublishTakesOneSeq) {
  World w;
  EXPECT_EQ(w.data.state().seq, 1u);  // the start-up state is the first publication
  EXPECT_EQ(w.data.state().published_t_ns, kT0);
  w.Connect();
  w.Beat(210);
  EXPECT_EQ(w.data.state().seq, 1u);  // nothing changed, nothing published
  w.Wait(1);
  Step p = w.policy.Publish(w.data, w.t);
  EXPECT_TRUE(p.publish);
  EXPECT_EQ(w.data.state().seq, 2u);
  EXPECT_EQ(w.data.state().published_t_ns, w.t);
  EXPECT_EQ(w.data.state().changed_t_ns, kT0);
  p = w.policy.Publish(w.data, w.t);  // the same instant: still a publication
  EXPECT_EQ(w.data.state().seq, 3u);
  w.ResetCurrent();
  EXPECT_TRUE(w.reset.accepted);
  EXPECT_EQ(w.data.state().seq, 4u);
  EXPECT_EQ(w.data.state().changed_t_ns, w.t);
  w.Contact("forearm", 170.0f);
  EXPECT_TRUE(w.last.publish);
  EXPECT_EQ(w.data.state().seq, 5u);
  w.Contact("upper_arm", 170.0f);  // recorded, the published state is unchanged: no publication
  EXPECT_FALSE(w.last.publish);
  EXPECT_EQ(w.data.state().seq, 5u);
  // A Publish whose Tick finds a change (both patches silent: the escalation) publishes once, not twice.
  w.Wait(31);
  p = w.policy.Publish(w.data, w.t);
  EXPECT_TRUE(p.publish);
  EXPECT_EQ(w.state(), State::kFault);
  EXPECT_EQ(w.data.state().seq, 6u);
  EXPECT_EQ(w.data.state().changed_t_ns, w.t);
  // A refused event (time backwards) that changes nothing published is no publication.
  p = w.policy.Tick(w.data, w.t - 1);
  EXPECT_EQ(p.rejection, Rejection::kTimeBackwards);
  EXPECT_FALSE(p.publish);
  EXPECT_EQ(w.data.state().seq, 6u);
  EXPECT_EQ(w.data.counters().publications, 6u);
  // A Publish from the past still publishes, once.
  p = w.policy.Publish(w.data, w.t - 1);
  EXPECT_EQ(p.rejection, Rejection::kTimeBackwards);
  EXPECT_TRUE(p.publish);
  EXPECT_EQ(w.data.state().seq, 7u);
  EXPECT_EQ(w.data.state().published_t_ns, w.t);  // the newest good time
  // A Publish from the past that latches (CLEAR -> FAULT) is one publication too.
  World v;
  v.Clear();
  const std::uint64_t seq = v.data.state().seq;
  p = v.policy.Publish(v.data, v.t - 1);
  EXPECT_EQ(v.state(), State::kFault);
  EXPECT_EQ(v.data.state().seq, seq + 1);
  EXPECT_EQ(v.data.counters().publications, seq + 1);
}

TEST(SafetyCause, ContactCauseCarriesTheEvidence) {
  World w;
  w.Clear();
  const std::int64_t frame_t = w.t - 2 * kMs;  // the interrogator's time of the frame
  w.last = w.policy.OnContact(
      w.data, "upper_arm", {.force_n = 151.5f, .t_ns = frame_t, .p_bc_m = std::array<double, 3>{0.1, 0.2, 0.3}}, w.t);
  const Cause& c = w.data.state().cause;
  EXPECT_EQ(c.kind, CauseKind::kContact);
  EXPECT_EQ(w.policy.patch_id(c.patch), "upper_arm");
  EXPECT_EQ(w.policy.region_name(c.region), "upper_arm");
  EXPECT_FLOAT_EQ(c.force_n, 151.5f);
  EXPECT_FLOAT_EQ(c.threshold_n, 150.0f);
  ASSERT_TRUE(c.p_bc_m.has_value());
  EXPECT_DOUBLE_EQ((*c.p_bc_m)[2], 0.3);
  EXPECT_EQ(c.t_ns, frame_t);
  EXPECT_EQ(w.data.state().changed_t_ns, w.t);
  EXPECT_EQ(Describe(w.policy, c),
            "contact patch 'upper_arm' force 151.5 N above region 'upper_arm' threshold 150 N at (0.1, 0.2, 0.3) m"
            " at t_ns " + std::to_string(frame_t));
}

// Issue 17: a frame the decoder flagged faint, and a force that is a seam sum (review 3 finding 7), are
// information in the cause's text and nothing else: the same frames with and without the marks give the same
// states, epochs, publications and reset outcomes at every step (a STOP at the force as read, never lowered,
// held while the force stays above the release level).
TEST(SafetyCause, FaintAndSeamSumMarksChangeNoJudgementAndAreNamed) {
  World plain, marked;
  for (World* w : {&plain, &marked}) {
    w->Clear();
    w->touching = {"forearm"};
  }
  const std::int32_t partner = marked.policy.FindPatch("upper_arm");
  // Below the 160 N threshold, above it, hovering above the release level (144 N), then below it for the hold.
  const float forces[] = {120.0f, 159.0f, 161.0f, 200.0f, 150.0f, 145.0f, 170.0f, 100.0f, 100.0f, 100.0f, 100.0f};
  for (float f : forces) {
    for (int k = 0; k < 12; ++k) {
      for (World* w : {&plain, &marked}) {
        w->Beat(10);
        Contact c{.force_n = f};
        if (w == &marked) {
          c.faint = true;
          c.seam_partner = partner;
          c.seam_own_force_n = f / 2;
          c.seam_partner_force_n = f / 2;
        }
        w->last = w->policy.OnContact(w->data, "forearm", c, w->t);
        if (k == 11) w->ResetCurrent();
      }
      ASSERT_EQ(marked.state(), plain.state()) << f << " N";
      ASSERT_EQ(marked.epoch(), plain.epoch()) << f << " N";
      ASSERT_EQ(marked.data.state().seq, plain.data.state().seq) << f << " N";
      ASSERT_EQ(marked.reset.accepted, plain.reset.accepted) << f << " N";
      ASSERT_EQ(marked.reset.reason, plain.reset.reason) << f << " N";
      ASSERT_FLOAT_EQ(marked.data.state().cause.force_n, plain.data.state().cause.force_n) << f << " N";
    }
    if (f == 200.0f) {
      ASSERT_EQ(marked.state(), State::kStop);
      EXPECT_EQ(marked.reset.reason, ResetRefusal::kCausePresent) << "a faint 200 N contact ended its cause";
    }
  }
  EXPECT_EQ(marked.state(), State::kClear) << "the cause ends as the unmarked one does, after the hold below release";
  // The first STOP's cause (161 N) says what it was.
  World w;
  w.Clear();
  w.last = w.policy.OnContact(w.data, "forearm",
                              {.force_n = 161.0f, .seam_partner = partner, .seam_own_force_n = 100.0f,
                               .seam_partner_force_n = 61.0f, .faint = true},
                              w.t);
  const Cause& c = w.data.state().cause;
  ASSERT_EQ(w.state(), State::kStop);
  EXPECT_FLOAT_EQ(c.force_n, 161.0f);
  const std::string text = Describe(w.policy, c);
  EXPECT_NE(text.find("force 161 N (seam sum of 'forearm' 100 N and 'upper_arm' 61 N)"), std::string::npos) << text;
  EXPECT_NE(text.find("[faint:"), std::string::npos) << text;
  World one;
  one.Clear();
  one.Contact("forearm", 161.0f);
  const std::string alone = Describe(one.policy, one.data.state().cause);
  EXPECT_EQ(alone.find("seam sum"), std::string::npos) << alone;
  EXPECT_EQ(alone.find("faint"), std::string::npos) << alone;
}

TEST(SafetyCause, NanDoubtIsNamed) {
  World w;
  w.Clear();
  w.Contact("forearm", kNaN);
  const Cause& c = w.data.state().cause;
  EXPECT_TRUE(std::isnan(c.force_n));
  EXPECT_EQ(c.doubt, Rejection::kNonFiniteForce);
  EXPECT_NE(Describe(w.policy, c).find("[doubt: non_finite_force]"), std::string::npos);
}

TEST(SafetyCause, SecondCauseIsRecordedNotPublished) {
  World w;
  w.Clear();
  w.Contact("forearm", 200.0f);
  w.last = w.policy.OnHeartbeat(w.data, "upper_arm", {.healthy = true}, w.t);
  w.Contact("upper_arm", 180.0f);
  EXPECT_EQ(w.policy.patch_id(w.data.state().cause.patch), "forearm");
  EXPECT_EQ(w.policy.patch_id(w.data.latest_cause().patch), "upper_arm");
  EXPECT_EQ(w.data.counters().causes_while_latched, 1u);
  EXPECT_EQ(w.data.counters().causes[static_cast<std::size_t>(CauseKind::kContact)], 2u);
}

TEST(SafetyReset, RefusedResetChangesNothingButItsCounter) {
  World w;
  w.Clear();
  w.touching = {"forearm"};
  w.Contact("forearm", 200.0f);
  w.Beat(50);
  for (const ResetRequest r : {ResetRequest{.stop_epoch = 2, .authorized = false},
                               ResetRequest{.stop_epoch = 1, .authorized = true},
                               ResetRequest{.stop_epoch = 2, .authorized = true}}) {
    const Data before = w.data;
    const ResetResult out = w.policy.Reset(w.data, r, w.t);
    EXPECT_FALSE(out.accepted);
    Counters expected = before.counters();
    ++expected.resets_refused[static_cast<std::size_t>(out.reason)];
    EXPECT_EQ(w.data.counters(), expected);
    EXPECT_EQ(w.data.state(), before.state());
    EXPECT_TRUE(std::equal(w.data.patches().begin(), w.data.patches().end(), before.patches().begin(),
                           before.patches().end()));
    EXPECT_EQ(w.data.latest_cause(), before.latest_cause());
    EXPECT_EQ(w.data.now_ns(), before.now_ns());
  }
  EXPECT_EQ(w.data.counters().resets_refused[static_cast<std::size_t>(ResetRefusal::kUnauthorized)], 1u);
  EXPECT_EQ(w.data.counters().resets_refused[static_cast<std::size_t>(ResetRefusal::kWrongEpoch)], 1u);
  EXPECT_EQ(w.data.counters().resets_refused[static_cast<std::size_t>(ResetRefusal::kCausePresent)], 1u);
}

TEST(SafetyReset, DescribeNamesPatchAndCause) {
  World w;
  w.Hello("forearm");
  w.quiet = {"upper_arm"};
  w.Beat(200);
  EXPECT_EQ(Describe(w.policy, w.Reset(1)),
            "reset refused (cause_present): cause still present: patch_missing patch 'upper_arm' at t_ns " +
                std::to_string(w.t));
  w.Hello("upper_arm");
  w.quiet.clear();
  w.Beat(100);
  EXPECT_EQ(Describe(w.policy, w.Reset(1)),
            "reset refused (not_healthy_long_enough): patch 'upper_arm' healthy for 90000000 ns of the 200000000 ns "
            "required");
  EXPECT_EQ(Describe(w.policy, w.Reset(7)), "reset refused (wrong_epoch): the current stop_epoch is 1");
  w.Beat(110);
  EXPECT_EQ(Describe(w.policy, w.Reset(1)), "reset accepted: stop_epoch 1 cleared");
}

TEST(SafetyCounters, CountStopsFaultsRefusalsAndRejections) {
  World w;
  w.Clear();
  w.Contact("forearm", 200.0f);                                                      // stop
  w.last = w.policy.OnPatchFault(w.data, "upper_arm", PatchFaultCode::kInternal, w.t);  // escalation
  w.Contact("forearm", kNaN);                                                         // rejection (recorded)
  w.Contact("tail", 1.0f);                                                            // rejection (recorded)
  w.Reset(1);                                                                         // wrong epoch
  const Counters& n = w.data.counters();
  EXPECT_EQ(n.stops, 1u);
  EXPECT_EQ(n.faults, 2u);  // start-up, escalation
  EXPECT_EQ(n.escalations, 1u);
  EXPECT_EQ(n.epochs, 2u);
  EXPECT_EQ(n.resets_accepted, 1u);
  EXPECT_EQ(n.resets_refused[static_cast<std::size_t>(ResetRefusal::kWrongEpoch)], 1u);
  EXPECT_EQ(n.rejections[static_cast<std::size_t>(Rejection::kNonFiniteForce)], 1u);
  EXPECT_EQ(n.rejections[static_cast<std::size_t>(Rejection::kUnknownPatch)], 1u);
  // The unknown patch. The NaN doubt on forearm, whose contact was already held, is the same cause.
  EXPECT_EQ(n.causes_while_latched, 1u);
}

TEST(SafetyPatches, LinkStatesFollowTheEvents) {
  World w;
  auto link = [&](std::string_view id) { return w.data.patches()[static_cast<std::size_t>(w.policy.FindPatch(id))].link; };
  EXPECT_EQ(link("forearm"), LinkState::kDisconnected);
  w.Hello("forearm");
  EXPECT_EQ(link("forearm"), LinkState::kUnhealthy);  // live, no healthy heartbeat yet
  w.Beat(10);
  EXPECT_EQ(link("forearm"), LinkState::kHealthy);
  w.Wait(31);
  (void)w.policy.Tick(w.data, w.t);
  EXPECT_EQ(link("forearm"), LinkState::kSilent);
  w.Beat(10);
  EXPECT_EQ(link("forearm"), LinkState::kHealthy);
  (void)w.policy.OnHelloRefused(w.data, "upper_arm", w.t);
  EXPECT_EQ(link("upper_arm"), LinkState::kRefused);
  (void)w.policy.OnDisconnect(w.data, "forearm", w.t);
  EXPECT_EQ(link("forearm"), LinkState::kDisconnected);
}

// --- Config -------------------------------------------------------------------------------------------------

struct BadConfig {
  const char* name;
  std::function<void(Config&)> edit;
  const char* message;
};

TEST(SafetyConfig, ErrorsNameTheFieldAndTheValue) {
  const std::vector<BadConfig> cases = {
      {"no_regions", [](Config& c) { c.regions.clear(); },
       "safety.regions is empty: every patch's contacts are judged in a body region"},
      {"dup_region", [](Config& c) { c.regions[2].name = "forearm"; }, "safety.regions[2].name ('forearm') is a duplicate"},
      {"nan_threshold", [](Config& c) { c.regions[1].threshold_n = kNaN; },
       "safety.regions[1].threshold_n (nan) must be a finite force above 0 N"},
      {"zero_threshold", [](Config& c) { c.regions[0].threshold_n = 0.0f; },
       "safety.regions[0].threshold_n (0) must be a finite force above 0 N"},
      {"no_patches", [](Config& c) { c.patches.clear(); }, "safety.patches is empty: a scene names at least one patch"},
      {"empty_id", [](Config& c) { c.patches[1].id.clear(); }, "safety.patches[1].id is empty"},
      {"dup_patch", [](Config& c) { c.patches[1].id = "forearm"; }, "safety.patches[1].id ('forearm') is a duplicate"},
      {"unknown_region", [](Config& c) { c.patches[0].region = "tail"; },
       "safety.patches[0].region ('tail') names no region in safety.regions"},
      {"zero_deadline", [](Config& c) { c.patches[1].silence_deadline_ns = 0; },
       "safety.patches[1].silence_deadline_ns (0) must be above 0"},
      {"joint_age", [](Config& c) { c.joint_state_max_age_ns = -5; },
       "safety.joint_state_max_age_ns (-5) must be above 0"},
      {"healthy_time", [](Config& c) { c.healthy_before_reset_ns = -1; },
       "safety.healthy_before_reset_ns (-1) must be 0 or more"},
  };
  EXPECT_NO_THROW(Validate(TwoPatchScene()));
  for (const BadConfig& bc : cases) {
    Config c = TwoPatchScene();
    bc.edit(c);
    try {
      Policy p(c);
      ADD_FAILURE() << bc.name << ": accepted";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), bc.message) << bc.name;
    }
  }
}

// --- Names ----------------------------------------------------------------------------------------------------

template <typename E>
void ExpectDistinctNames(std::size_t count, std::string_view (*name)(E) noexcept) {
  std::set<std::string_view> seen;
  for (std::size_t i = 0; i < count; ++i) {
    const std::string_view n = name(static_cast<E>(i));
    EXPECT_FALSE(n.empty());
    EXPECT_TRUE(seen.insert(n).second) << n;
    for (char ch : n) EXPECT_TRUE((ch >= 'a' && ch <= 'z') || ch == '_') << n;
  }
}

TEST(SafetyNames, AreDistinctSnakeCase) {
  ExpectDistinctNames<CauseKind>(kCauseKindCount, &CauseKindName);
  ExpectDistinctNames<ResetRefusal>(kResetRefusalCount, &ResetRefusalName);
  ExpectDistinctNames<LinkState>(kLinkStateCount, &LinkStateName);
  ExpectDistinctNames<PatchFaultCode>(kPatchFaultCodeCount, &PatchFaultCodeName);
  ExpectDistinctNames<Rejection>(kRejectionCount, &RejectionName);
  EXPECT_EQ(StateName(State::kStop), "stop");
}

namespace ruffini::safety {
namespace {

// Review finding 6 / issue 15 section 2: a contact hovering at its threshold (frames at 1 kHz, crossing it
// every 25 ms for 0.75 s: 30 crossings) is one cause, one epoch. Before the release hysteresis every crossing
// above was a new cause, and with new_epoch_per_cause (the default) a new epoch: 30 epochs.
TEST(SafetyHysteresis, AContactHoveringAtTheThresholdOpensOneEpoch) {
  Config c = TwoPatchScene();
  c.new_epoch_per_cause = true;
  testing::World w(c);
  w.Clear();
  const std::uint64_t epoch0 = w.epoch();
  for (int k = 0; k < 750; ++k) {
    w.Wait(1);
    const bool above = (k / 25) % 2 == 0;
    w.Contact("forearm", above ? 160.3f : 159.8f);
    if (k % 10 == 0) w.last = w.policy.OnHeartbeat(w.data, "upper_arm", {.healthy = true}, w.t);
    if (k % 10 == 0) w.last = w.policy.OnJointState(w.data, w.t);
  }
  EXPECT_EQ(w.epoch(), epoch0 + 1);
  EXPECT_EQ(w.data.counters().causes[static_cast<std::size_t>(CauseKind::kContact)], 1u);
  EXPECT_EQ(w.state(), State::kStop);
}

TEST(SafetyHysteresis, TheCauseEndsOnlyAfterTheForceStayedBelowTheReleaseLevelForTheHold) {
  Config c = TwoPatchScene();
  c.new_epoch_per_cause = true;
  c.regions[0].release = {.fraction = 0.1f, .hold_ns = 50 * kMs, .source = "test"};  // forearm: below 144 N
  testing::World w(c);
  w.Clear();
  w.touching = {"forearm"};
  w.Contact("forearm", 170.0f);
  ASSERT_EQ(w.epoch(), 2u);
  auto present = [&] {
    w.Reset(w.epoch());
    return w.reset.reason == ResetRefusal::kCausePresent && w.reset.blocking.kind == CauseKind::kContact;
  };
  // Between the release level (144 N) and the threshold: held, however long.
  for (int k = 0; k < 30; ++k) {
    w.Beat(10);
    w.Contact("forearm", 150.0f);
  }
  EXPECT_TRUE(present());
  // Below the release level for 40 ms, then above the threshold again: the same cause, no new epoch.
  w.Contact("forearm", 100.0f);
  w.Beat(40);
  w.Contact("forearm", 100.0f);
  EXPECT_TRUE(present());
  w.Contact("forearm", 165.0f);
  EXPECT_EQ(w.epoch(), 2u);
  // Below the release level for the full 50 ms: the cause is over (without another frame), and a reset clears.
  w.Contact("forearm", 100.0f);
  w.Beat(40);
  EXPECT_TRUE(present());
  w.Beat(10);
  w.Reset(w.epoch());
  EXPECT_TRUE(w.reset.accepted) << Describe(w.policy, w.reset);
  // Cleared: the next frame above the threshold is a new STOP at once (hysteresis never delays a stop).
  w.Contact("forearm", 160.5f);
  EXPECT_EQ(w.state(), State::kStop);
  EXPECT_EQ(w.epoch(), 3u);
}

TEST(SafetyHysteresis, ReleaseSettingsAreValidated) {
  Config c = TwoPatchScene();
  c.regions[1].release.fraction = 1.0f;
  EXPECT_THROW(Policy{c}, InputError);
  c = TwoPatchScene();
  c.regions[1].release.hold_ns = -1;
  EXPECT_THROW(Policy{c}, InputError);
  c = TwoPatchScene();
  c.input.negative_force_tolerance_n = -0.1f;
  EXPECT_THROW(Policy{c}, InputError);
  c = TwoPatchScene();
  c.input.max_time_skew_ns = 0;
  EXPECT_THROW(Policy{c}, InputError);
}

// The same rejection again is the same cause: a stream of refused heartbeats (an unknown patch here) takes
// one epoch, not one each (before: one epoch per heartbeat with new_epoch_per_cause).
TEST(SafetyRejections, TheSameRejectionAgainTakesNoNewEpoch) {
  Config c = TwoPatchScene();
  c.new_epoch_per_cause = true;
  testing::World w(c);
  w.Clear();
  for (int k = 0; k < 100; ++k) {
    w.Beat(10);  // the scene's patches stay healthy
    w.last = w.policy.OnHeartbeat(w.data, "tail", {.healthy = true}, w.t);
    EXPECT_EQ(w.last.rejection, Rejection::kUnknownPatch);
  }
  EXPECT_EQ(w.epoch(), 2u);
  EXPECT_EQ(w.data.counters().rejections[static_cast<std::size_t>(Rejection::kUnknownPatch)], 100u);
  // Another kind of rejection is a new cause.
  w.Contact("forearm", kNaN);
  EXPECT_EQ(w.epoch(), 3u);
}

// Every latch, escalation, new epoch, shutdown and reset is recorded once for the caller's log.
TEST(SafetyEvents, LatchesEscalationsAndResetsAreRecorded) {
  Config c = TwoPatchScene();
  c.new_epoch_per_cause = true;
  testing::World w(c);
  w.Clear();
  ASSERT_EQ(w.data.events().size(), 1u);  // the start-up reset (the start-up latch is the Data's initial state)
  EXPECT_EQ(w.data.events()[0].type, EventType::kResetAccepted);
  EXPECT_EQ(w.data.events()[0].reset_epoch, 1u);
  w.data.ClearEvents();
  w.Contact("forearm", 200.0f);
  w.Contact("forearm", 201.0f);  // held: nothing new
  w.last = w.policy.OnPatchFault(w.data, "upper_arm", PatchFaultCode::kFramesLost, w.t);
  w.Contact("upper_arm", 180.0f);
  w.Reset(2);
  (void)w.policy.Shutdown(w.data, w.t);
  const auto ev = w.data.events();
  ASSERT_EQ(ev.size(), 5u);
  EXPECT_EQ(ev[0].type, EventType::kLatch);
  EXPECT_EQ(ev[0].stop_epoch, 2u);
  EXPECT_EQ(ev[0].cause.kind, CauseKind::kContact);
  EXPECT_EQ(ev[0].cause.patch, 0);
  EXPECT_FLOAT_EQ(ev[0].cause.force_n, 200.0f);
  EXPECT_EQ(ev[1].type, EventType::kEscalation);
  EXPECT_EQ(ev[1].state, State::kFault);
  EXPECT_EQ(ev[1].stop_epoch, 3u);
  EXPECT_EQ(ev[2].type, EventType::kNewEpoch);
  EXPECT_EQ(ev[2].stop_epoch, 4u);
  EXPECT_EQ(ev[3].type, EventType::kResetRefused);
  EXPECT_EQ(ev[3].reset_refusal, ResetRefusal::kWrongEpoch);
  EXPECT_EQ(ev[3].reset_epoch, 2u);
  EXPECT_EQ(ev[4].type, EventType::kShutdown);
  EXPECT_EQ(EventTypeName(EventType::kNewEpoch), "new_epoch");
  // Full: the oldest are dropped and counted, the newest kept.
  for (int k = 0; k < 20; ++k) w.Reset(1);
  EXPECT_EQ(w.data.events().size(), kEventCapacity);
  EXPECT_EQ(w.data.counters().events_dropped, 5u + 20u - kEventCapacity);
}

}  // namespace
}  // namespace ruffini::safety

// The scene's stop rule (Config::stop_rule, docs/safety.md "The stop rule"): a contact is judged at
// force + sd_k x sd.
void Judge(World& w, float force_n, float sd_n, bool over_range = false, bool saturated = false) {
  w.last = w.policy.OnContact(
      w.data, "forearm", {.force_n = force_n, .force_sd_n = sd_n, .over_range = over_range, .saturated = saturated}, w.t);
}

TEST(SafetyStopRule, ThePositiveRuleStopsOnAnUncertainReadingBelowTheThreshold) {
  Config c = TwoPatchScene();
  c.stop_rule.sd_k = 1.0f;
  World w(c);
  w.Clear();
  Judge(w, 150.0f, 5.0f);  // 155 N judged: below 160
  EXPECT_EQ(w.state(), State::kClear);
  Judge(w, 150.0f, 15.0f);  // 165 N judged
  EXPECT_EQ(w.state(), State::kStop);
  EXPECT_FLOAT_EQ(w.data.state().cause.judged_n, 165.0f);
  EXPECT_NE(Describe(w.policy, w.data.state().cause).find("force 150 N (judged 165 N with its sd) above region 'forearm'"),
            std::string::npos)
      << Describe(w.policy, w.data.state().cause);
  // The default rule (sd_k 0) judges the force alone.
  World d;
  d.Clear();
  d.last = d.policy.OnContact(d.data, "forearm", {.force_n = 150.0f, .force_sd_n = 15.0f}, d.t);
  EXPECT_EQ(d.state(), State::kClear);
}

TEST(SafetyStopRule, AnUnreadableSdIsADoubtForThePositiveRuleAndIgnoredByTheNegative) {
  for (const float bad : {kNaN, std::numeric_limits<float>::infinity(), -1.0f}) {
    Config c = TwoPatchScene();
    c.stop_rule.sd_k = 0.5f;
    World w(c);
    w.Clear();
    Judge(w, 1.0f, bad);
    EXPECT_EQ(w.state(), State::kStop) << bad;
    c.stop_rule.sd_k = -2.0f;
    World n(c);
    n.Clear();
    Judge(n, 161.0f, bad);  // never lowered by an sd it cannot read
    EXPECT_EQ(n.state(), State::kStop) << bad;
  }
}

TEST(SafetyStopRule, TheNegativeRuleAsksForMarginAndIsBounded) {
  Config c = TwoPatchScene();
  c.stop_rule.sd_k = -2.0f;
  c.stop_rule.max_sd_n = 1.0f;
  World w(c);
  w.Clear();
  Judge(w, 161.0f, 0.4f);  // 160.2 judged: still above
  EXPECT_EQ(w.state(), State::kStop);
  World b(c);
  b.Clear();
  Judge(b, 161.0f, 1.0f);  // 159 judged: the reading does not clear the threshold by 2 sigma
  EXPECT_EQ(b.state(), State::kClear);
  // An sd above max_sd_n (a broken or forged decoder) never lowers: 161 N with an sd of 1000 N or FLT_MAX stops.
  for (const float huge : {1000.0f, std::numeric_limits<float>::max()}) {
    World h(c);
    h.Clear();
    Judge(h, 161.0f, huge);
    EXPECT_EQ(h.state(), State::kStop) << huge;
  }
  // An over-range contact's force is a lower bound: never lowered.
  World o(c);
  o.Clear();
  Judge(o, 160.5f, 1.0f, /*over_range=*/true);
  EXPECT_EQ(o.state(), State::kStop);
}

// An over-range contact stops whatever the region's threshold: its force is a lower bound (2.5 N from the shipped
// decoders), and a region at 160 N would otherwise never stop on a saturated press (review 10, finding 8). The
// same force not over range does not stop, and the cause holds while over-range frames go on.
TEST(SafetyStopRule, AnOverRangeContactStopsAboveAnyThreshold) {
  World w(TwoPatchScene());  // forearm region: 160 N
  w.Clear();
  Judge(w, 2.5f, 0.1f);
  EXPECT_EQ(w.state(), State::kClear);
  Judge(w, 2.5f, 0.1f, /*over_range=*/true);  // a lower bound only (a two-touch frame's raised force): judged
  EXPECT_EQ(w.state(), State::kClear);
  Judge(w, 2.5f, 0.1f, /*over_range=*/true, /*saturated=*/true);
  EXPECT_EQ(w.state(), State::kStop);
  w.touching.insert("forearm");
  for (int k = 0; k < 30; ++k) {  // 300 ms of over-range frames, every patch healthy
    w.Beat(10);
    Judge(w, 2.5f, 0.1f, /*over_range=*/true, /*saturated=*/true);
  }
  EXPECT_EQ(w.state(), State::kStop);
  const ResetResult r = w.ResetCurrent();
  EXPECT_FALSE(r.accepted) << "a reset while the over-range press is held";
  EXPECT_EQ(r.reason, ResetRefusal::kCausePresent);
}

// A lowering rule may delay a STOP's start, never end one early: the release is judged on the force too.
// (The adversarial review: a contact eased to just above the release level, its reading lowered below it,
// had its cause ended after the hold.)
TEST(SafetyStopRule, ALoweringRuleNeverEndsACauseWhileTheForceIsAboveTheReleaseLevel) {
  Config c = TwoPatchScene();
  c.stop_rule.sd_k = -2.0f;
  c.stop_rule.max_sd_n = 1.0f;
  World w(c);
  w.Clear();
  w.touching.insert("forearm");
  Judge(w, 170.0f, 1.0f);
  ASSERT_EQ(w.state(), State::kStop);
  // 145 N: above the release level (160 x 0.9 = 144), judged 143 N (below it).
  for (int k = 0; k < 30; ++k) {
    w.Beat(10);
    Judge(w, 145.0f, 1.0f);
  }
  EXPECT_EQ(w.ResetCurrent().reason, ResetRefusal::kCausePresent) << "the contact cause ended while 145 N was read";
  EXPECT_EQ(w.state(), State::kStop);
  // Once the force itself is below the release level for the hold, the cause ends.
  for (int k = 0; k < 30; ++k) {
    w.Beat(10);
    Judge(w, 100.0f, 1.0f);
  }
  EXPECT_TRUE(w.ResetCurrent().accepted);
}

TEST(SafetyStopRule, JudgedForceNeverGoesBelowZeroAndTheConfigIsValidated) {
  Config::StopRule neg;
  neg.sd_k = -3.0f;
  neg.max_sd_n = 10.0f;
  EXPECT_EQ(JudgedForce(0.5f, 5.0f, false, neg), 0.0f);
  EXPECT_EQ(JudgedForce(0.5f, 5.0f, false, Config::StopRule{}), 0.5f);
  for (const auto& [k, max_sd] : {std::pair{3.5f, 0.5f}, std::pair{kNaN, 0.5f}, std::pair{1.0f, 0.0f}}) {
    Config::StopRule bad;
    bad.sd_k = k;
    bad.max_sd_n = max_sd;
    Config c = TwoPatchScene();
    c.stop_rule = bad;
    EXPECT_THROW(Validate(c), InputError);
  }
  // The largest lowering must stay within half of every threshold: 1 x 1 N against a 1.5 N region is refused.
  Config c = TwoPatchScene();
  c.regions[2].threshold_n = 1.5f;
  c.stop_rule.sd_k = -1.0f;
  c.stop_rule.max_sd_n = 1.0f;
  EXPECT_THROW(Validate(c), InputError);
  c.stop_rule.max_sd_n = 0.5f;
  EXPECT_NO_THROW(Validate(c));
}

}  // namespace
}  // namespace ruffini::safety
