// Decode() allocates nothing: a counting global operator new, armed around the calls.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "../common/alloc_counter.h"
#include "ruffini/decode/baseline.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/decode/touches.h"
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


// A synthetic model with calibrated uncertainty and a ResponseMap over the whole patch: a Gaussian bump of
// sensitivity (10 mm sigma) at each grating.
v1::DecoderModel ModelWithResponseMap(const patch::PatchSpec& spec) {
  auto m = testing::SyntheticModel(spec, 16);
  m.mutable_preprocessing()->set_common_mode_removed(true);
  auto* u = m.mutable_uncertainty();
  u->add_force_knots_n(0.1f);
  u->add_force_sd_n(0.02f);
  u->add_position_scale(2.0f);
  ResponseModel r;
  r.dy_mm = 1.5;
  r.dr_deg = 2.0;
  r.ny = static_cast<int>(spec.extent_y_mm / r.dy_mm) + 1;
  r.nr = static_cast<int>(spec.extent_r_deg / r.dr_deg) + 1;
  r.g.resize(static_cast<std::size_t>(r.ny * r.nr));
  const double mm_per_deg = spec.surface_radius_mm * std::numbers::pi / 180.0;
  for (int iy = 0; iy < r.ny; ++iy) {
    for (int ir = 0; ir < r.nr; ++ir) {
      for (std::size_t i = 0; i < 16; ++i) {
        const double dy = iy * r.dy_mm - spec.gratings[i].centre.y_mm;
        const double da = (ir * r.dr_deg - spec.gratings[i].centre.r_deg) * mm_per_deg;
        r.g[static_cast<std::size_t>(iy * r.nr + ir)][i] = static_cast<float>(100.0 * std::exp(-(dy * dy + da * da) / 200.0));
      }
    }
  }
  *m.mutable_response() = ToProto(r, 0.05, "rt test");
  return m;
}

// The forearm spec, a model with a response map, and its pipeline at 1 kHz (the next two tests').
struct MapRig {
  patch::PatchSpec spec = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  v1::DecoderModel model = ModelWithResponseMap(spec);
  Pipeline<float> p{model, spec, [this] {
                      PipelineConfig cfg;
                      cfg.baseline = BaselineFor(model, 1000.0);
                      cfg.z_limit = 1e6;
                      return cfg;
                    }()};
};

// The same with a ResponseMap and frames two touches far apart: the check flags them and the two-touch fit
// runs (once every multi_refit_s), still without allocating (review: the RT claim of touches.h was untested).
TEST(RealTime, PipelineWithAResponseMapDoesNotAllocate) {
  const MapRig rig;
  const auto& spec = rig.spec;
  const Pipeline<float>& p = rig.p;
  Pipeline<float>::Data data(p);
  Wavelengths wl;
  long located = 0, multiple = 0;
  const long n = ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 3000; ++k) {
      for (std::size_t i = 0; i < 16; ++i) {
        wl[i] = spec.gratings[i].wavelength_nm + 1e-6 * k + (k > 1200 && (i == 0 || i == 15) ? 0.2 : 0.0);
      }
      if (k % 97 == 0) wl[7] = std::nan("");
      if (k % 211 == 0) wl.fill(0.0);
      const auto o = p.Process(wl, k % 389 == 0 ? 1u : 0u, data);
      located += o.located;
      multiple += o.multiple;
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_GT(located, 1000);
  EXPECT_GT(multiple, 1000) << "the two-touch path ran";
}

// The two-touch fit's cache (Data::pair_) does not outlive a gap of invalid or over-range frames (review: it did,
// since invalid() and over_range() return before `located` is computed): the first located frame after the gap is
// placed from a fresh fit, not at the old pair's centre.
TEST(RealTime, TheTwoTouchCacheIsNotReusedAcrossAGap) {
  const MapRig rig;
  const auto& spec = rig.spec;
  const Pipeline<float>& p = rig.p;
  Pipeline<float>::Data data(p);
  Wavelengths wl;
  PipelineOutput before, after_gap, settled;
  for (int k = 0; k < 1700; ++k) {
    const bool first = k >= 1200 && k < 1600, second = k >= 1605;
    for (std::size_t i = 0; i < 16; ++i) {
      const bool pressed = (first && (i == 0 || i == 15)) || (second && (i == 2 || i == 5));
      wl[i] = spec.gratings[i].wavelength_nm + (pressed ? 0.2 : 0.0);
    }
    if (k >= 1600 && k < 1605) wl.fill(0.0);  // 5 frames without signal while loaded: over range
    const auto o = p.Process(wl, 0u, data);
    if (k == 1599) before = o;
    if (k == 1605) after_gap = o;
    if (k == 1650) settled = o;
  }
  ASSERT_TRUE(before.multiple && after_gap.multiple && settled.multiple);
  EXPECT_NEAR(after_gap.y_mm, settled.y_mm, 1.0) << "the frame after the gap is placed from the old pair";
  EXPECT_NEAR(after_gap.r_deg, settled.r_deg, 1.0) << "the frame after the gap is placed from the old pair";
}

}  // namespace
}  // namespace ruffini::decode
