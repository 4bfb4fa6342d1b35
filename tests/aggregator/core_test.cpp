// aggregate::Core without the network, on an injected clock: the Connect stream rules (hello checks, seq),
// joint-state validation, body-frame placement with interpolated joint states, and what reaches the policy.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <random>

#include "ruffini/aggregate/core.h"
#include "ruffini/error.h"
#include "ruffini/robot/scene.h"
#include "ruffini/safety/scene.h"
#include "ruffini/scene_file.h"
#include "ruffini/twin/scene.h"
#include "sealed.h"

// The program runner of the Core's fuzz target (tests/fuzz): bytes -> streams, joint states, resets, ticks,
// with the safety invariants checked after every step.
#include "../fuzz/core_program.h"

namespace {

using namespace ruffini;

constexpr std::int64_t kT0 = 1'700'000'000'000'000'000;
constexpr std::int64_t kMs = 1'000'000;
const std::string kScene = std::string(RUFFINI_SOURCE_DIR) + "/config/scenes/cobot.yaml";
constexpr std::uint64_t kRunId = 0x5eed'1234'abcd'0001;

aggregate::Setup CobotSetup() {
  const SceneFile file = LoadSceneFile(kScene);
  aggregate::Setup s;
  s.safety = safety::ConfigFromScene(file);
  const auto robot = robot::LoadRobotScene(file);
  s.robot = robot.model;
  const auto scene = twin::LoadScene(kScene);
  for (const auto& p : scene.patches) {
    aggregate::PatchExpectation e;
    e.id = p.name;
    e.spec_name = p.spec.name;
    e.spec_fingerprint = p.spec.Fingerprint();
    e.model_sha256 = "abc";
    e.mount = robot.FindPatch(p.name)->mount;
    s.patches.push_back(e);
  }
  s.run_id = kRunId;
  s.robot_name = file.name;
  return s;
}

v1::PatchMessage Hello(const aggregate::Setup& s, std::size_t patch) {
  v1::PatchMessage m;
  m.set_patch_id(s.patches[patch].id);
  m.set_seq(1);
  auto* h = m.mutable_hello();
  h->set_patch_name(s.patches[patch].spec_name);
  h->set_patch_fingerprint(s.patches[patch].spec_fingerprint);
  h->set_model_patch_fingerprint(s.patches[patch].spec_fingerprint);
  h->set_model_sha256("abc");
  h->set_heartbeat_period_ns(10 * kMs);
  return m;
}

class CoreTest : public ::testing::Test {
 protected:
  CoreTest() : CoreTest(CobotSetup()) {}
  explicit CoreTest(aggregate::Setup s) : setup(std::move(s)), core(setup, kT0) {}
  // Opens a stream for patch i and sends its hello; returns the stream id.
  int Connect(std::size_t i, std::int64_t t) {
    const int s = core.OpenStream(t);
    const auto r = ruffini::testing::Deliver(core, s, Hello(setup, i), t);
    EXPECT_TRUE(r.command && r.command->has_hello_accepted()) << (r.command ? r.command->DebugString() : "none");
    seq[s] = 1;
    return s;
  }
  aggregate::Core::Reply Send(int stream, std::size_t i, v1::PatchMessage m, std::int64_t t) {
    m.set_patch_id(setup.patches[i].id);
    m.set_seq(++seq[stream]);
    return ruffini::testing::Deliver(core, stream, m, t);
  }
  aggregate::Core::Reply Heartbeat(int stream, std::size_t i, std::int64_t t, bool healthy = true) {
    v1::PatchMessage m;
    m.mutable_heartbeat()->set_healthy(healthy);
    return Send(stream, i, m, t);
  }
  v1::JointState Joints(std::int64_t t, double q) const {
    v1::JointState js;
    for (std::size_t i = 0; i < setup.robot->num_dof(); ++i) {
      js.add_names(setup.robot->dof_joint(i).name);
      js.add_positions_rad(q);
    }
    js.set_t_ns(t);
    return js;
  }
  v1::ResetStopRequest ResetRequest(std::uint64_t epoch, std::uint64_t run = kRunId) const {
    v1::ResetStopRequest r;
    r.set_stop_epoch(epoch);
    r.set_aggregator_run_id(run);
    r.set_operator_name("alice");
    return r;
  }
  // Every patch connected, healthy heartbeats and joint states every 10 ms for 300 ms, the start-up latch
  // reset: CLEAR at `tc` (returned streams in scene order).
  std::vector<int> ClearAll() {
    std::vector<int> streams;
    for (std::size_t i = 0; i < setup.patches.size(); ++i) streams.push_back(Connect(i, tc));
    Beat(streams, 300);
    const auto r = core.OnReset(ResetRequest(core.SafetyState().stop_epoch()), true, tc);
    EXPECT_TRUE(r.accepted()) << r.message();
    return streams;
  }
  // dt_ms of 10 ms steps: a healthy heartbeat on every stream (unless skipped) and a joint state.
  void Beat(const std::vector<int>& streams, int dt_ms, int skip = -1) {
    for (int k = 0; k < dt_ms / 10; ++k) {
      tc += 10 * kMs;
      core.OnJointState(Joints(tc, 0.1), tc);
      for (std::size_t i = 0; i < streams.size(); ++i) {
        if (static_cast<int>(i) != skip) Heartbeat(streams[i], i, tc);
      }
      core.Tick(tc);
    }
  }
  v1::PatchMessage ContactMsg(float force_n, std::int64_t t_ns) const {
    v1::PatchMessage m;
    m.set_t_ns(t_ns);
    m.mutable_contact()->set_force_n(force_n);
    return m;
  }
  aggregate::Setup setup;
  aggregate::Core core;
  std::map<int, std::uint64_t> seq;
  std::int64_t tc = kT0;  // the test's clock
};

TEST_F(CoreTest, StartsInFaultAndHellosAreChecked) {
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT);
  EXPECT_EQ(core.SafetyState().cause().kind(), v1::SafetyCause::KIND_STARTUP);
  struct Row {
    const char* what;
    std::function<void(v1::PatchMessage&)> edit;
    v1::HelloRefusal expect;
  };
  const std::vector<Row> rows = {
      {"not a hello first", [](v1::PatchMessage& m) { m.mutable_heartbeat(); }, v1::HELLO_REFUSAL_PROTOCOL_ERROR},
      {"seq 2 first", [](v1::PatchMessage& m) { m.set_seq(2); }, v1::HELLO_REFUSAL_PROTOCOL_ERROR},
      {"unknown patch", [](v1::PatchMessage& m) { m.set_patch_id("elbow"); }, v1::HELLO_REFUSAL_UNKNOWN_PATCH},
      {"other spec", [](v1::PatchMessage& m) { m.mutable_hello()->set_patch_fingerprint("00"); },
       v1::HELLO_REFUSAL_SPEC_MISMATCH},
      {"model for another spec", [](v1::PatchMessage& m) { m.mutable_hello()->set_model_patch_fingerprint("00"); },
       v1::HELLO_REFUSAL_SPEC_MISMATCH},
      {"other model", [](v1::PatchMessage& m) { m.mutable_hello()->set_model_sha256("def"); },
       v1::HELLO_REFUSAL_MODEL_MISMATCH},
      {"slow heartbeat", [](v1::PatchMessage& m) { m.mutable_hello()->set_heartbeat_period_ns(50 * kMs); },
       v1::HELLO_REFUSAL_RATE_MISMATCH},
  };
  for (const auto& row : rows) {
    v1::PatchMessage m = Hello(setup, 0);
    row.edit(m);
    const int s = core.OpenStream(kT0);
    const auto r = ruffini::testing::Deliver(core, s, m, kT0);
    ASSERT_TRUE(r.command) << row.what;
    ASSERT_TRUE(r.command->has_hello_refused()) << row.what;
    EXPECT_EQ(r.command->hello_refused().reason(), row.expect) << row.what;
    EXPECT_TRUE(r.close) << row.what;
    EXPECT_FALSE(r.command->hello_refused().message().empty());
    core.CloseStream(s, kT0);
  }
  // Accepted; a second live stream for the same patch is refused.
  const int first = Connect(0, kT0);
  const int second = core.OpenStream(kT0);
  const auto dup = ruffini::testing::Deliver(core, second, Hello(setup, 0), kT0);
  ASSERT_TRUE(dup.command && dup.command->has_hello_refused());
  EXPECT_EQ(dup.command->hello_refused().reason(), v1::HELLO_REFUSAL_DUPLICATE_PATCH);
  (void)first;
}

// A hello naming a patch the scene does not have is refused and counted, and changes nothing: not the safety
// state, not its epoch, not any patch's link (the second adversarial review's F5: it used to FAULT the robot
// with KIND_INTERNAL, so any caller could stop the cell by naming a patch that does not exist).
TEST_F(CoreTest, AHelloForAPatchTheSceneDoesNotHaveIsRefusedAndChangesNothing) {
  const std::vector<int> streams = ClearAll();
  ASSERT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  const v1::SafetyState before = core.SafetyState();
  const auto status_before = core.Status(tc);
  for (int k = 0; k < 3; ++k) {
    v1::PatchMessage m = Hello(setup, 0);
    m.set_patch_id("elbow");
    const int s = core.OpenStream(tc);
    const auto r = ruffini::testing::Deliver(core, s, m, tc);
    ASSERT_TRUE(r.command && r.command->has_hello_refused());
    EXPECT_EQ(r.command->hello_refused().reason(), v1::HELLO_REFUSAL_UNKNOWN_PATCH);
    EXPECT_NE(r.command->hello_refused().message().find("elbow"), std::string::npos);
    EXPECT_TRUE(r.close);
    core.CloseStream(s, tc);
    Beat(streams, 20);  // the scene's own patches keep beating: the refusals are all that happens
  }
  EXPECT_EQ(core.counters().hellos_refused[v1::HELLO_REFUSAL_UNKNOWN_PATCH], 3u);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  EXPECT_EQ(core.SafetyState().stop_epoch(), before.stop_epoch());
  const auto status_after = core.Status(tc);
  for (int i = 0; i < status_after.patches_size(); ++i) {
    EXPECT_EQ(status_after.patches(i).link_state(), status_before.patches(i).link_state()) << i;
  }
}

// A stream opened for a caller whose certificate names forearm_a (docs/security.md): a hello for forearm_b is
// refused UNAUTHORIZED, counted, and changes nothing: not forearm_b's live link, not the safety state.
TEST_F(CoreTest, AHelloForAnotherPatchThanTheCallersIsUnauthorizedAndChangesNothing) {
  const int live = Connect(1, kT0);  // forearm_b, held by its own decoder
  const v1::SafetyState before = core.SafetyState();
  const auto status_before = core.Status(kT0 + kMs);
  const int impostor = core.OpenStream(kT0 + kMs, setup.patches[0].id);
  const auto r = ruffini::testing::Deliver(core, impostor, Hello(setup, 1), kT0 + kMs);
  ASSERT_TRUE(r.command && r.command->has_hello_refused());
  EXPECT_EQ(r.command->hello_refused().reason(), v1::HELLO_REFUSAL_UNAUTHORIZED);
  EXPECT_NE(r.command->hello_refused().message().find("forearm_a"), std::string::npos);
  EXPECT_TRUE(r.close);
  EXPECT_EQ(core.counters().hellos_refused[v1::HELLO_REFUSAL_UNAUTHORIZED], 1u);
  core.CloseStream(impostor, kT0 + kMs);
  EXPECT_EQ(core.SafetyState().state(), before.state());
  EXPECT_EQ(core.SafetyState().stop_epoch(), before.stop_epoch());
  const auto status_after = core.Status(kT0 + kMs);
  EXPECT_EQ(status_after.patches(1).link_state(), status_before.patches(1).link_state());
  EXPECT_EQ(status_after.patches(0).link_state(), status_before.patches(0).link_state());
  // The same caller publishing its own patch is accepted.
  const int own = core.OpenStream(kT0 + 2 * kMs, setup.patches[0].id);
  const auto ok = ruffini::testing::Deliver(core, own, Hello(setup, 0), kT0 + 2 * kMs);
  ASSERT_TRUE(ok.command && ok.command->has_hello_accepted()) << ok.command->DebugString();
  (void)live;
}

TEST_F(CoreTest, ASeqBreakEndsTheStreamAndFaults) {
  std::vector<int> streams;
  for (std::size_t i = 0; i < setup.patches.size(); ++i) streams.push_back(Connect(i, kT0));
  v1::PatchMessage m;
  m.mutable_heartbeat()->set_healthy(true);
  m.set_patch_id(setup.patches[0].id);
  m.set_seq(5);  // expected 2
  const auto r = ruffini::testing::Deliver(core, streams[0], m, kT0 + kMs);
  EXPECT_TRUE(r.close);
  EXPECT_FALSE(r.command);
  EXPECT_EQ(core.counters().protocol_errors, 1u);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT);
  // A message without a body is a protocol error too.
  v1::PatchMessage empty;
  EXPECT_TRUE(Send(streams[1], 1, empty, kT0 + 2 * kMs).close);
}

TEST_F(CoreTest, JointStatesAreValidated) {
  EXPECT_EQ(core.OnJointState(Joints(kT0, 0.1), kT0), aggregate::JointRejection::kNone);
  EXPECT_EQ(core.OnJointState(Joints(kT0, 0.1), kT0), aggregate::JointRejection::kNotMonotonic);
  auto short_js = Joints(kT0 + kMs, 0.1);
  short_js.mutable_positions_rad()->RemoveLast();
  EXPECT_EQ(core.OnJointState(short_js, kT0), aggregate::JointRejection::kWrongCount);
  auto renamed = Joints(kT0 + kMs, 0.1);
  renamed.set_names(2, "elbow");
  EXPECT_EQ(core.OnJointState(renamed, kT0), aggregate::JointRejection::kWrongNames);
  auto nan = Joints(kT0 + kMs, 0.1);
  nan.set_positions_rad(3, std::nan(""));
  EXPECT_EQ(core.OnJointState(nan, kT0), aggregate::JointRejection::kNotFinite);
  EXPECT_EQ(core.counters().joint_states[0], 1u);
  EXPECT_EQ(core.OnJointState(Joints(kT0 + kMs, 0.2), kT0 + kMs), aggregate::JointRejection::kNone);
  // Names sent once, then left empty: the robot's order.
  auto unnamed = Joints(kT0 + 2 * kMs, 0.3);
  unnamed.clear_names();
  EXPECT_EQ(core.OnJointState(unnamed, kT0 + 2 * kMs), aggregate::JointRejection::kNone);
  unnamed.set_t_ns(kT0 + 3 * kMs);
  unnamed.mutable_positions_rad()->RemoveLast();
  EXPECT_EQ(core.OnJointState(unnamed, kT0 + 3 * kMs), aggregate::JointRejection::kWrongCount);
}

TEST_F(CoreTest, ContactsArePlacedWithTheJointStateAtTheirTime) {
  std::vector<int> streams;
  for (std::size_t i = 0; i < setup.patches.size(); ++i) streams.push_back(Connect(i, kT0));
  core.OnJointState(Joints(kT0, 0.0), kT0);
  core.OnJointState(Joints(kT0 + 10 * kMs, 0.4), kT0 + 10 * kMs);
  v1::PatchMessage m;
  m.set_t_ns(kT0 + 5 * kMs);  // halfway: q = 0.2 on every joint
  auto* c = m.mutable_contact();
  c->set_force_n(0.5f);
  c->set_located(true);
  c->set_y_mm(60);
  c->set_r_deg(30);
  c->set_onset(true);
  Send(streams[2], 2, m, kT0 + 11 * kMs);
  const v1::ContactSet set = core.Contacts(kT0 + 11 * kMs);
  ASSERT_EQ(set.contacts_size(), 1);
  const auto& b = set.contacts(0);
  EXPECT_EQ(b.link(), "upper_arm_link");
  EXPECT_EQ(b.body_region(), "upper_arm");
  // The expected point: FK at q = 0.2, the mount's map.
  robot::Data fk;
  std::vector<double> q(setup.robot->num_dof(), 0.2);
  ASSERT_EQ(robot::ForwardKinematics(*setup.robot, q, fk), robot::FkStatus::kOk);
  const auto& mount = *setup.patches[2].mount;
  const auto s = robot::PatchToLink(mount, {60.0, 30.0});
  const Eigen::Vector3d p = fk.X_BL[*setup.robot->FindLink(mount.link)] * s.p_LS_m;
  EXPECT_NEAR(b.p_bc_m().x(), p.x(), 1e-9);
  EXPECT_NEAR(b.p_bc_m().y(), p.y(), 1e-9);
  EXPECT_NEAR(b.p_bc_m().z(), p.z(), 1e-9);
  const Eigen::Vector3d n(b.normal_b().x(), b.normal_b().y(), b.normal_b().z());
  EXPECT_NEAR(n.norm(), 1.0, 1e-9);
  // Released: gone from the set.
  v1::PatchMessage r;
  r.set_t_ns(kT0 + 6 * kMs);
  r.mutable_contact()->set_released(true);
  Send(streams[2], 2, r, kT0 + 12 * kMs);
  EXPECT_EQ(core.Contacts(kT0 + 12 * kMs).contacts_size(), 0);
}

TEST_F(CoreTest, AHardContactStopsAndTheLatencyIsMeasured) {
  std::vector<int> streams;
  for (std::size_t i = 0; i < setup.patches.size(); ++i) streams.push_back(Connect(i, kT0));
  std::int64_t t = kT0;
  for (; t < kT0 + 300 * kMs; t += 10 * kMs) {
    core.OnJointState(Joints(t, 0.1), t);
    for (std::size_t i = 0; i < streams.size(); ++i) Heartbeat(streams[i], i, t);
    core.Tick(t);
  }
  const auto reset = core.OnReset([] {
    v1::ResetStopRequest r;
    r.set_stop_epoch(1);
    r.set_aggregator_run_id(kRunId);
    return r;
  }(), true, t);
  ASSERT_TRUE(reset.accepted()) << reset.message();
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  // 1.2 N (below 1.5 N): no stop; 1.8 N: STOP, the frame 0.4 ms before.
  v1::PatchMessage light;
  light.set_t_ns(t);
  light.mutable_contact()->set_force_n(1.2f);
  light.mutable_contact()->set_onset(true);
  Send(streams[0], 0, light, t);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  v1::PatchMessage hard;
  hard.set_t_ns(t + kMs);
  hard.mutable_contact()->set_force_n(1.8f);
  Send(streams[0], 0, hard, t + kMs + 400'000);
  const auto st = core.SafetyState();
  EXPECT_EQ(st.state(), v1::SafetyState::STATE_STOP);
  EXPECT_EQ(st.cause().patch_id(), "forearm_a");
  EXPECT_EQ(st.cause().link(), "forearm_link");
  EXPECT_FLOAT_EQ(st.cause().threshold_n(), 1.5f);
  EXPECT_EQ(core.TakeStopLatencyNs(), 400'000);
  EXPECT_EQ(core.TakeStopLatencyNs(), -1);
  // The same STOP published again (heartbeats, another frame above threshold) is not a new sample.
  core.Publish(t + 10 * kMs);
  Send(streams[0], 0, hard, t + 11 * kMs);
  EXPECT_EQ(core.TakeStopLatencyNs(), -1);
  // A NaN force is never sent as NaN.
  v1::PatchMessage nan;
  nan.set_t_ns(t + 2 * kMs);
  nan.mutable_contact()->set_force_n(std::nanf(""));
  Send(streams[1], 1, nan, t + 2 * kMs);
  EXPECT_TRUE(std::isfinite(core.SafetyState().cause().force_n()));
  EXPECT_NE(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
}

// The scene's stop rule reaches the policy through the Core: with sd_k 1, a calibrated 1.3 N +- 0.3 N contact
// is judged at 1.6 N and stops; the same reading without calibrated uncertainty is judged at 1.3 N.
class CoreStopRule : public CoreTest {
 protected:
  static aggregate::Setup WithSdK(float k) {
    aggregate::Setup s = CobotSetup();
    s.safety.stop_rule.sd_k = k;
    s.safety.stop_rule.source = "test";
    return s;
  }
  CoreStopRule() : CoreTest(WithSdK(1.0f)) {}
  explicit CoreStopRule(float k) : CoreTest(WithSdK(k)) {}
};

class CoreLoweringStopRule : public CoreStopRule {
 protected:
  CoreLoweringStopRule() : CoreStopRule(-1.0f) {}
};

// With sd_k -1 a two-touch frame's force (the stronger fitted touch's lower bound) is never lowered again:
// 1.6 N +- 0.3 N flagged multiple stops; the same reading of one touch is judged 1.3 N.
// Issue 17: a frame flagged faint (every shift within a baseline error) is judged at its force as read, as an
// unflagged one: 1.2 x the threshold STOPs, the cause carries that force and says "faint", the reset is refused
// while it lasts; the flag reaches the body contact and the counter. Below the threshold it changes nothing
// either (CLEAR, flagged in the set).
TEST_F(CoreTest, AFaintContactStopsAtItsForceAndTheFlagReachesTheSetAndTheCause) {
  const std::vector<int> streams = ClearAll();
  const float threshold = setup.safety.regions[static_cast<std::size_t>(
      core.policy().FindRegion(setup.safety.patches[2].region))].threshold_n;
  auto faint = [&](float force_n, bool onset) {
    v1::PatchMessage m = ContactMsg(force_n, tc);
    auto* c = m.mutable_contact();
    c->set_onset(onset);
    c->set_located(true);
    c->set_y_mm(60);
    c->set_r_deg(30);
    c->set_faint(true);
    return m;
  };
  Send(streams[2], 2, faint(0.8f * threshold, true), tc);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  {
    const v1::ContactSet set = core.Contacts(tc);
    ASSERT_EQ(set.contacts_size(), 1);
    EXPECT_TRUE(set.contacts(0).faint());
    EXPECT_FLOAT_EQ(set.contacts(0).force_n(), 0.8f * threshold) << "the force is shown as read";
  }
  tc += 10 * kMs;
  Send(streams[2], 2, faint(1.2f * threshold, false), tc);
  const auto st = core.SafetyState();
  ASSERT_EQ(st.state(), v1::SafetyState::STATE_STOP) << "a faint contact above its threshold stops";
  EXPECT_EQ(st.cause().kind(), v1::SafetyCause::KIND_CONTACT);
  EXPECT_FLOAT_EQ(st.cause().force_n(), 1.2f * threshold);
  EXPECT_NE(st.cause().message().find("[faint:"), std::string::npos) << st.cause().message();
  EXPECT_TRUE(core.Contacts(tc).contacts(0).faint());
  EXPECT_EQ(core.counters().contacts_faint, 2u);
  // Still pressed, still flagged: the STOP holds and a reset is refused.
  for (int k = 0; k < 30; ++k) {
    Beat(streams, 10, 2);
    v1::PatchMessage hb;
    hb.mutable_heartbeat()->set_healthy(true);
    hb.mutable_heartbeat()->set_in_contact(true);
    Send(streams[2], 2, hb, tc);
    Send(streams[2], 2, faint(1.2f * threshold, false), tc);
  }
  const auto r = core.OnReset(ResetRequest(core.SafetyState().stop_epoch()), true, tc);
  EXPECT_FALSE(r.accepted()) << r.message();
  EXPECT_EQ(r.reason(), v1::RESET_REFUSAL_CAUSE_PRESENT) << r.message();
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_STOP);
  // An unflagged contact's cause does not say faint, and its body contact is not flagged.
  v1::PatchMessage firm = ContactMsg(2.0f * threshold, tc);
  firm.mutable_contact()->set_onset(true);
  Send(streams[0], 0, firm, tc);
  const v1::ContactSet set = core.Contacts(tc);
  int firm_seen = 0;
  for (const auto& b : set.contacts()) {
    if (b.patch_ids(0) != setup.patches[0].id) continue;
    ++firm_seen;
    EXPECT_FALSE(b.faint());
  }
  EXPECT_EQ(firm_seen, 1) << set.DebugString();
  EXPECT_EQ(core.counters().contacts_faint, 32u);
}

TEST_F(CoreLoweringStopRule, ATwoTouchFramesForceIsALowerBoundAndNotLowered) {
  const std::vector<int> streams = ClearAll();
  const std::int64_t t = tc;
  v1::PatchMessage m;
  m.set_t_ns(t);
  auto* c = m.mutable_contact();
  c->set_force_n(1.6f);
  c->set_force_sd_n(0.3f);
  c->set_uncertainty_calibrated(true);
  c->set_onset(true);
  c->set_located(true);
  c->set_y_mm(75.0f);
  c->set_r_deg(72.5f);
  c->set_cov_yy_mm2(400.0f);
  c->set_cov_rr_mm2(400.0f);
  Send(streams[0], 0, m, t);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR) << "one touch: judged 1.3 N";
  m.set_t_ns(t + kMs);
  c->set_onset(false);
  c->set_multiple(true);
  Send(streams[0], 0, m, t + kMs);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_STOP);
}

// An over-range contact (saturated, lost or out-of-band peaks under load) stops whatever its force says: the force
// is the decoder's lower bound (review 10, finding 8: a region above it would never stop on a saturated press). A
// two-touch frame's raised force, also a lower bound, is judged as before.
TEST_F(CoreTest, AnOverRangeContactStopsBelowTheThresholdATwoTouchFrameDoesNot) {
  const std::vector<int> streams = ClearAll();
  const float threshold = setup.safety.regions[static_cast<std::size_t>(
      core.policy().FindRegion(setup.safety.patches[2].region))].threshold_n;
  v1::PatchMessage m = ContactMsg(0.5f * threshold, tc);
  m.mutable_contact()->set_onset(true);
  m.mutable_contact()->set_located(true);
  m.mutable_contact()->set_y_mm(60);
  m.mutable_contact()->set_r_deg(30);
  m.mutable_contact()->set_multiple(true);
  Send(streams[2], 2, m, tc);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR) << "a two-touch frame at half the threshold";
  v1::PatchMessage o = ContactMsg(0.5f * threshold, tc + kMs);
  o.mutable_contact()->set_over_range(true);
  Send(streams[2], 2, o, tc + kMs);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_STOP) << "an over-range contact at half the threshold";
}

TEST_F(CoreStopRule, ACalibratedSdIsJudgedAndAnUncalibratedOneIsNot) {
  const std::vector<int> streams = ClearAll();
  const std::int64_t t = tc;
  ASSERT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  v1::PatchMessage m;
  m.set_t_ns(t);
  m.mutable_contact()->set_force_n(1.3f);
  m.mutable_contact()->set_force_sd_n(0.3f);
  m.mutable_contact()->set_onset(true);
  Send(streams[0], 0, m, t);  // uncertainty_calibrated false: the sd is not read
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  m.set_t_ns(t + kMs);
  m.mutable_contact()->set_onset(false);
  m.mutable_contact()->set_uncertainty_calibrated(true);
  Send(streams[0], 0, m, t + kMs);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_STOP);
  EXPECT_FLOAT_EQ(core.SafetyState().cause().force_n(), 1.3f);  // the cause carries the force as received
}

// The forearm seam (issue 16, docs/fusion.md "Seams"): one probe across it loads both patches and each decoder
// reads its share; a contact that may lie on the seam is judged on the sum of both sides' newest forces.
class CoreSeam : public CoreTest {
 protected:
  static aggregate::Setup WithSeams() {
    aggregate::Setup s = CobotSetup();
    std::vector<robot::MountedSurface> surfaces;
    for (const auto& p : s.patches) surfaces.push_back({*p.mount, p.extent_y_mm, p.extent_r_deg});
    for (const robot::Seam& seam : robot::FindSeams(surfaces)) s.seams.push_back({seam, 30.0, 30.0});
    s.safety.seam_sum.enabled = true;
    s.safety.seam_sum.source = "test";
    return s;
  }
  CoreSeam() : CoreTest(WithSeams()) {}
  explicit CoreSeam(aggregate::Setup s) : CoreTest(std::move(s)) {}
  // A located contact with a 2 mm sd on both axes.
  v1::PatchMessage Located(float force_n, float y_mm, float r_deg, std::int64_t t_ns, bool released = false) const {
    v1::PatchMessage m = ContactMsg(force_n, t_ns);
    auto* c = m.mutable_contact();
    c->set_located(true);
    c->set_y_mm(y_mm);
    c->set_r_deg(r_deg);
    c->set_uncertainty_calibrated(true);
    c->set_force_sd_n(0.1f);
    c->set_cov_yy_mm2(4.0f);
    c->set_cov_rr_mm2(4.0f);
    c->set_onset(true);
    c->set_released(released);
    return m;
  }
};

class CoreNoSeam : public CoreSeam {
 protected:
  CoreNoSeam() : CoreSeam(CobotSetup()) {}
};

TEST_F(CoreSeam, AProbeOnTheSeamIsJudgedOnBothSidesForces) {
  ASSERT_EQ(setup.seams.size(), 1u);
  ASSERT_EQ(setup.patches[setup.seams[0].seam.a].id, "forearm_a");
  ASSERT_EQ(setup.patches[setup.seams[0].seam.b].id, "forearm_b");
  const std::vector<int> streams = ClearAll();
  // 0.9 N on each side, each placed about 10 mm inside its own patch: 1.8 N on the seam.
  Send(streams[0], 0, Located(0.9f, 75, 130, tc), tc);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR) << "one side alone: 0.9 N";
  Send(streams[1], 1, Located(0.9f, 75, 15, tc + kMs), tc + kMs);
  const auto st = core.SafetyState();
  EXPECT_EQ(st.state(), v1::SafetyState::STATE_STOP);
  EXPECT_EQ(st.cause().patch_id(), "forearm_b");
  EXPECT_FLOAT_EQ(st.cause().force_n(), 1.8f);
  EXPECT_EQ(core.counters().seam_sums, 1u);
  // Review 3, finding 7: the cause says its force is a sum, and of what.
  EXPECT_NE(st.cause().message().find("force 1.8 N (seam sum of 'forearm_b' 0.9 N and 'forearm_a' 0.9 N)"),
            std::string::npos)
      << st.cause().message();
  // ... and names the partner in a field a client can read without parsing text (the demo's check does).
  EXPECT_EQ(st.cause().seam_partner_patch_id(), "forearm_a");
}

// A STOP on one side's own force names no seam sum, even with a live contact across the seam.
TEST_F(CoreSeam, AStopOnItsOwnForceNamesNoSum) {
  const std::vector<int> streams = ClearAll();
  Send(streams[0], 0, Located(2.0f, 75, 10, tc), tc);
  const auto st = core.SafetyState();
  ASSERT_EQ(st.state(), v1::SafetyState::STATE_STOP);
  EXPECT_FLOAT_EQ(st.cause().force_n(), 2.0f);
  EXPECT_EQ(st.cause().message().find("seam sum"), std::string::npos) << st.cause().message();
  EXPECT_EQ(st.cause().seam_partner_patch_id(), "");
  EXPECT_EQ(core.counters().seam_sums, 0u);
}

// Issue 17: the fused contact of a probe on the seam is flagged faint only when both sides' frames are (a
// force with one firm side does not rest on a baseline error alone).
TEST_F(CoreSeam, AFusedContactIsFaintOnlyWhenEverySideIs) {
  const std::vector<int> streams = ClearAll();
  for (const bool other_faint : {false, true}) {
    Beat(streams, 10);
    v1::PatchMessage a = Located(0.5f, 75, 130, tc), b = Located(0.5f, 75, 15, tc);
    a.mutable_contact()->set_faint(true);
    b.mutable_contact()->set_faint(other_faint);
    Send(streams[0], 0, a, tc);
    Send(streams[1], 1, b, tc);
    const v1::ContactSet set = core.Contacts(tc);
    ASSERT_EQ(set.contacts_size(), 1) << "one probe on the seam: one body contact\n" << set.DebugString();
    ASSERT_EQ(set.contacts(0).patch_ids_size(), 2);
    EXPECT_EQ(set.contacts(0).faint(), other_faint) << set.DebugString();
  }
}

TEST_F(CoreSeam, FarFromTheSeamApartAlongItOrReleasedTheSidesAreNotSummed) {
  const std::vector<int> streams = ClearAll();
  // forearm_b's contact 100 deg (65 mm) from the seam: two touches.
  Send(streams[0], 0, Located(0.9f, 75, 130, tc), tc);
  Send(streams[1], 1, Located(0.9f, 75, 100, tc + kMs), tc + kMs);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  // Both on the seam but 60 mm apart along it (2 mm sd each): two touches.
  Beat(streams, 10);
  Send(streams[0], 0, Located(0.9f, 45, 130, tc), tc);
  Send(streams[1], 1, Located(0.9f, 105, 15, tc + kMs), tc + kMs);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  // The other side released: nothing to add.
  Beat(streams, 10);
  Send(streams[0], 0, Located(0.0f, 75, 130, tc, true), tc);
  Send(streams[1], 1, Located(0.9f, 75, 15, tc + kMs), tc + kMs);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  EXPECT_EQ(core.counters().seam_sums, 0u);
}

// Review 3, finding 2: the sum pairs the two sides by arrival, not by frame time, so a side whose interrogator
// clock or decoder runs 10 ms behind does not end the cause while the press goes on.
TEST_F(CoreSeam, ALaggingSideKeepsTheSumWhileThePressGoesOn) {
  const std::vector<int> streams = ClearAll();
  for (int k = 0; k < 300; ++k) {
    tc += kMs;
    Send(streams[0], 0, Located(0.9f, 75, 130, tc), tc);
    Send(streams[1], 1, Located(0.9f, 75, 15, tc - 10 * kMs), tc);
    if (k % 10 == 0) {
      core.OnJointState(Joints(tc, 0.1), tc);
      for (std::size_t i = 2; i < streams.size(); ++i) Heartbeat(streams[i], i, tc);
      core.Tick(tc);
    }
  }
  ASSERT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_STOP);
  const auto r = core.OnReset(ResetRequest(core.SafetyState().stop_epoch()), true, tc);
  EXPECT_FALSE(r.accepted()) << "the 0.9 + 0.9 N press is still on the seam: " << r.message();
}

class CoreSeamSumOff : public CoreSeam {
 protected:
  static aggregate::Setup Off() {
    aggregate::Setup s = WithSeams();
    s.safety.seam_sum = {};
    return s;
  }
  CoreSeamSumOff() : CoreSeam(Off()) {}
};

TEST_F(CoreSeamSumOff, TheSceneDefaultJudgesEachSideAlone) {
  const std::vector<int> streams = ClearAll();
  Send(streams[0], 0, Located(0.9f, 75, 130, tc), tc);
  Send(streams[1], 1, Located(0.9f, 75, 15, tc + kMs), tc + kMs);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  EXPECT_EQ(core.counters().seam_sums, 0u);
}

TEST_F(CoreNoSeam, WithoutBandsTheSidesAreJudgedAlone) {
  const std::vector<int> streams = ClearAll();
  Send(streams[0], 0, Located(0.9f, 75, 130, tc), tc);
  Send(streams[1], 1, Located(0.9f, 75, 15, tc + kMs), tc + kMs);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
}

// Review finding 6: a second hello for a patch with a live, healthy stream is refused DUPLICATE_PATCH before
// anything else is looked at, whatever it says (here: another spec), and changes nothing: the state stays
// CLEAR, no epoch, the live link HEALTHY and its stream still served. Old code: the spec check came first,
// SPEC_MISMATCH and OnHelloRefused set the patch REFUSED (FAULT PATCH_MISSING), and every later heartbeat of
// the live stream was a kNotConnected rejection with a new epoch each.
// RetarePatch (docs/safety.md "Re-tare"): sent only for an operator, this run, a known and connected patch, while
// the robot is held, one at a time; the decoder's answer shows in the status and changes no safety state.
TEST_F(CoreTest, ARetareIsSentOnlyWhileHeldOnceAtATimeAndItsResultChangesNothing) {
  const auto streams = ClearAll();
  auto ask = [&](const std::string& patch, std::uint64_t run = kRunId, bool authorized = true) {
    v1::RetarePatchRequest r;
    r.set_patch_id(patch);
    r.set_aggregator_run_id(run);
    r.set_operator_name("alice");
    return core.OnRetare(r, authorized, tc);
  };
  const std::string a = setup.patches[0].id;
  // CLEAR: the robot may move, so nothing is sent.
  auto d = ask(a);
  EXPECT_FALSE(d.response.sent());
  EXPECT_EQ(d.response.reason(), v1::RETARE_REFUSAL_NOT_HELD);
  EXPECT_FALSE(d.command.has_value());
  // Held (a fault on patch 0).
  v1::PatchMessage fault;
  fault.mutable_fault()->set_code(v1::PATCH_FAULT_CODE_BASELINE_STALE);
  Send(streams[0], 0, fault, tc);
  ASSERT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT);
  const std::uint64_t epoch = core.SafetyState().stop_epoch();
  EXPECT_EQ(ask(a, kRunId, false).response.reason(), v1::RETARE_REFUSAL_UNAUTHORIZED);
  EXPECT_EQ(ask(a, kRunId + 1).response.reason(), v1::RETARE_REFUSAL_WRONG_RUN);
  EXPECT_EQ(ask(a, 0).response.reason(), v1::RETARE_REFUSAL_WRONG_RUN);
  EXPECT_EQ(ask("no_such_patch").response.reason(), v1::RETARE_REFUSAL_UNKNOWN_PATCH);
  d = ask(a);
  ASSERT_TRUE(d.response.sent()) << d.response.message();
  ASSERT_TRUE(d.command.has_value());
  EXPECT_EQ(d.stream, streams[0]);
  EXPECT_EQ(d.command->retare().request_id(), d.response.request_id());
  EXPECT_EQ(d.command->retare().operator_name(), "alice");
  // A second one before the answer: busy; another patch is independent.
  EXPECT_EQ(ask(a).response.reason(), v1::RETARE_REFUSAL_BUSY);
  const auto other = ask(setup.patches[1].id);
  EXPECT_TRUE(other.response.sent());
  EXPECT_GT(other.response.request_id(), d.response.request_id());
  // The answer: shown in the status, the pending request cleared, the safety state and epoch unchanged.
  v1::PatchMessage answer;
  answer.mutable_retare_result()->set_request_id(d.response.request_id());
  answer.mutable_retare_result()->set_outcome(v1::RETARE_OUTCOME_PRESSING);
  answer.mutable_retare_result()->set_force_n(1.2f);
  ASSERT_FALSE(Send(streams[0], 0, answer, tc).close);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT);
  EXPECT_EQ(core.SafetyState().stop_epoch(), epoch);
  const auto st = core.Status(tc);
  EXPECT_EQ(st.patches(0).last_retare().outcome(), v1::RETARE_OUTCOME_PRESSING);
  EXPECT_EQ(st.patches(0).retare_pending(), 0u);
  EXPECT_EQ(st.patches(1).retare_pending(), other.response.request_id());
  EXPECT_EQ(core.counters().retare_results[v1::RETARE_OUTCOME_PRESSING], 1u);
  EXPECT_EQ(core.counters().retare_requests[0], 2u);
  EXPECT_EQ(core.counters().retare_requests[v1::RETARE_REFUSAL_WRONG_RUN], 2u);
  // Answered: a new request is sent. An unanswered one stops blocking after kRetareAnswerNs.
  EXPECT_TRUE(ask(a).response.sent());
  EXPECT_EQ(ask(a).response.reason(), v1::RETARE_REFUSAL_BUSY);
  tc += aggregate::Core::kRetareAnswerNs + kMs;
  core.OnJointState(Joints(tc, 0.1), tc);
  for (std::size_t i = 0; i < streams.size(); ++i) Heartbeat(streams[i], i, tc);
  EXPECT_TRUE(ask(a).response.sent());
  // A patch whose stream ended: not connected.
  core.CloseStream(streams[2], tc);
  EXPECT_EQ(ask(setup.patches[2].id).response.reason(), v1::RETARE_REFUSAL_NOT_CONNECTED);
}

TEST_F(CoreTest, ADuplicateHelloIsRefusedFirstAndChangesNothing) {
  const auto streams = ClearAll();
  ASSERT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  const std::uint64_t epoch = core.SafetyState().stop_epoch();
  for (const char* what : {"same", "other spec", "other model", "slow heartbeat"}) {
    v1::PatchMessage h = Hello(setup, 0);
    if (std::string(what) == "other spec") h.mutable_hello()->set_patch_fingerprint("deadbeef");
    if (std::string(what) == "other model") h.mutable_hello()->set_model_sha256("0badf00d");
    if (std::string(what) == "slow heartbeat") h.mutable_hello()->set_heartbeat_period_ns(50 * kMs);
    const int impostor = core.OpenStream(tc);
    const auto r = ruffini::testing::Deliver(core, impostor, h, tc);
    ASSERT_TRUE(r.command && r.command->has_hello_refused()) << what;
    EXPECT_EQ(r.command->hello_refused().reason(), v1::HELLO_REFUSAL_DUPLICATE_PATCH) << what;
    EXPECT_TRUE(r.close);
    EXPECT_EQ(r.end_stream, -1);
    core.CloseStream(impostor, tc);
    Beat(streams, 10);
  }
  Beat(streams, 500);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  EXPECT_EQ(core.SafetyState().stop_epoch(), epoch);
  EXPECT_EQ(core.Status(tc).patches(0).link_state(), v1::LINK_STATE_HEALTHY);
  EXPECT_EQ(core.counters().hellos_refused[v1::HELLO_REFUSAL_DUPLICATE_PATCH], 4u);
}

// Review finding 10: a hello re-sent on the live stream is checked like the first; a mismatch is a protocol
// fault of that stream (old code stored it silently: "hello now spec 'another-spec'", HEALTHY, CLEAR).
TEST_F(CoreTest, AReSentHelloIsCheckedLikeTheFirst) {
  const auto streams = ClearAll();
  v1::PatchMessage same = Hello(setup, 1);
  EXPECT_FALSE(Send(streams[1], 1, same, tc).close);  // the same hello again: fine
  v1::PatchMessage other = Hello(setup, 1);
  other.mutable_hello()->set_patch_name("another-spec");
  other.mutable_hello()->set_model_sha256("0badf00d");
  const auto r = Send(streams[1], 1, other, tc + kMs);
  EXPECT_TRUE(r.close);
  EXPECT_FALSE(r.command);
  EXPECT_NE(core.last_protocol_error().find("re-sent hello"), std::string::npos) << core.last_protocol_error();
  EXPECT_EQ(core.counters().bad_input[static_cast<std::size_t>(aggregate::BadInput::kHelloChanged)], 1u);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT);
  EXPECT_EQ(core.SafetyState().cause().kind(), v1::SafetyCause::KIND_PATCH_PROTOCOL);
  EXPECT_EQ(core.SafetyState().cause().patch_id(), "forearm_b");
  core.CloseStream(streams[1], tc + kMs);  // the service ends the stream (then: silent, a new cause)
  EXPECT_EQ(core.Status(tc + kMs).patches(1).hello().patch_name(), setup.patches[1].spec_name);  // not stored
}

// Issue 15 section 2 (review finding 5's core half): a hello for a patch whose stream has been silent for
// more than 3 watchdogs takes it over; the Core names the old stream for the caller to end. Alive and not
// silent: still DUPLICATE_PATCH. Old code: DUPLICATE_PATCH for as long as the half-open stream existed.
TEST_F(CoreTest, ASilentStreamIsTakenOverByANewHello) {
  const auto streams = ClearAll();
  const std::int64_t watchdog = setup.safety.patches[2].silence_deadline_ns;  // 30 ms
  Beat(streams, 90, /*skip=*/2);  // upper_arm_a silent for 90 ms = 3 watchdogs: not yet past
  const int early = core.OpenStream(tc);
  const auto r1 = ruffini::testing::Deliver(core, early, Hello(setup, 2), tc);
  ASSERT_TRUE(r1.command && r1.command->has_hello_refused());
  EXPECT_EQ(r1.command->hello_refused().reason(), v1::HELLO_REFUSAL_DUPLICATE_PATCH);
  core.CloseStream(early, tc);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT);  // silent: FAULT already
  const std::uint64_t epoch = core.SafetyState().stop_epoch();
  tc += 1;  // silent for 3 x 30 ms + 1 ns: past 3 watchdogs
  ASSERT_EQ(watchdog, 30 * kMs);
  const int fresh = core.OpenStream(tc);
  seq[fresh] = 1;
  const auto r2 = ruffini::testing::Deliver(core, fresh, Hello(setup, 2), tc);
  ASSERT_TRUE(r2.command && r2.command->has_hello_accepted()) << r2.command->DebugString();
  EXPECT_EQ(r2.end_stream, streams[2]);
  EXPECT_EQ(core.counters().takeovers, 1u);
  EXPECT_EQ(core.SafetyState().stop_epoch(), epoch);  // the silence was the cause; the takeover adds none
  // The old stream is gone: anything it still says ends it, and changes nothing.
  const auto old = Heartbeat(streams[2], 2, tc);
  EXPECT_TRUE(old.close);
  core.CloseStream(streams[2], tc);
  // The new stream serves the patch; after 200 ms healthy the FAULT can be reset.
  std::vector<int> now_streams = streams;
  now_streams[2] = fresh;
  Beat(now_streams, 250);
  EXPECT_EQ(core.Status(tc).patches(2).link_state(), v1::LINK_STATE_HEALTHY);
  const auto reset = core.OnReset(ResetRequest(core.SafetyState().stop_epoch()), true, tc);
  EXPECT_TRUE(reset.accepted()) << reset.message();
  const auto events = core.TakeEvents();
  bool logged = false;
  for (const auto& e : events) logged = logged || (e.takeover && e.replaced_stream == streams[2] && e.cause_patch == "upper_arm_a");
  EXPECT_TRUE(logged);
}

// Review finding 10 and issue 15 section 3: bad input is a doubt (STOP), named and counted; no NaN published;
// a contact off the patch does not vanish from the contact set.
TEST_F(CoreTest, BadContactsAreDoubtsNeverNaNAndNeverVanish) {
  struct Row {
    const char* what;
    std::function<void(v1::PatchMessage&)> edit;
    aggregate::BadInput bad;
    const char* doubt;
  };
  const std::vector<Row> rows = {
      {"NaN position", [](v1::PatchMessage& m) { m.mutable_contact()->set_y_mm(std::nanf("")); },
       aggregate::BadInput::kBadPosition, "bad_position"},
      {"infinite r", [](v1::PatchMessage& m) { m.mutable_contact()->set_r_deg(INFINITY); },
       aggregate::BadInput::kBadPosition, "bad_position"},
      {"y = 5000 mm", [](v1::PatchMessage& m) { m.mutable_contact()->set_y_mm(5000); }, aggregate::BadInput::kBadPosition,
       "bad_position"},
      {"r = -10 deg", [](v1::PatchMessage& m) { m.mutable_contact()->set_r_deg(-10); }, aggregate::BadInput::kBadPosition,
       "bad_position"},
      {"non-PSD covariance", [](v1::PatchMessage& m) { m.mutable_contact()->set_cov_yr_mm2(10); },
       aggregate::BadInput::kBadCovariance, "bad_covariance"},
      {"negative variance", [](v1::PatchMessage& m) { m.mutable_contact()->set_cov_rr_mm2(-1); },
       aggregate::BadInput::kBadCovariance, "bad_covariance"},
      {"NaN covariance", [](v1::PatchMessage& m) { m.mutable_contact()->set_cov_yy_mm2(std::nanf("")); },
       aggregate::BadInput::kBadCovariance, "bad_covariance"},
      {"frame 1 h ahead", [](v1::PatchMessage& m) { m.set_t_ns(m.t_ns() + 3'600'000 * kMs); },
       aggregate::BadInput::kImplausibleTime, "implausible_time"},
      {"frame INT64_MIN", [](v1::PatchMessage& m) { m.set_t_ns(std::numeric_limits<std::int64_t>::min()); },
       aggregate::BadInput::kImplausibleTime, "implausible_time"},
  };
  for (const Row& row : rows) {
    // A fresh core per row.
    aggregate::Core c(setup, kT0);
    std::map<int, std::uint64_t> sq;
    std::vector<int> st;
    std::int64_t now = kT0;
    for (std::size_t i = 0; i < setup.patches.size(); ++i) {
      st.push_back(c.OpenStream(now));
      ASSERT_TRUE(ruffini::testing::Deliver(c, st.back(), Hello(setup, i), now).command->has_hello_accepted());
      sq[st.back()] = 1;
    }
    auto send = [&](std::size_t i, v1::PatchMessage m) {
      m.set_patch_id(setup.patches[i].id);
      m.set_seq(++sq[st[i]]);
      return ruffini::testing::Deliver(c, st[i], m, now);
    };
    for (int k = 0; k < 30; ++k) {
      now += 10 * kMs;
      c.OnJointState(Joints(now, 0.1), now);
      for (std::size_t i = 0; i < st.size(); ++i) {
        v1::PatchMessage hb;
        hb.mutable_heartbeat()->set_healthy(true);
        send(i, hb);
      }
    }
    ASSERT_TRUE(c.OnReset(ResetRequest(1), true, now).accepted()) << row.what;
    // A light (1.0 N, below 1.5 N) located contact, made bad by the row.
    v1::PatchMessage m = ContactMsg(1.0f, now - kMs);
    auto* pc = m.mutable_contact();
    pc->set_located(true);
    pc->set_y_mm(60);
    pc->set_r_deg(30);
    pc->set_cov_yy_mm2(4);
    pc->set_cov_rr_mm2(4);
    pc->set_onset(true);
    row.edit(m);
    EXPECT_FALSE(send(0, m).close) << row.what;
    const v1::SafetyState s = c.SafetyState();
    EXPECT_EQ(s.state(), v1::SafetyState::STATE_STOP) << row.what;
    EXPECT_EQ(s.cause().kind(), v1::SafetyCause::KIND_CONTACT) << row.what;
    EXPECT_EQ(s.cause().patch_id(), "forearm_a") << row.what;
    EXPECT_FALSE(s.cause().has_p_bc_m()) << row.what;  // never a NaN (or an off-patch) position
    EXPECT_EQ(s.cause().message().find("nan"), std::string::npos) << row.what << ": " << s.cause().message();
    EXPECT_NE(s.cause().message().find(row.doubt), std::string::npos) << row.what << ": " << s.cause().message();
    EXPECT_LE(s.cause().t_ns(), now) << row.what;  // evidence time never from a wild clock
    EXPECT_EQ(c.counters().bad_input[static_cast<std::size_t>(row.bad)], 1u) << row.what;
    // Still in the contact set (at the patch, unplaced), finite.
    const v1::ContactSet set = c.Contacts(now);
    ASSERT_EQ(set.contacts_size(), 1) << row.what;
    EXPECT_EQ(set.contacts(0).patch_ids(0), "forearm_a") << row.what;
    EXPECT_FALSE(set.contacts(0).located()) << row.what;
    EXPECT_TRUE(std::isfinite(set.contacts(0).p_bc_m().x()) && std::isfinite(set.contacts(0).force_n())) << row.what;
    EXPECT_GE(c.TakeStopLatencyNs(), 0) << row.what;
  }
}

// Review finding 10: an active_fault outside the contract's enum (negative too) is a fault, counted (old code
// clamped -3 to 0, "no fault": HEALTHY and CLEAR). A released frame of -0.0004 N is noise: no STOP.
TEST_F(CoreTest, UnknownFaultCodesFaultAndNoiseBelowZeroDoesNotStop) {
  const auto streams = ClearAll();
  v1::PatchMessage touch = ContactMsg(0.4f, tc);
  touch.mutable_contact()->set_onset(true);
  Send(streams[0], 0, touch, tc);
  v1::PatchMessage release = ContactMsg(-0.0004f, tc + kMs);
  release.mutable_contact()->set_released(true);
  Send(streams[0], 0, release, tc + kMs);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  for (int code : {-3, 99, 12}) {
    v1::PatchMessage hb;
    hb.mutable_heartbeat()->set_healthy(true);
    hb.mutable_heartbeat()->set_active_fault(static_cast<v1::PatchFaultCode>(code));
    Send(streams[1], 1, hb, tc + 2 * kMs);
    EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT) << code;
    EXPECT_EQ(core.SafetyState().cause().kind(), v1::SafetyCause::KIND_PATCH_FAULT) << code;
    EXPECT_EQ(core.SafetyState().cause().patch_fault(), v1::PATCH_FAULT_CODE_INTERNAL) << code;
    EXPECT_EQ(core.Status(tc + 2 * kMs).patches(1).link_state(), v1::LINK_STATE_UNHEALTHY) << code;
  }
  EXPECT_EQ(core.counters().bad_input[static_cast<std::size_t>(aggregate::BadInput::kUnknownFaultCode)], 3u);
  v1::PatchMessage f;
  f.mutable_fault()->set_code(static_cast<v1::PatchFaultCode>(-7));
  Send(streams[2], 2, f, tc + 3 * kMs);
  EXPECT_EQ(core.counters().bad_input[static_cast<std::size_t>(aggregate::BadInput::kUnknownFaultCode)], 4u);
}

// Review finding 10 / 12: a joint state stamped INT64_MAX (or far from arrival) is refused and counted, and
// cannot become the monotonic reference (old code: accepted, then every later state not_monotonic: FAULT until
// restart, joint_state_age_ns -7427876283578196409). The reference is per stream.
TEST_F(CoreTest, AWildJointStampIsRefusedAndCannotLockTheAggregator) {
  const auto streams = ClearAll();
  EXPECT_EQ(core.OnJointState(Joints(std::numeric_limits<std::int64_t>::max(), 0.1), tc),
            aggregate::JointRejection::kImplausibleTime);
  EXPECT_EQ(core.OnJointState(Joints(tc - 3'000 * kMs, 0.1), tc), aggregate::JointRejection::kImplausibleTime);
  EXPECT_EQ(core.counters().joint_states[static_cast<std::size_t>(aggregate::JointRejection::kImplausibleTime)], 2u);
  Beat(streams, 100);  // later states, on time, are accepted
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
  const auto st = core.Status(tc);
  EXPECT_GE(st.joint_state_age_ns(), 0);
  EXPECT_LT(st.joint_state_age_ns(), 10 * kMs);
  // Per stream: stream 7 a second ahead (plausible), then a reconnected controller (stream 8) on time.
  EXPECT_EQ(core.OnJointState(Joints(tc + 1'000 * kMs, 0.1), tc, 7), aggregate::JointRejection::kNone);
  EXPECT_EQ(core.OnJointState(Joints(tc + 5 * kMs, 0.1), tc + 5 * kMs, 7), aggregate::JointRejection::kNotMonotonic);
  EXPECT_EQ(core.OnJointState(Joints(tc + 5 * kMs, 0.1), tc + 5 * kMs, 8), aggregate::JointRejection::kNone);
  core.CloseJointStream(7);
  EXPECT_EQ(core.OnJointState(Joints(tc + 6 * kMs, 0.1), tc + 6 * kMs, 7), aggregate::JointRejection::kNone);
  // The age is by arrival on the aggregator's clock: never negative even with a future stamp.
  EXPECT_EQ(core.Status(tc + 6 * kMs).joint_state_age_ns(), 0);
}

// A healthy heartbeat out of contact ends the Core's contact as it ends the policy's: a doubt shown in the
// contact set (off the patch) is gone after it (before, the Core kept it until a released frame).
TEST_F(CoreTest, AHealthyHeartbeatOutOfContactEndsTheContactInTheSet) {
  const auto streams = ClearAll();
  v1::PatchMessage off = ContactMsg(0.5f, tc);
  off.mutable_contact()->set_located(true);
  off.mutable_contact()->set_y_mm(5000);
  Send(streams[0], 0, off, tc);
  ASSERT_EQ(core.Contacts(tc).contacts_size(), 1);
  v1::PatchMessage hb;
  hb.mutable_heartbeat()->set_healthy(true);
  hb.mutable_heartbeat()->set_in_contact(true);
  Send(streams[0], 0, hb, tc + kMs);
  EXPECT_EQ(core.Contacts(tc + kMs).contacts_size(), 1);  // still touched
  hb.mutable_heartbeat()->set_in_contact(false);
  Send(streams[0], 0, hb, tc + 2 * kMs);
  EXPECT_EQ(core.Contacts(tc + 2 * kMs).contacts_size(), 0);
}

TEST_F(CoreTest, NoJointStateYetIsAgeMinusOne) { EXPECT_EQ(core.Status(kT0).joint_state_age_ns(), -1); }

// Finding 4 (core half): every SafetyState, AggregatorStatus and HelloAccepted carries the run id and the robot
// name; a ResetStop naming another run, or none, is refused WRONG_RUN and changes nothing else.
TEST_F(CoreTest, RunIdentityIsPublishedAndResetsAreBoundToTheRun) {
  const int s0 = core.OpenStream(tc);
  const auto hello = ruffini::testing::Deliver(core, s0, Hello(setup, 0), tc);
  ASSERT_TRUE(hello.command && hello.command->has_hello_accepted());
  EXPECT_EQ(hello.command->hello_accepted().aggregator_run_id(), kRunId);
  EXPECT_EQ(hello.command->hello_accepted().robot_name(), "cobot");
  EXPECT_EQ(core.SafetyState().aggregator_run_id(), kRunId);
  EXPECT_EQ(core.SafetyState().robot_name(), "cobot");
  EXPECT_EQ(core.Status(tc).aggregator_run_id(), kRunId);
  EXPECT_EQ(core.Status(tc).robot_name(), "cobot");
  core.CloseStream(s0, tc);
  (void)core.TakeEvents();
  const auto streams = ClearAll();
  v1::PatchMessage hard = ContactMsg(1.8f, tc);
  Send(streams[0], 0, hard, tc);
  v1::PatchMessage rel = ContactMsg(0.0f, tc);
  rel.mutable_contact()->set_released(true);
  Send(streams[0], 0, rel, tc);
  Beat(streams, 10);
  const v1::SafetyState before = core.SafetyState();
  ASSERT_EQ(before.state(), v1::SafetyState::STATE_STOP);
  for (std::uint64_t run : {std::uint64_t{0}, kRunId + 1}) {
    const auto r = core.OnReset(ResetRequest(before.stop_epoch(), run), true, tc);
    EXPECT_FALSE(r.accepted());
    EXPECT_EQ(r.reason(), v1::RESET_REFUSAL_WRONG_RUN);
    EXPECT_EQ(core.SafetyState().SerializeAsString(), before.SerializeAsString());
  }
  const auto ok = core.OnReset(ResetRequest(before.stop_epoch()), true, tc);
  EXPECT_TRUE(ok.accepted()) << ok.message();
  // The reset events name the operator.
  const auto events = core.TakeEvents();
  int refused = 0, accepted = 0;
  for (const auto& e : events) {
    if (e.safety.type == safety::EventType::kResetRefused && e.safety.reset_refusal == safety::ResetRefusal::kWrongRun) {
      ++refused;
      EXPECT_EQ(e.operator_name, "alice");
    }
    if (e.safety.type == safety::EventType::kResetAccepted) ++accepted;
  }
  EXPECT_EQ(refused, 2);
  EXPECT_EQ(accepted, 2);  // ClearAll's start-up reset and this one
  auto zero = setup;
  zero.run_id = 0;
  EXPECT_THROW(aggregate::Core(zero, kT0), InputError);
}

// Finding 11: ContactSet.t_ns is the newest contributing frame's interrogator time, 0 when empty (old code:
// the publication time); CONFIG_MISMATCH and the rate are checked at hello when the scene states them.
TEST_F(CoreTest, ContactSetTimeAndHelloExpectations) {
  const auto streams = ClearAll();
  EXPECT_EQ(core.Contacts(tc).t_ns(), 0);
  v1::PatchMessage a = ContactMsg(0.5f, tc - 3 * kMs);
  a.mutable_contact()->set_onset(true);
  Send(streams[0], 0, a, tc);
  v1::PatchMessage b = ContactMsg(0.6f, tc - 2 * kMs);
  b.mutable_contact()->set_onset(true);
  Send(streams[2], 2, b, tc);
  EXPECT_EQ(core.Contacts(tc + 5 * kMs).t_ns(), tc - 2 * kMs);
  EXPECT_EQ(core.Contacts(tc + 5 * kMs).published_t_ns(), tc + 5 * kMs);

  auto pinned = CobotSetup();
  pinned.safety.input.sample_rate_hz = 1000;
  pinned.safety.input.decoder_config_sha256 = std::string(64, 'a');
  aggregate::Core c(pinned, kT0);
  auto hello = [&](double rate, const std::string& sha) {
    v1::PatchMessage m = Hello(pinned, 0);
    m.mutable_hello()->set_sample_rate_hz(rate);
    m.mutable_hello()->mutable_decoder_config()->set_config_sha256(sha);
    const int s = c.OpenStream(kT0);
    const auto r = ruffini::testing::Deliver(c, s, m, kT0);
    c.CloseStream(s, kT0);
    return r.command->has_hello_accepted() ? v1::HELLO_REFUSAL_UNSPECIFIED : r.command->hello_refused().reason();
  };
  EXPECT_EQ(hello(500, std::string(64, 'a')), v1::HELLO_REFUSAL_RATE_MISMATCH);
  EXPECT_EQ(hello(std::nan(""), std::string(64, 'a')), v1::HELLO_REFUSAL_RATE_MISMATCH);
  EXPECT_EQ(hello(1000, std::string(64, 'b')), v1::HELLO_REFUSAL_CONFIG_MISMATCH);
  EXPECT_EQ(hello(1000.2, std::string(64, 'a')), v1::HELLO_REFUSAL_UNSPECIFIED);
}

// A hello's faint refusal (DecoderConfig.faint_refuse_below_n). A pinned model was checked when the scene
// loaded; unpinned, the aggregator refuses a decoder that refuses above what the patch may stop on: its
// region's threshold with the force alone, nothing under a raising stop rule or on a seam. A value that is not
// a force is refused whatever the scene pins.
TEST(CoreHello, AFaintRefusalIsCheckedAgainstWhatThePatchMayStopOn) {
  auto run = [](aggregate::Setup setup, float refuse_n) {
    aggregate::Core c(setup, kT0);
    v1::PatchMessage m = Hello(setup, 0);
    m.mutable_hello()->mutable_decoder_config()->set_faint_refuse_below_n(refuse_n);
    const int st = c.OpenStream(kT0);
    const auto r = ruffini::testing::Deliver(c, st, m, kT0);
    return r.command->has_hello_accepted() ? v1::HELLO_REFUSAL_UNSPECIFIED : r.command->hello_refused().reason();
  };
  aggregate::Setup unpinned = CobotSetup();
  for (auto& p : unpinned.patches) p.model_sha256.clear();
  float threshold = 0;
  for (const auto& r : unpinned.safety.regions) {
    if (r.name == unpinned.safety.patches[0].region) threshold = r.threshold_n;
  }
  ASSERT_GT(threshold, 0.5f);
  ASSERT_TRUE(unpinned.seams.empty()) << "CobotSetup finds no seams; the seam case below adds one";
  EXPECT_EQ(run(unpinned, 0.0f), v1::HELLO_REFUSAL_UNSPECIFIED);
  EXPECT_EQ(run(unpinned, threshold - 0.1f), v1::HELLO_REFUSAL_UNSPECIFIED);
  EXPECT_EQ(run(unpinned, threshold + 0.1f), v1::HELLO_REFUSAL_CONFIG_MISMATCH);
  for (float bad : {-0.5f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    EXPECT_EQ(run(unpinned, bad), v1::HELLO_REFUSAL_CONFIG_MISMATCH) << bad;
    EXPECT_EQ(run(CobotSetup(), bad), v1::HELLO_REFUSAL_CONFIG_MISMATCH) << "pinned, " << bad;
  }
  EXPECT_EQ(run(CobotSetup(), threshold + 0.1f), v1::HELLO_REFUSAL_UNSPECIFIED) << "pinned: checked at load";
  aggregate::Setup raising = unpinned;
  raising.safety.stop_rule.sd_k = 1.0f;
  EXPECT_EQ(run(raising, threshold - 0.1f), v1::HELLO_REFUSAL_CONFIG_MISMATCH);
  aggregate::Setup seamed = unpinned;
  seamed.seams.push_back({robot::Seam{0, 1}, 10.0, 10.0});
  EXPECT_EQ(run(seamed, threshold - 0.1f), v1::HELLO_REFUSAL_CONFIG_MISMATCH);
}

// Issue 15 section 2 through the Core: a contact hovering at the threshold for 0.75 s (frames at 1 kHz,
// crossing every 25 ms) opens one epoch with the scene's release settings (old code: 30).
TEST_F(CoreTest, AContactHoveringAtTheThresholdOpensOneEpoch) {
  const auto streams = ClearAll();
  const std::uint64_t epoch = core.SafetyState().stop_epoch();
  for (int k = 0; k < 750; ++k) {
    tc += kMs;
    v1::PatchMessage m = ContactMsg((k / 25) % 2 == 0 ? 1.52f : 1.48f, tc);
    m.mutable_contact()->set_onset(k == 0);
    Send(streams[0], 0, m, tc);
    if (k % 10 == 0) {
      core.OnJointState(Joints(tc, 0.1), tc);
      for (std::size_t i = 0; i < streams.size(); ++i) {
        v1::PatchMessage hb;
        hb.mutable_heartbeat()->set_healthy(true);
        hb.mutable_heartbeat()->set_in_contact(i == 0);
        Send(streams[i], i, hb, tc);
      }
    }
  }
  EXPECT_EQ(core.SafetyState().stop_epoch(), epoch + 1);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_STOP);
}

// tests/safety/property_test.cpp's idea for the Core: seeded random programs (the fuzz target's byte language,
// core_program.h), each starting from the cobot scene cleared (four hellos, 300 ms of healthy heartbeats and
// joint states, the start-up reset), then random steps. Any invariant broken aborts the test (no NaN
// published, epoch and seq never decrease, no CLEAR without an accepted reset naming this run and the epoch
// in force, identity on every state). The tallies show the programs reach STOP, FAULT, resets and clears.
TEST(CoreProperty, RandomProgramsKeepTheInvariants) {
  std::vector<std::uint8_t> clear;
  auto add = [&clear](std::initializer_list<int> xs) {
    for (int x : xs) clear.push_back(static_cast<std::uint8_t>(x));
  };
  for (int i = 0; i < 4; ++i) add({0, 0, 1});
  for (int i = 0; i < 4; ++i) add({1, 0, i, i, 0});
  for (int k = 0; k < 30; ++k) {
    add({10, 50, 0});
    for (int i = 0; i < 4; ++i) add({3, 0, i, 0});
    add({12, 0, 0});
  }
  add({11, 0, 0});
  // The pieces programs are made of: mostly 10 ms of health (so clears happen), contacts light and hard,
  // resets right and of another run, snapshots; and random bytes.
  const std::vector<std::vector<int>> pieces = {
      {10, 50, 0, 3, 0, 0, 0, 3, 0, 1, 0, 3, 0, 2, 0, 3, 0, 3, 0, 12, 0, 1},  // 10 ms of health
      {5, 1, 0, 1, 4, 0, 4, 50, 100, 100},                                    // a light contact on forearm_a
      {5, 1, 0, 2, 4, 0, 4, 0, 100, 100},                                     // its released frame
      {5, 1, 1, 0, 4, 0, 4, 200, 100, 100},                                   // a hard contact on forearm_b
      {5, 1, 1, 2, 4, 0, 4, 0, 100, 100},                                     // its released frame
      {11, 0, 0},                                                             // a reset of the epoch in force
      {11, 0, 4},                                                             // a reset naming another run
      {13, 0},                                                                // contacts and status
  };
  core_program::Tally total;
  constexpr int kPrograms = 300;
  for (int seed = 1; seed <= kPrograms; ++seed) {
    std::mt19937 rng(static_cast<std::uint32_t>(seed));
    std::vector<std::uint8_t> bytes = clear;
    for (int k = 0; k < 400; ++k) {
      const auto r = static_cast<unsigned>(rng() % 100);
      if (r < 5) {
        for (int j = 0; j < 8; ++j) bytes.push_back(static_cast<std::uint8_t>(rng()));
      } else {
        const auto& piece = pieces[r < 55 ? 0 : 1 + r % (pieces.size() - 1)];
        for (int x : piece) bytes.push_back(static_cast<std::uint8_t>(x));
      }
    }
    const core_program::Tally t = core_program::Run(bytes.data(), bytes.size());
    total.steps += t.steps;
    total.accepted_resets += t.accepted_resets;
    total.stops += t.stops;
    total.faults += t.faults;
    total.clears += t.clears;
  }
  std::printf("programs %d, steps %ld, stops %ld, faults %ld, accepted resets %ld, clears %ld\n", kPrograms,
              total.steps, total.stops, total.faults, total.accepted_resets, total.clears);
  EXPECT_EQ(total.clears, total.accepted_resets);
  // Seeds 1..300 gave 542712 steps, 255 STOPs, 321 FAULTs, 453 clears (300 of them the start-ups).
  EXPECT_GT(total.clears, kPrograms + 100);  // beyond the start-up reset of each program
  EXPECT_GT(total.stops, kPrograms / 2);
  EXPECT_GT(total.faults, kPrograms / 2);
  EXPECT_GT(total.steps, 100L * kPrograms);
}

TEST(CoreSetup, InconsistentSetupsAreRefused) {
  auto s = CobotSetup();
  s.patches.pop_back();
  EXPECT_THROW(aggregate::Core(s, kT0), InputError);
  auto t = CobotSetup();
  t.patches[0].mount->link = "hand_link";
  EXPECT_THROW(aggregate::Core(t, kT0), InputError);
}

}  // namespace

// ---- The safety layer on the decoder links (docs/safety-channel.md): each of the eight errors, as the Core
// sees it, with its stated reaction. Starts from CLEAR with every patch healthy.
namespace {

class CoreSafetyLayer : public CoreTest {
 protected:
  void SetUp() override {
    streams = ClearAll();
    ASSERT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_CLEAR);
    epoch = core.SafetyState().stop_epoch();
  }
  // A heartbeat for patch 0 with the next seq, sealed at `sent` (the decoder's clock) and delivered at tc.
  v1::PatchMessage Next(std::int64_t sent) {
    v1::PatchMessage m;
    m.set_patch_id(setup.patches[0].id);
    m.set_seq(++seq[streams[0]]);
    m.mutable_heartbeat()->set_healthy(true);
    ruffini::testing::SealAsDecoder(m, core.run_id(), sent);
    return m;
  }
  aggregate::Core::Reply Raw(const v1::PatchMessage& m) { return core.OnPatchMessage(streams[0], m, tc); }
  std::uint64_t Errors(channel::Error e) const { return core.link_errors()[0][e]; }
  bool StillClear() const {
    const auto st = core.SafetyState();
    return st.state() == v1::SafetyState::STATE_CLEAR && st.stop_epoch() == epoch;
  }
  std::vector<int> streams;
  std::uint64_t epoch = 0;
};

TEST_F(CoreSafetyLayer, CorruptionIsDiscardedAndTheGapItLeavesFaultsThePatch) {
  tc += kMs;
  v1::PatchMessage m = Next(tc);
  m.mutable_heartbeat()->set_healthy(false);  // flipped after sealing
  const auto r = Raw(m);
  EXPECT_FALSE(r.close);
  EXPECT_EQ(Errors(channel::Error::kCorruption), 1u);
  EXPECT_TRUE(StillClear()) << "the corrupted content (unhealthy) was not believed";
  tc += kMs;
  const auto r2 = Raw(Next(tc));  // its seq is one past the discarded one: a loss
  EXPECT_TRUE(r2.close);
  EXPECT_EQ(Errors(channel::Error::kLoss), 1u);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT);
  EXPECT_EQ(core.SafetyState().cause().kind(), v1::SafetyCause::KIND_LINK_ERRORS) << "two errors within the window";
}

TEST_F(CoreSafetyLayer, ALossUsesTheMessageThenFaults) {
  seq[streams[0]] += 3;  // three messages lost on the way
  tc += kMs;
  v1::PatchMessage m;
  m.set_patch_id(setup.patches[0].id);
  m.set_seq(++seq[streams[0]]);
  m.set_t_ns(tc);
  m.mutable_contact()->set_force_n(3.0f);
  m.mutable_contact()->set_onset(true);
  ruffini::testing::SealAsDecoder(m, core.run_id(), tc);
  const auto r = Raw(m);
  EXPECT_TRUE(r.close) << "the stream ends: the decoder reconnects with a fresh hello";
  EXPECT_EQ(Errors(channel::Error::kLoss), 1u);
  // The contact was used (a STOP), then the link's fault escalated it to FAULT.
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT);
  EXPECT_EQ(core.SafetyState().cause().kind(), v1::SafetyCause::KIND_PATCH_PROTOCOL);
  EXPECT_GE(core.safety_counters().stops, 1u);
}

TEST_F(CoreSafetyLayer, RepetitionAndIncorrectSequenceAreDiscardedThenTheErrorRateLatches) {
  tc += kMs;
  const v1::PatchMessage m = Next(tc);
  EXPECT_FALSE(Raw(m).close);
  EXPECT_FALSE(Raw(m).close) << "the same message again";
  EXPECT_EQ(Errors(channel::Error::kRepetition), 1u);
  EXPECT_TRUE(StillClear());
  tc += kMs;
  const v1::PatchMessage a = Next(tc);
  const v1::PatchMessage b = Next(tc);
  EXPECT_TRUE(Raw(b).close) << "b came first: a gap (a's seq) is a loss, and the second error in the window";
  EXPECT_EQ(core.SafetyState().cause().kind(), v1::SafetyCause::KIND_LINK_ERRORS);
  EXPECT_TRUE(Raw(a).close) << "the stream is over";
}

TEST_F(CoreSafetyLayer, AnOlderSeqIsAnIncorrectSequence) {
  tc += kMs;
  const v1::PatchMessage a = Next(tc);
  const v1::PatchMessage b = Next(tc);
  EXPECT_FALSE(Raw(a).close);
  EXPECT_FALSE(Raw(b).close);
  EXPECT_FALSE(Raw(a).close);
  EXPECT_EQ(Errors(channel::Error::kIncorrectSequence), 1u);
  EXPECT_TRUE(StillClear());
}

TEST_F(CoreSafetyLayer, DelayUsesTheMessageThenFaultsLate) {
  // The decoder's clock runs with the test's; a message sent 25 ms before it arrives is 25 ms old.
  tc += kMs;
  v1::PatchMessage m;
  m.set_patch_id(setup.patches[0].id);
  m.set_seq(++seq[streams[0]]);
  m.set_t_ns(tc - 25 * kMs);
  m.mutable_contact()->set_force_n(3.0f);
  m.mutable_contact()->set_onset(true);
  ruffini::testing::SealAsDecoder(m, core.run_id(), tc - 25 * kMs);
  const auto r = Raw(m);
  EXPECT_TRUE(r.close);
  EXPECT_EQ(Errors(channel::Error::kDelay), 1u);
  EXPECT_EQ(core.SafetyState().state(), v1::SafetyState::STATE_FAULT);
  EXPECT_EQ(core.SafetyState().cause().kind(), v1::SafetyCause::KIND_PATCH_LATE);
  EXPECT_GE(core.safety_counters().stops, 1u) << "the late STOP still stopped first";
}

TEST_F(CoreSafetyLayer, InsertionMasqueradeAndAddressingAreDiscarded) {
  struct Row {
    channel::Error error;
    std::function<void(v1::PatchMessage&)> forge;
  };
  const std::vector<Row> rows = {
      {channel::Error::kInsertion, [](v1::PatchMessage& m) { m.set_sender_run_id(0xBAD); }},
      {channel::Error::kMasquerade, [&](v1::PatchMessage& m) { m.set_patch_id(setup.patches[1].id); }},
      {channel::Error::kAddressing, [&](v1::PatchMessage& m) { m.set_aggregator_run_id(core.run_id() + 1); }},
  };
  for (const Row& row : rows) {
    SCOPED_TRACE(std::string(channel::Name(row.error)));
    tc += 10 * kMs;
    v1::PatchMessage forged = Next(tc);
    --seq[streams[0]];  // it takes the place of the next genuine message
    row.forge(forged);
    channel::Seal(forged);  // a well-formed forgery: the CRC matches
    forged.mutable_heartbeat()->set_healthy(false);
    channel::Seal(forged);
    EXPECT_FALSE(Raw(forged).close);
    EXPECT_EQ(Errors(row.error), 1u);
    EXPECT_TRUE(StillClear()) << "the forged unhealthy heartbeat was not believed";
    EXPECT_FALSE(Raw(Next(tc)).close) << "the genuine stream goes on";
    Beat(streams, 61'000);  // healthy for longer than the error-rate window before the next row
    ASSERT_TRUE(StillClear());
  }
  EXPECT_EQ(core.link_errors()[1].total(), 0u) << "the masquerade counts on the stream's own patch";
}

TEST_F(CoreSafetyLayer, ACorruptedHelloIsRefused) {
  const int s = core.OpenStream(tc);
  v1::PatchMessage h = Hello(setup, 0);
  ruffini::testing::SealAsDecoder(h, core.run_id(), tc);
  h.mutable_hello()->set_model_sha256("abd");
  const auto r = core.OnPatchMessage(s, h, tc);
  ASSERT_TRUE(r.command && r.command->has_hello_refused());
  EXPECT_EQ(r.command->hello_refused().reason(), v1::HELLO_REFUSAL_PROTOCOL_ERROR);
  EXPECT_EQ(core.link_errors_unbound()[channel::Error::kCorruption], 1u);
  EXPECT_TRUE(StillClear()) << "the live stream of that patch is untouched";
}

}  // namespace
