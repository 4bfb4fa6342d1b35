// The step `ruffini bench` times for the Eigen runtime (baseline update, then decode) allocates nothing, so the
// bench times arithmetic, not the allocator.
#include <gtest/gtest.h>

#include <cmath>

#include "../common/alloc_counter.h"
#include "../decode/synthetic_model.h"
#include "ruffini/eval/bench.h"
#include "ruffini/patch/spec_loader.h"

namespace ruffini::eval {
namespace {

TEST(RealTime, BenchStepDoesNotAllocate) {
  const auto spec = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  const auto m = decode::testing::SyntheticModel(spec, 16);
  NetworkFrameDecoder<float> dec(m);
  const std::unique_ptr<FrameStep> step = MakeFrameStep(dec);
  decode::Wavelengths wl;
  for (std::size_t i = 0; i < 16; ++i) wl[i] = 1530.0 + 2.3 * static_cast<double>(i);
  decode::BaselineTracker tracker;
  decode::ShiftsPm s{};
  for (int k = 0; k < 200; ++k) tracker.Update(wl, s);  // a captured baseline
  step->Reset(tracker, s);
  std::size_t located = 0;
  const long n = ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 2000; ++k) {
      wl[3] = 1530.0 + 2.3 * 3 + (k % 400 > 100 ? 0.2 : 0.0);  // 200 pm on and off: the gate opens and closes
      wl[7] = k % 97 == 0 ? std::nan("") : 1530.0 + 2.3 * 7;
      located += step->Step(wl).located ? 1 : 0;
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_GT(located, 0u);      // location ran
  EXPECT_LT(located, 2000u);   // and did not always
}

}  // namespace
}  // namespace ruffini::eval
