// The steps `ruffini bench` times for the Eigen runtime (baseline update then decode; the shipped
// decode::Pipeline::Process) allocate nothing, so the bench times arithmetic, not the allocator.
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
      located += step->Step(wl, 0) ? 1 : 0;
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_GT(located, 0u);      // location ran
  EXPECT_LT(located, 2000u);   // and did not always
}

template <typename Scalar>
void PipelineStepDoesNotAllocate() {
  const auto spec = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  auto m = decode::testing::SyntheticModel(spec, 16);
  // The synthetic model's std is 1 pm: without a known input range every press would be out of range.
  auto* range = m.mutable_input_range();
  for (int i = 0; i < 16; ++i) {
    range->add_min_shift_pm(-50.0f);
    range->add_max_shift_pm(300.0f);
  }
  range->set_margin_pm(50.0f);
  PipelineStep<Scalar> step(m, spec, ShippedPipelineConfig(m, 100.0));
  step.Restart();  // untimed in the bench: allocates the stream's state
  decode::Wavelengths wl;
  for (std::size_t i = 0; i < 16; ++i) wl[i] = spec.gratings[i].wavelength_nm;
  for (int k = 0; k < 300; ++k) (void)step.Step(wl, 0);  // the baseline captured
  ASSERT_TRUE(step.last().valid) << decode::ReasonName(step.last().reason);
  std::size_t contact = 0, valid = 0;
  const long n = ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 2000; ++k) {
      const double press = k % 400 > 100 ? 0.2 : 0.0;  // 200 pm on and off: the gate opens and closes
      wl[3] = spec.gratings[3].wavelength_nm + press;
      wl[4] = spec.gratings[4].wavelength_nm + 0.5 * press;
      wl[7] = k % 97 == 0 ? std::nan("") : spec.gratings[7].wavelength_nm;
      const std::uint32_t flags = k % 501 == 0 ? decode::Pipeline<Scalar>::kSourceSaturated : 0u;  // an invalid frame now and then
      contact += step.Step(wl, flags) ? 1 : 0;
      valid += step.last().valid ? 1 : 0;
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_GT(contact, 0u);     // the gate opened (location ran)
  EXPECT_LT(contact, 2000u);  // and closed
  EXPECT_GT(valid, 1000u);
}

TEST(RealTime, PipelineStepDoesNotAllocateFloat) { PipelineStepDoesNotAllocate<float>(); }
TEST(RealTime, PipelineStepDoesNotAllocateDouble) { PipelineStepDoesNotAllocate<double>(); }

}  // namespace
}  // namespace ruffini::eval
