// Every event of the policy allocates nothing once the Data is built: a counting global operator new, armed
// around a run through start-up, clearing, contacts, faults, silences, bad input, resets and shutdown.
#include <gtest/gtest.h>

#include <limits>

#include "../common/alloc_counter.h"
#include "world.h"

namespace ruffini::safety {
namespace {

using testing::World;

TEST(SafetyRealTime, EventsDoNotAllocate) {
  World w;
  const long n = ruffini::testing::CountAllocations([&] {
    for (int round = 0; round < 3; ++round) {
      w.Connect();
      w.Beat(210);
      w.ResetCurrent();
      w.Contact("forearm", 10.0f, "hand");
      w.Contact("upper_arm", 400.0f);
      w.Contact("forearm", std::numeric_limits<float>::quiet_NaN());
      w.Contact("forearm", -1.0f);
      w.Contact("tail", 1.0f);
      w.Contact("forearm", 1.0f, "tail");
      (void)w.policy.OnHeartbeat(w.data, "forearm", {.healthy = false}, w.t);
      (void)w.policy.OnPatchFault(w.data, "upper_arm", PatchFaultCode::kFramesLost, w.t);
      (void)w.policy.OnProtocolError(w.data, "upper_arm", w.t);
      (void)w.policy.Tick(w.data, w.t - 1);
      w.Reset(1);
      w.ResetCurrent();
      (void)w.policy.OnDisconnect(w.data, "forearm", w.t);
      (void)w.policy.OnHelloRefused(w.data, "upper_arm", w.t);
      w.Wait(100);
      (void)w.policy.Tick(w.data, w.t);
      (void)w.policy.Publish(w.data, w.t);
      (void)w.policy.OnJointState(w.data, w.t);
    }
    (void)w.policy.Shutdown(w.data, w.t);
    w.ResetCurrent();
  });
  EXPECT_EQ(n, 0);
  EXPECT_EQ(w.data.counters().resets_accepted, 3u);
  EXPECT_EQ(w.state(), State::kFault);
}

TEST(SafetyRealTime, TheCounterCounts) {
  int* seen = nullptr;
  EXPECT_EQ(ruffini::testing::CountAllocations([&] { seen = new int(1); }), 1);
  delete seen;
}

}  // namespace
}  // namespace ruffini::safety
