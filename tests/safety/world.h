#pragma once
// A two-patch scene and a driver for the safety policy on a simulated clock (ms since kT0).
#include <cstdint>
#include <set>
#include <string>

#include "ruffini/safety/policy.h"

namespace ruffini::safety::testing {

inline constexpr std::int64_t kT0 = 1'700'000'000'000'000'000LL;  // Unix ns
inline constexpr std::int64_t kMs = 1'000'000;

// forearm (160 N) and upper_arm (150 N), a hand region (140 N) for overrides; 30 ms silence deadlines,
// joint states within 50 ms, 200 ms healthy before a reset.
inline Config TwoPatchScene() {
  Config c;
  c.new_epoch_per_cause = false;  // the table rows assume it; EpochPerCause() turns it on
  c.regions = {{.name = "forearm", .threshold_n = 160.0f, .source = "quoted ISO/TS 15066 value (FACTS.md)"},
               {.name = "upper_arm", .threshold_n = 150.0f, .source = "quoted ISO/TS 15066 value (FACTS.md)"},
               {.name = "hand", .threshold_n = 140.0f, .source = "quoted ISO/TS 15066 value (FACTS.md)"}};
  c.patches = {{.id = "forearm", .region = "forearm", .silence_deadline_ns = 30 * kMs},
               {.id = "upper_arm", .region = "upper_arm", .silence_deadline_ns = 30 * kMs}};
  c.joint_states_required = true;
  c.joint_state_max_age_ns = 50 * kMs;
  c.healthy_before_reset_ns = 200 * kMs;
  return c;
}

struct World {
  explicit World(Config c = TwoPatchScene()) : policy(std::move(c)), data(policy, kT0) {}

  Policy policy;
  Data data;
  std::int64_t t = kT0;
  std::set<std::string> quiet;     // patches that send nothing during Beat()
  std::set<std::string> touching;  // patches whose heartbeats say in_contact during Beat()
  bool joints = true;            // Beat() sends joint states
  Step last{};
  ResetResult reset{};

  [[nodiscard]] std::int64_t ms() const { return (t - kT0) / kMs; }
  void Wait(std::int64_t dt_ms) { t += dt_ms * kMs; }

  void Hello(std::string_view patch) { last = policy.OnHelloAccepted(data, patch, t); }
  void Connect() {
    for (const PatchConfig& p : policy.config().patches) Hello(p.id);
  }
  // Every 10 ms for dt_ms: a healthy heartbeat from every patch not quiet, and a joint state.
  void Beat(std::int64_t dt_ms) {
    for (std::int64_t k = 0; k < dt_ms / 10; ++k) {
      Wait(10);
      for (const PatchConfig& p : policy.config().patches) {
        if (!quiet.contains(p.id)) {
          last = policy.OnHeartbeat(data, p.id, {.healthy = true, .in_contact = touching.contains(p.id)}, t);
        }
      }
      if (joints) last = policy.OnJointState(data, t);
    }
  }
  ResetResult Reset(std::uint64_t epoch) {
    reset = policy.Reset(data, {.stop_epoch = epoch, .authorized = true}, t);
    return reset;
  }
  ResetResult ResetCurrent() { return Reset(data.state().stop_epoch); }
  // Start-up done: every patch connected and healthy for 200 ms (heartbeats from 10 ms to 210 ms), epoch 1
  // reset: CLEAR.
  void Clear() {
    Connect();
    Beat(210);
    ResetCurrent();
  }
  void Contact(std::string_view patch, float force_n, std::string_view region = {}, bool released = false) {
    last = policy.OnContact(data, patch, {.force_n = force_n, .region = region, .released = released}, t);
  }
  [[nodiscard]] State state() const { return data.state().state; }
  [[nodiscard]] std::uint64_t epoch() const { return data.state().stop_epoch; }
};

}  // namespace ruffini::safety::testing
