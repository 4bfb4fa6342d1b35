// Regression tests for bad input reaching the twin, the protocols and the report (from review findings).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "ruffini/error.h"
#include "ruffini/patch/spec_loader.h"
#include "ruffini/twin/contact.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/report.h"
#include "ruffini/twin/scene.h"

#include "fixtures.h"

namespace ruffini::twin {
namespace {

using fixtures::DefaultScene;
using fixtures::PlainTwin;

TEST(TwinRobustness, NonFiniteOrOversizedProbeRadiusIsRejected) {
  const SkinTwin& t = PlainTwin();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const Probe p : {Probe{Probe::Shape::kPoint, nan}, Probe{Probe::Shape::kPoint, -1.0},
                        Probe{Probe::Shape::kPoint, 50.0}, Probe{Probe::Shape::kSphere, nan}}) {
    const Contact c{{70, 70}, 1.0, p};
    Shifts s;
    std::uint32_t flags = 0;
    t.StrainShiftsPm(std::span<const Contact>(&c, 1), s, flags);
    EXPECT_TRUE(flags & kFlagBadContact);
    for (double v : s) EXPECT_EQ(v, 0.0);
  }
}

// Huge forces: bottomed out, the fibre pinched; every wavelength is either inside the window or a missing
// peak (NaN, flagged): never an infinity or a wavelength out of the window.
TEST(TwinRobustness, HugeForcesGiveWindowedOrMissingPeaksNeverInfinities) {
  const SkinTwin& t = PlainTwin();
  InterrogatorSim sim(t, 1);
  const Probe sphere{};
  for (double f : {1e6, 1e18, 1e300, std::numeric_limits<double>::max()}) {
    const Contact cs[2] = {{{70, 70}, f, sphere}, {{71, 71}, f, Probe{Probe::Shape::kPoint, 0.25}}};
    Shifts s;
    std::uint32_t flags = 0;
    t.StrainShiftsPm(cs, s, flags);
    EXPECT_TRUE(flags & kFlagSaturated) << f;
    std::array<double, 16> wl{};
    sim.Read(0.0, s, wl, flags);
    EXPECT_TRUE(flags & kFlagPeakMissing) << f;  // (70, 70) lies on the fibre: pinched
    for (std::size_t i = 0; i < 16; ++i) {
      ASSERT_FALSE(std::isinf(wl[i])) << f;
      if (!std::isnan(wl[i])) {
        EXPECT_GE(wl[i], t.spec().interrogator.window_min_nm);
        EXPECT_LE(wl[i], t.spec().interrogator.window_max_nm);
      }
    }
  }
  // NaN strain (a pinched grating, or anyone calling Read) becomes a missing peak, not a NaN shift.
  Shifts bad{};
  bad[3] = std::numeric_limits<double>::quiet_NaN();
  std::array<double, 16> wl{};
  std::uint32_t flags = 0;
  sim.Read(0.0, bad, wl, flags);
  EXPECT_TRUE(flags & kFlagPeakMissing);
  EXPECT_TRUE(std::isnan(wl[3]));
  EXPECT_TRUE(std::isfinite(wl[4]));
}

TEST(ContactLawTest, MonotoneInvertibleAndSafeAtExtremes) {
  const ContactLaw law(8.0, 152.0, 0.49, 5.5);
  double prev = -1;
  for (double d = 0.0; d < law.max_depth_mm(); d += 0.05) {
    const double f = law.ForceN(d);
    EXPECT_GT(f, prev);
    prev = f;
    EXPECT_NEAR(law.DepthMm(f), d, 0.005) << d;
  }
  // FACTS.md: about 2.5 N at about 1.8 mm for the 11 mm probe on this layer.
  EXPECT_NEAR(law.DepthMm(2.5), 1.8, 0.15);
  EXPECT_EQ(law.DepthMm(1e18), law.max_depth_mm());
  EXPECT_EQ(law.DepthMm(std::numeric_limits<double>::infinity()), law.max_depth_mm());
  EXPECT_EQ(law.DepthMm(std::nan("")), 0.0);
  EXPECT_EQ(law.DepthMm(-1.0), 0.0);
  EXPECT_GT(law.linear_limit_force_n(), 2.5);
}

TEST(TwinRobustness, StiffeningSoftensTheResponseALittle) {
  TwinEffects stiff;
  stiff.stiffening = StiffeningEffect{};
  const SkinTwin a(DefaultScene().patches[0].spec, TwinEffects{}, {5.5});
  const SkinTwin b(DefaultScene().patches[0].spec, stiff, {5.5});
  const auto& g = a.spec().gratings[6].centre;
  const double lin = a.StrainShiftsPm(Contact{g, 2.5, Probe{}})[6];
  const double yeoh = b.StrainShiftsPm(Contact{g, 2.5, Probe{}})[6];
  EXPECT_LT(yeoh, lin);
  EXPECT_GT(yeoh, 0.95 * lin);  // Dragon Skin 10's Yeoh constants stiffen by well under 5 % at 2.5 N
  const double small_lin = a.StrainShiftsPm(Contact{g, 1e-6, Probe{}})[6];
  EXPECT_NEAR(b.StrainShiftsPm(Contact{g, 1e-6, Probe{}})[6], small_lin, 1e-9 * small_lin);  // none at small strain
}

TEST(ProtocolRobustness, ForceControlledProtocolsNeedASphere) {
  Scene s = DefaultScene();
  s.probe = Probe{Probe::Shape::kPoint, 0.25};
  const SkinTwin t(s.patches[0].spec, TwinEffects{}, {5.5});
  PaperProtocol p;
  p.indentations = 1;
  EXPECT_THROW(RunPaper(t, s, p, 1, [](std::span<const dataset::Frame>) {}), InputError);
  EXPECT_THROW(RunReceptiveField(t, s, ReceptiveFieldProtocol{}, 1, [](std::span<const dataset::Frame>) {}), InputError);
}

TEST(ProtocolRobustness, ASinkThatThrowsStopsTheRunOnce) {
  PaperProtocol p;
  p.indentations = 20;
  int calls = 0;
  EXPECT_THROW(RunPaper(PlainTwin(), DefaultScene(), p, 1,
                        [&](std::span<const dataset::Frame>) {
                          ++calls;
                          throw std::runtime_error("disk full");
                        }),
               std::runtime_error);
  EXPECT_EQ(calls, 1);
}

// A peak that drops out now and then must not corrupt its baseline (it once averaged NaN frames as 0 nm and
// "detected" every touch). Noise factor 1 isolates the dropout: a noisier grating does trip a 2 pm threshold.
TEST(ReportRobustness, DroppingPeakDoesNotFakeDetections) {
  TwinEffects e = DefaultScene().effects;
  e.faults.push_back(FaultEffect{5, FaultEffect::Kind::kDimmed, 0.3, 1.0});
  const SkinTwin t(DefaultScene().patches[0].spec, e, {5.5});
  VonFreyProtocol p;
  p.subjects = 1;
  p.filaments_g = {0.4, 60.0};
  const DetectionFit fit = MeasureDetection(t, p, 3, 2.0);
  ASSERT_EQ(fit.points.size(), 2u);
  EXPECT_LT(fit.points[0].rate(), 0.2);  // 4 mN is far below detection
  EXPECT_GT(fit.points[1].rate(), 0.5);
}

TEST(ReportRobustness, UnreachedThresholdIsNaNAndJsonStaysValid) {
  const DetectionFit f = FitDetection({{0.01, 20, 0}, {0.1, 20, 1}, {1.0, 20, 4}});
  EXPECT_TRUE(std::isnan(f.threshold75_n));
  TwinReport r;
  r.detection_uniform = f;
  const std::string json = ReportJson(r);
  EXPECT_EQ(json.find("nan"), std::string::npos);
  EXPECT_EQ(json.find("inf"), std::string::npos);
  EXPECT_NE(json.find("\"threshold75_n\": null"), std::string::npos);
}

TEST(SceneRobustness, SkinSampleThatWouldMergeBandsIsRejected) {
  patch::PatchSpec spec = DefaultScene().patches[0].spec;
  spec.fibre.band_half_width_nm = 1.149;  // 2.298 of the 2.3 nm spacing: any wavelength perturbation merges
  TwinEffects e;
  e.skin_sample = SkinSampleEffect{};
  EXPECT_THROW(SkinTwin(spec, e, {5.5}), InputError);
}

}  // namespace
}  // namespace ruffini::twin
