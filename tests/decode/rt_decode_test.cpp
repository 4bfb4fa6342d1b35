// Decode() allocates nothing: a counting global operator new, armed around the calls.
#include <gtest/gtest.h>

#include "../common/alloc_counter.h"
#include "ruffini/decode/baseline.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/patch/spec_loader.h"
#include "synthetic_model.h"

namespace ruffini::decode {
namespace {

template <typename Scalar>
long CountAllocations(int window) {
  const auto spec = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  const auto m = testing::SyntheticModel(spec, window);
  NetworkDecoder<Scalar> d(m);
  typename NetworkDecoder<Scalar>::Data data(d);
  BaselineTracker baseline;
  Wavelengths wl;
  ShiftsPm s;
  return ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 2000; ++k) {
      for (std::size_t i = 0; i < 16; ++i) wl[i] = 1530.0 + 2.3 * static_cast<double>(i) + (k > 200 && i == 3 ? 0.2 : 0.0);
      if (k % 97 == 0) wl[7] = std::nan("");
      baseline.Update(wl, s);
      const auto o = d.Decode(s, data);
      (void)o;
    }
  });
}

TEST(RealTime, DecodeDoesNotAllocate) {
  EXPECT_EQ(CountAllocations<float>(1), 0);
  EXPECT_EQ(CountAllocations<float>(32), 0);
  EXPECT_EQ(CountAllocations<double>(8), 0);
  int* seen = nullptr;  // the counter counts
  EXPECT_EQ(ruffini::testing::CountAllocations([&] { seen = new int(1); }), 1);
  delete seen;
}

// The whole per-frame path (plausibility, baseline, networks, uncertainty), with bad frames mixed in.
TEST(RealTime, PipelineProcessDoesNotAllocate) {
  const auto spec = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  auto m = testing::SyntheticModel(spec, 16);
  m.mutable_preprocessing()->set_common_mode_removed(true);
  auto* u = m.mutable_uncertainty();
  u->add_force_knots_n(0.1f);
  u->add_force_sd_n(0.02f);
  u->add_position_scale(2.0f);
  PipelineConfig cfg;
  cfg.baseline = BaselineFor(m, 1000.0);
  cfg.z_limit = 1e6;  // the synthetic model's std is 1 pm
  const Pipeline<float> p(m, spec, cfg);
  Pipeline<float>::Data data(p);
  Wavelengths wl;
  long located = 0;
  const long n = ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 3000; ++k) {
      for (std::size_t i = 0; i < 16; ++i) wl[i] = spec.gratings[i].wavelength_nm + 1e-6 * k + (k > 1200 && i == 3 ? 0.2 : 0.0);
      if (k % 97 == 0) wl[7] = std::nan("");
      if (k % 211 == 0) wl.fill(0.0);
      const auto o = p.Process(wl, k % 389 == 0 ? 1u : 0u, data);
      located += o.located;
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_GT(located, 1000);  // the path under test did run the networks
}

}  // namespace
}  // namespace ruffini::decode
