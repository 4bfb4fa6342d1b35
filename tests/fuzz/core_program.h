#pragma once
// A program for aggregate::Core (the aggregator's state without the network) on the cobot scene, read from
// bytes: run by the libFuzzer target (core_fuzz.cpp) on the fuzzer's bytes and by core_test's property test
// (CoreProperty) on seeded random bytes. The input is a program: each step is an opcode byte and a few argument bytes, run against one Core on an
// injected clock, the way the service's loop would (a closing reply ends the stream; a takeover's end_stream
// is ended). Decoder streams (hellos right and wrong, heartbeats, contacts with any floats and timestamps,
// faults with any code, seq breaks), joint-state streams (any stamps, NaN, wrong counts), resets (right and
// wrong epoch, run and authority), ticks, publications, contact sets and status snapshots are all reachable.
//
// Invariants checked after every step (abort with a message when one breaks):
//   1. no NaN or infinity anywhere in a published SafetyState, ContactSet or AggregatorStatus number, and
//      no "nan"/"inf" in the cause's message (except a non-finite force's own doubt, which names it);
//   2. stop_epoch and seq never decrease;
//   3. nothing but an accepted reset turns STOP or FAULT into CLEAR, and an accepted reset named this run;
//   4. every state, status and HelloAccepted carries this run's id and the robot's name;
//   5. a CLEAR state has no cause; a STOP or FAULT has one;
//   6. joint_state_age_ns is never below -1.
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "ruffini/aggregate/core.h"
#include "ruffini/channel/crc.h"
#include "ruffini/patch/spec_loader.h"
#include "ruffini/robot/scene.h"
#include "ruffini/safety/scene.h"
#include "ruffini/scene_file.h"

namespace ruffini::core_program {

namespace detail {

constexpr std::uint64_t kRunId = 0x9e3779b97f4a7c15ULL;
constexpr std::int64_t kT0 = 1'700'000'000'000'000'000;
constexpr std::int64_t kMs = 1'000'000;

inline void Check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "invariant violated: %s\n", what);
    std::abort();
  }
}

// The bytes, read as arguments; past the end everything reads 0.
struct Reader {
  const std::uint8_t* p;
  std::size_t n, i = 0;
  bool done() const { return i >= n; }
  std::uint8_t u8() { return i < n ? p[i++] : 0; }
  std::uint32_t u32() {
    std::uint32_t v = 0;
    for (int k = 0; k < 4; ++k) v = (v << 8) | u8();
    return v;
  }
  std::uint64_t u64() { return (static_cast<std::uint64_t>(u32()) << 32) | u32(); }
  float f32() {
    const std::uint32_t b = u32();
    float f;
    std::memcpy(&f, &b, sizeof f);
    return f;
  }
  // A force: mostly near the threshold (1.5 N) or zero, sometimes any bit pattern.
  float force() {
    switch (u8() % 8) {
      case 0: return f32();
      case 1: return 0.0f;
      case 2: return -static_cast<float>(u8()) / 10000.0f;  // tiny negative noise
      case 3: return std::numeric_limits<float>::quiet_NaN();
      default: return 1.3f + static_cast<float>(u8()) / 500.0f;  // 1.3 .. 1.81 N
    }
  }
  // A timestamp relative to now: mostly close, sometimes wild.
  std::int64_t stamp(std::int64_t now) {
    switch (u8() % 8) {
      case 0: return static_cast<std::int64_t>(u64());
      case 1: return 0;
      case 2: return std::numeric_limits<std::int64_t>::max();
      case 3: return now + static_cast<std::int64_t>(static_cast<std::int16_t>(u32() & 0xffff)) * 50 * kMs;
      default: return now - static_cast<std::int64_t>(u8()) * 100'000;
    }
  }
};

struct Fixture {
  aggregate::Setup setup;
};

inline const Fixture& TheFixture() {
  static const Fixture* f = [] {
    auto* out = new Fixture;
    const std::string scene = RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml";
    const SceneFile file = LoadSceneFile(scene);
    out->setup.safety = safety::ConfigFromScene(file);
    const robot::RobotScene robot = robot::LoadRobotScene(file);
    out->setup.robot = robot.model;
    for (const SceneFilePatch& p : file.patches) {
      const patch::PatchSpec spec = patch::LoadPatchSpec(p.spec_path);
      aggregate::PatchExpectation e;
      e.id = p.name;
      e.spec_name = spec.name;
      e.spec_fingerprint = spec.Fingerprint();
      e.model_sha256 = "abc";
      e.extent_y_mm = spec.extent_y_mm;
      e.extent_r_deg = spec.extent_r_deg;
      e.mount = robot.FindPatch(p.name)->mount;
      out->setup.patches.push_back(e);
    }
    out->setup.run_id = kRunId;
    out->setup.robot_name = file.name;
    return out;
  }();
  return *f;
}

inline bool Finite(double v) { return std::isfinite(v); }

inline void CheckState(const v1::SafetyState& s, const std::string& robot) {
  Check(s.aggregator_run_id() == kRunId, "SafetyState carries the run id");
  Check(s.robot_name() == robot, "SafetyState carries the robot name");
  const v1::SafetyCause& c = s.cause();
  Check(Finite(c.force_n()) && Finite(c.threshold_n()), "finite cause force and threshold");
  Check(Finite(c.p_bc_m().x()) && Finite(c.p_bc_m().y()) && Finite(c.p_bc_m().z()), "finite cause position");
  // A NaN or infinite force is named as such in the message of its doubt; nothing else may read nan or inf.
  if (c.message().find("non_finite_force") == std::string::npos) {
    Check(c.message().find("nan") == std::string::npos && c.message().find("inf") == std::string::npos,
          "no nan or inf in the cause's message (but a non-finite force's own doubt)");
  }
  if (s.state() == v1::SafetyState::STATE_CLEAR) {
    Check(c.kind() == v1::SafetyCause::KIND_UNSPECIFIED, "CLEAR has no cause");
  } else {
    Check(s.state() == v1::SafetyState::STATE_STOP || s.state() == v1::SafetyState::STATE_FAULT, "a known state");
    Check(c.kind() != v1::SafetyCause::KIND_UNSPECIFIED, "STOP or FAULT has a cause");
  }
}

inline void CheckContacts(const v1::ContactSet& set) {
  for (const v1::BodyContact& b : set.contacts()) {
    Check(Finite(b.force_n()) && Finite(b.force_sd_n()) && Finite(b.threshold_n()), "finite contact force");
    Check(Finite(b.p_bc_m().x()) && Finite(b.p_bc_m().y()) && Finite(b.p_bc_m().z()), "finite contact p_bc_m");
    Check(Finite(b.p_lc_m().x()) && Finite(b.p_lc_m().y()) && Finite(b.p_lc_m().z()), "finite contact p_lc_m");
    Check(Finite(b.normal_b().x()) && Finite(b.normal_b().y()) && Finite(b.normal_b().z()), "finite normal");
    const auto& v = b.cov_p_bc_m2();
    Check(Finite(v.xx()) && Finite(v.xy()) && Finite(v.xz()) && Finite(v.yy()) && Finite(v.yz()) && Finite(v.zz()),
          "finite contact covariance");
  }
}

}  // namespace detail

using namespace detail;

// What one run did (for a property test's tallies).
struct Tally {
  long steps = 0, hellos_accepted = 0, accepted_resets = 0, stops = 0, faults = 0, clears = 0, takeovers = 0;
};

// Runs the program in data[0, size); aborts with a message when an invariant breaks.
inline Tally Run(const std::uint8_t* data, std::size_t size) {
  Tally tally;
  const Fixture& fx = TheFixture();
  const aggregate::Setup& setup = fx.setup;
  const std::size_t patches = setup.patches.size();
  Reader in{data, size};
  std::int64_t now = kT0;
  aggregate::Core core(setup, now);

  struct Open {
    int id;
    std::uint64_t seq = 0;  // the last seq sent
    int patch = -1;         // the patch of its hello (the envelope's)
  };
  std::vector<Open> streams;
  std::vector<int> joint_streams = {0};
  v1::SafetyState last = core.SafetyState();
  CheckState(last, setup.robot_name);

  auto end = [&](int id) {
    for (std::size_t k = 0; k < streams.size(); ++k) {
      if (streams[k].id == id) {
        streams.erase(streams.begin() + static_cast<long>(k));
        break;
      }
    }
    core.CloseStream(id, now);
  };
  auto send = [&](std::size_t k, v1::PatchMessage m, bool keep_seq) {
    Open& s = streams[k];
    if (s.patch >= 0) m.set_patch_id(setup.patches[static_cast<std::size_t>(s.patch)].id);
    m.set_seq(keep_seq ? s.seq + 1 : in.u64());
    s.seq = m.seq();
    m.set_decoder_t_ns(now);
    const int id = s.id;
    // The decoder's part of the safety layer (docs/safety-channel.md): run id, send time (now: fresh), the
    // aggregator run, the CRC. No byte of the program is spent on it (the programs' byte language is
    // unchanged); a random seq (keep_seq false) still drives the layer's sequence paths.
    m.set_sender_run_id(0xF0220000ULL + static_cast<std::uint64_t>(id));
    m.set_sender_steady_ns(now);
    m.set_aggregator_run_id(m.has_hello() && m.seq() <= 1 ? 0 : kRunId);
    channel::Seal(m);
    const aggregate::Core::Reply r = core.OnPatchMessage(id, m, now);
    if (r.command && r.command->has_hello_accepted()) {
      Check(r.command->hello_accepted().aggregator_run_id() == kRunId, "HelloAccepted carries the run id");
      Check(r.command->hello_accepted().robot_name() == setup.robot_name, "HelloAccepted carries the robot name");
    }
    if (r.end_stream >= 0) {
      Check(r.end_stream != id, "a takeover never ends the stream that took over");
      end(r.end_stream);
    }
    if (r.close) end(id);
  };
  auto pick_stream = [&]() -> std::size_t { return in.u8() % streams.size(); };

  int steps = 0;
  while (!in.done() && steps++ < 2000) {
    const std::uint8_t op = in.u8();
    bool accepted_reset = false;
    now += static_cast<std::int64_t>(in.u8()) * 200'000;  // 0 .. 51 ms a step
    switch (op % 14) {
      case 0: {  // a new stream (sometimes bound to a patch's identity)
        const std::uint8_t a = in.u8();
        const std::string allowed = a % 4 == 0 ? setup.patches[a / 4 % patches].id : std::string();
        if (streams.size() < 16) streams.push_back({core.OpenStream(now, allowed)});
        break;
      }
      case 1:
      case 2: {  // a hello (first or re-sent), right or wrong
        if (streams.empty()) break;
        const std::size_t k = pick_stream();
        const std::uint8_t a = in.u8(), b = in.u8();
        const std::size_t patch = a % (patches + 1);  // == patches: an unknown patch
        v1::PatchMessage m;
        m.set_patch_id(patch < patches ? setup.patches[patch].id : "elbow");
        auto* h = m.mutable_hello();
        const aggregate::PatchExpectation& want = setup.patches[patch % patches];
        h->set_patch_name(b & 1 ? "other" : want.spec_name);
        h->set_patch_fingerprint(b & 2 ? "00" : want.spec_fingerprint);
        h->set_model_patch_fingerprint(want.spec_fingerprint);
        h->set_model_sha256(b & 4 ? "def" : "abc");
        h->set_heartbeat_period_ns(b & 8 ? 50 * kMs : 10 * kMs);
        h->set_sample_rate_hz(b & 16 ? std::nan("") : 1000.0);
        if (streams[k].seq == 0) {
          if (patch < patches) streams[k].patch = static_cast<int>(patch);
          m.set_seq(b & 32 ? 2 : 1);
          streams[k].seq = m.seq();
          const int id = streams[k].id;
          m.set_sender_run_id(0xF0220000ULL + static_cast<std::uint64_t>(id));
          m.set_sender_steady_ns(now);
          channel::Seal(m);
          const auto r = core.OnPatchMessage(id, m, now);
          if (r.command && r.command->has_hello_accepted()) {
            Check(r.command->hello_accepted().aggregator_run_id() == kRunId, "HelloAccepted carries the run id");
          }
          if (r.end_stream >= 0) end(r.end_stream);
          if (r.close) end(id);
        } else {
          send(k, m, (b & 64) == 0);
        }
        break;
      }
      case 3:
      case 4: {  // a heartbeat
        if (streams.empty()) break;
        const std::size_t k = pick_stream();
        const std::uint8_t a = in.u8();
        v1::PatchMessage m;
        m.set_t_ns(a & 8 ? in.stamp(now) : now - kMs);
        auto* hb = m.mutable_heartbeat();
        hb->set_healthy((a & 1) == 0);
        hb->set_in_contact((a & 2) != 0);
        if (a & 4) hb->set_active_fault(static_cast<v1::PatchFaultCode>(static_cast<std::int32_t>(in.u32())));
        send(k, m, (a & 16) == 0 || in.u8() != 0);
        break;
      }
      case 5:
      case 6:
      case 7: {  // a contact frame
        if (streams.empty()) break;
        const std::size_t k = pick_stream();
        const std::uint8_t a = in.u8();
        v1::PatchMessage m;
        m.set_t_ns(in.stamp(now));
        auto* c = m.mutable_contact();
        c->set_force_n(in.force());
        c->set_onset((a & 1) != 0);
        c->set_released((a & 2) != 0);
        c->set_located((a & 4) != 0);
        if (a & 8) {
          c->set_y_mm(in.f32());
          c->set_r_deg(in.f32());
        } else {
          c->set_y_mm(static_cast<float>(in.u8()) * 0.6f);
          c->set_r_deg(static_cast<float>(in.u8()) * 0.6f);
        }
        if (a & 16) {
          c->set_cov_yy_mm2(in.f32());
          c->set_cov_yr_mm2(in.f32());
          c->set_cov_rr_mm2(in.f32());
        } else {
          c->set_cov_yy_mm2(4);
          c->set_cov_rr_mm2(4);
        }
        c->set_force_sd_n(a & 32 ? in.f32() : 0.02f);
        c->set_uncertainty_calibrated((a & 64) != 0);
        // Flagged faint on half the frames, from bits already read (no byte of its own: programs read as before).
        c->set_faint((((a >> 1) ^ (a >> 5)) & 1) != 0);
        send(k, m, (a & 128) == 0 || in.u8() != 0);
        break;
      }
      case 8: {  // a fault
        if (streams.empty()) break;
        v1::PatchMessage m;
        m.mutable_fault()->set_code(static_cast<v1::PatchFaultCode>(static_cast<std::int32_t>(in.u32())));
        send(pick_stream(), m, true);
        break;
      }
      case 9: {  // a stream ends
        if (streams.empty()) break;
        end(streams[pick_stream()].id);
        break;
      }
      case 10: {  // a joint state
        const std::uint8_t a = in.u8();
        const int js_stream = a % 3;
        v1::JointState js;
        const std::size_t n = setup.robot->num_dof() + (a & 8 ? 1 : 0);
        for (std::size_t j = 0; j < n; ++j) js.add_positions_rad(a & 16 && j == 2 ? in.f32() : 0.1 * static_cast<double>(j));
        if (a & 32) {
          for (std::size_t j = 0; j < n; ++j) js.add_names(j < setup.robot->num_dof() ? setup.robot->dof_joint(j).name : "x");
        }
        js.set_t_ns(a & 64 ? in.stamp(now) : now);
        (void)core.OnJointState(js, now, js_stream);
        if (a & 128) core.CloseJointStream(js_stream);
        break;
      }
      case 11: {  // a reset
        const std::uint8_t a = in.u8();
        v1::ResetStopRequest r;
        const std::uint64_t epoch = core.SafetyState().stop_epoch();
        r.set_stop_epoch(a & 1 ? epoch + (a & 2 ? 1 : -1) : epoch);
        r.set_aggregator_run_id(a & 4 ? (a & 8 ? 0 : kRunId ^ 1) : kRunId);
        r.set_operator_name("fuzz");
        const bool authorized = (a & 16) == 0;
        const v1::ResetStopResponse resp = core.OnReset(r, authorized, now);
        accepted_reset = resp.accepted();
        if (accepted_reset) {
          Check(r.aggregator_run_id() == kRunId, "an accepted reset named this run");
          Check(authorized, "an accepted reset was authorized");
          Check(r.stop_epoch() == last.stop_epoch(), "an accepted reset named the epoch in force");
        }
        CheckState(resp.state(), setup.robot_name);
        break;
      }
      case 12: {  // the loop's periodic work
        core.Tick(now);
        if (in.u8() & 1) core.Publish(now);
        break;
      }
      case 13: {  // what subscribers and GetStatus see
        CheckContacts(core.Contacts(now));
        const v1::AggregatorStatus st = core.Status(now);
        Check(st.aggregator_run_id() == kRunId && st.robot_name() == setup.robot_name, "status carries the identity");
        Check(st.joint_state_age_ns() >= -1, "joint_state_age_ns is never below -1");
        CheckState(st.safety(), setup.robot_name);
        break;
      }
    }
    (void)core.TakeEvents();
    (void)core.TakeChanged();
    const v1::SafetyState s = core.SafetyState();
    CheckState(s, setup.robot_name);
    Check(s.stop_epoch() >= last.stop_epoch(), "stop_epoch never decreases");
    Check(s.seq() >= last.seq(), "seq never decreases");
    if (last.state() != v1::SafetyState::STATE_CLEAR && s.state() == v1::SafetyState::STATE_CLEAR) {
      Check(accepted_reset, "no CLEAR without an accepted reset");
      ++tally.clears;
    }
    tally.accepted_resets += accepted_reset;
    tally.stops += s.state() == v1::SafetyState::STATE_STOP && last.state() != v1::SafetyState::STATE_STOP;
    tally.faults += s.state() == v1::SafetyState::STATE_FAULT && last.state() != v1::SafetyState::STATE_FAULT;
    if (accepted_reset) Check(s.stop_epoch() == last.stop_epoch(), "a reset keeps the epoch");
    last = s;
  }
  // Shutdown is FAULT, forever.
  core.Shutdown(now);
  Check(core.SafetyState().state() == v1::SafetyState::STATE_FAULT, "shutdown is FAULT");
  tally.steps = steps;
  tally.hellos_accepted = static_cast<long>(core.counters().hellos_accepted);
  tally.takeovers = static_cast<long>(core.counters().takeovers);
  return tally;
}

}  // namespace ruffini::core_program
