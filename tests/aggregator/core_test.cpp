// aggregate::Core without the network, on an injected clock: the Connect stream rules (hello checks, seq),
// joint-state validation, body-frame placement with interpolated joint states, and what reaches the policy.
#include <gtest/gtest.h>

#include <cmath>

#include "ruffini/aggregate/core.h"
#include "ruffini/error.h"
#include "ruffini/robot/scene.h"
#include "ruffini/safety/scene.h"
#include "ruffini/scene_file.h"
#include "ruffini/twin/scene.h"

namespace {

using namespace ruffini;

constexpr std::int64_t kT0 = 1'700'000'000'000'000'000;
constexpr std::int64_t kMs = 1'000'000;
const std::string kScene = std::string(RUFFINI_SOURCE_DIR) + "/config/scenes/cobot.yaml";

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
  CoreTest() : setup(CobotSetup()), core(setup, kT0) {}
  // Opens a stream for patch i and sends its hello; returns the stream id.
  int Connect(std::size_t i, std::int64_t t) {
    const int s = core.OpenStream(t);
    const auto r = core.OnPatchMessage(s, Hello(setup, i), t);
    EXPECT_TRUE(r.command && r.command->has_hello_accepted()) << (r.command ? r.command->DebugString() : "none");
    seq[s] = 1;
    return s;
  }
  aggregate::Core::Reply Send(int stream, std::size_t i, v1::PatchMessage m, std::int64_t t) {
    m.set_patch_id(setup.patches[i].id);
    m.set_seq(++seq[stream]);
    return core.OnPatchMessage(stream, m, t);
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
  aggregate::Setup setup;
  aggregate::Core core;
  std::map<int, std::uint64_t> seq;
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
    const auto r = core.OnPatchMessage(s, m, kT0);
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
  const auto dup = core.OnPatchMessage(second, Hello(setup, 0), kT0);
  ASSERT_TRUE(dup.command && dup.command->has_hello_refused());
  EXPECT_EQ(dup.command->hello_refused().reason(), v1::HELLO_REFUSAL_DUPLICATE_PATCH);
  (void)first;
}

// A stream opened for a caller whose certificate names forearm_a (docs/security.md): a hello for forearm_b is
// refused UNAUTHORIZED, counted, and changes nothing: not forearm_b's live link, not the safety state.
TEST_F(CoreTest, AHelloForAnotherPatchThanTheCallersIsUnauthorizedAndChangesNothing) {
  const int live = Connect(1, kT0);  // forearm_b, held by its own decoder
  const v1::SafetyState before = core.SafetyState();
  const auto status_before = core.Status(kT0 + kMs);
  const int impostor = core.OpenStream(kT0 + kMs, setup.patches[0].id);
  const auto r = core.OnPatchMessage(impostor, Hello(setup, 1), kT0 + kMs);
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
  const auto ok = core.OnPatchMessage(own, Hello(setup, 0), kT0 + 2 * kMs);
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
  const auto r = core.OnPatchMessage(streams[0], m, kT0 + kMs);
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

TEST(CoreSetup, InconsistentSetupsAreRefused) {
  auto s = CobotSetup();
  s.patches.pop_back();
  EXPECT_THROW(aggregate::Core(s, kT0), InputError);
  auto t = CobotSetup();
  t.patches[0].mount->link = "hand_link";
  EXPECT_THROW(aggregate::Core(t, kT0), InputError);
}

}  // namespace
