// Behaviour of the skin twin at the extremes: zero and overload forces, the patch edge, superposition,
// temperature, faults, skin samples, where the response peaks, and that effects are built only when named.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "ruffini/error.h"
#include "ruffini/patch/spec_loader.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

#include "fixtures.h"

namespace ruffini::twin {
namespace {

constexpr std::size_t kN = patch::kGratings;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

using fixtures::DefaultScene;
using fixtures::DefaultTwin;
using fixtures::PlainTwin;
using fixtures::Spec;

// Twins built with only a skin sample of the given seed (each seed changes the layer: new tables, built once).
const SkinTwin& SampleTwin(std::uint64_t seed) {
  static std::map<std::uint64_t, std::unique_ptr<SkinTwin>> twins;
  auto& t = twins[seed];
  if (!t) {
    TwinEffects e;
    e.skin_sample = SkinSampleEffect{};
    e.skin_sample->seed = seed;
    t = std::make_unique<SkinTwin>(Spec(), e, std::vector<double>{5.5});
  }
  return *t;
}

// A twin with the given effects on the nominal layer (cached tables: cheap).
SkinTwin TwinWith(const TwinEffects& e) { return SkinTwin(Spec(), e, {5.5}); }

Contact Sphere(double y, double r, double f) { return Contact{{y, r}, f, Probe{Probe::Shape::kSphere, 5.5}}; }

Shifts Shift(const SkinTwin& twin, std::vector<Contact> contacts, std::uint32_t& flags) {
  Shifts s;
  s.fill(kNaN);
  flags = 0;
  twin.StrainShiftsPm(contacts, s, flags);
  return s;
}

bool AllFinite(const Shifts& s) {
  return std::all_of(s.begin(), s.end(), [](double v) { return std::isfinite(v); });
}

// ---------------------------------------------------------------------------------------------------
// 1. Zero force.

TEST(TwinExtremes, ZeroForceGivesExactlyZeroShift) {
  for (const SkinTwin* twin : {&PlainTwin(), &DefaultTwin()}) {
    std::uint32_t flags = 0;
    const Shifts none = Shift(*twin, {}, flags);
    EXPECT_EQ(flags, 0u);
    for (double v : none) EXPECT_EQ(v, 0.0);
    const Shifts zero = Shift(*twin, {Sphere(66, 72.5, 0.0), Sphere(24, 42.5, 0.0)}, flags);
    EXPECT_EQ(flags, 0u);
    for (double v : zero) EXPECT_EQ(v, 0.0);
  }
}

TEST(TwinExtremes, ZeroForceWithoutNoiseReadsTheReferenceExactly) {
  const SkinTwin& twin = PlainTwin();
  InterrogatorSim sim(twin, 11);
  const Shifts zero{};
  for (int k = 0; k < 200; ++k) {
    std::array<double, kN> wl{};
    std::uint32_t flags = 0;
    sim.Read(k * 0.01, zero, wl, flags);
    EXPECT_EQ(flags, 0u);
    for (std::size_t i = 0; i < kN; ++i) ASSERT_EQ(wl[i], twin.reference_wavelength_nm()[i]) << "grating " << i + 1;
  }
}

TEST(TwinExtremes, ZeroForceWithNoiseStaysWithinSixSigma) {
  TwinEffects e;
  e.noise = NoiseEffect{0.3};
  const SkinTwin twin = TwinWith(e);
  InterrogatorSim sim(twin, 12);
  const Shifts zero{};
  double max_abs = 0.0, sum2 = 0.0;
  int n = 0;
  for (int k = 0; k < 2000; ++k) {
    std::array<double, kN> wl{};
    std::uint32_t flags = 0;
    sim.Read(k * 0.01, zero, wl, flags);
    EXPECT_EQ(flags, 0u);
    for (std::size_t i = 0; i < kN; ++i) {
      const double d = (wl[i] - twin.reference_wavelength_nm()[i]) * 1e3;
      ASSERT_TRUE(std::isfinite(d));
      max_abs = std::max(max_abs, std::abs(d));
      sum2 += d * d;
      ++n;
    }
  }
  EXPECT_LE(max_abs, 6 * 0.3);
  // The noise is really there, at about the asked level.
  const double sd = std::sqrt(sum2 / n);
  EXPECT_NEAR(sd, 0.3, 0.03);
}

// ---------------------------------------------------------------------------------------------------
// 2. Overload.

// Hard presses (docs/twin.md, "Hard presses"). The contact law beyond the linear limit: continuous there,
// monotone, the depth approaching the bottom (the cover on the limb) without reaching it; the force to get
// there diverges. Below the limit nothing changed (the paper's range).
TEST(TwinExtremes, HardPressLawStiffensUntilTheCoverBottomsOut) {
  const SkinTwin& twin = PlainTwin();
  const ContactLaw& law = *twin.contact_law(Probe{});
  const double limit_n = law.linear_limit_force_n();
  ASSERT_GT(limit_n, 2.5);  // the paper's range is linear
  ASSERT_LT(limit_n, 10.0);
  for (double f = 0.01; f <= limit_n; f += 0.05) EXPECT_EQ(law.HardDepthMm(f), law.DepthMm(f)) << f;
  EXPECT_EQ(law.StrainForceN(2.5), 2.5);
  double last_depth = 0.0, last_strain = 0.0;
  for (double f = 0.5; f <= 200.0; f *= 1.05) {
    const double d = law.HardDepthMm(f), e = law.StrainForceN(f);
    EXPECT_GT(d, last_depth) << f;
    EXPECT_GE(e, last_strain) << f;
    EXPECT_LT(d, law.bottom_depth_mm()) << f;
    EXPECT_NEAR(law.HardForceN(d), f, 1e-3 * f) << f;  // the table inverts the law
    last_depth = d;
    last_strain = e;
  }
  // Stiffening: 200 N pushes the probe only a little deeper than 50 N, and the bottom needs > 1 kN.
  EXPECT_LT(law.HardDepthMm(200.0) - law.HardDepthMm(50.0), law.HardDepthMm(50.0) - law.HardDepthMm(limit_n));
  EXPECT_GT(law.HardForceN(law.bottom_depth_mm()), 1000.0);
  EXPECT_NEAR(law.HardForceN(ContactLaw::kLinearCompressionLimit * law.thickness_mm() * (1 + 1e-9)), limit_n, 1e-6);
}

// The grating under the probe responds monotonically from a touch to the point where its peak leaves its
// band or is lost (the fibre pinched): never a response that saturates in the band, as before.
TEST(TwinExtremes, HardPressResponseGrowsUntilThePeakLeavesItsBandOrIsLost) {
  const SkinTwin& twin = PlainTwin();
  const double band_pm = twin.spec().fibre.band_half_width_nm * 1e3;
  for (std::size_t g = 0; g < kN; ++g) {
    const auto& c = twin.spec().gratings[g].centre;
    double last = 0.0;
    bool left = false;
    for (double f = 0.5; f <= 200.0; f *= 1.1) {
      std::uint32_t flags = 0;
      const Shifts s = Shift(twin, {Sphere(c.y_mm, c.r_deg, f)}, flags);
      if (std::isnan(s[g])) {
        EXPECT_TRUE(flags & kFlagPeakMissing);
        left = true;
        break;
      }
      EXPECT_GT(s[g], last) << "grating " << g + 1 << " at " << f << " N";
      last = s[g];
      if (s[g] > band_pm) left = true;
    }
    EXPECT_TRUE(left) << "grating " << g + 1 << ": still in its band at 200 N (" << last << " pm)";
    // At 200 N on the grating its peak is gone (pinched) and so is every grating beyond it on the fibre.
    std::uint32_t flags = 0;
    const Shifts s = Shift(twin, {Sphere(c.y_mm, c.r_deg, 200.0)}, flags);
    EXPECT_TRUE(std::isnan(s[g])) << "grating " << g + 1;
    for (std::size_t j = g; j < kN; ++j) EXPECT_TRUE(std::isnan(s[j])) << "grating " << j + 1 << " beyond " << g + 1;
    EXPECT_TRUE(flags & kFlagSaturated);
    EXPECT_TRUE(flags & kFlagPeakMissing);
  }
}

// 20 N off the fibre's path: no pinch, every peak still there, and the nearest grating sees several times
// what the linear limit gave (the old twin saturated there: 20 N read as 4 N).
TEST(TwinExtremes, TwentyNewtonsOffTheFibreMoveTheGratingsBeyondTheLinearLimitResponse) {
  const SkinTwin& twin = PlainTwin();
  const double limit_n = twin.contact_law(Probe{})->linear_limit_force_n();
  const Contact hard = Sphere(140.0, 72.5, 20.0), at_limit = Sphere(140.0, 72.5, limit_n);
  std::uint32_t flags = 0;
  const Shifts s = Shift(twin, {hard}, flags), l = Shift(twin, {at_limit}, flags);
  EXPECT_TRUE(AllFinite(s));
  EXPECT_GT(std::abs(s[15]), 2.0 * std::abs(l[15]));  // FBG 16, the nearest (17.5 mm)
}

// A raw peak stream reports a peak where it is: a shift beyond the band is sent at its wavelength and
// flagged in the twin's frame flags; beyond the instrument's window it is lost (NaN, kFlagPeakMissing).
TEST(TwinExtremes, APeakBeyondItsBandIsReportedWhereItIsAndBeyondTheWindowIsLost) {
  const SkinTwin& twin = PlainTwin();
  const auto& ref = twin.reference_wavelength_nm();
  InterrogatorSim sim(twin, 6);
  for (double pm : {1500.0, -1500.0}) {
    Shifts s;
    s.fill(pm);
    std::array<double, kN> wl{};
    std::uint32_t flags = 0;
    sim.Read(0.0, s, wl, flags);
    EXPECT_TRUE(flags & kFlagSaturated) << pm;
    EXPECT_FALSE(flags & kFlagPeakMissing) << pm;
    for (std::size_t i = 0; i < kN; ++i) EXPECT_DOUBLE_EQ(wl[i], ref[i] + pm * 1e-3) << pm;
  }
  for (double pm : {1e5, -1e5, 1e300}) {
    Shifts s;
    s.fill(pm);
    std::array<double, kN> wl{};
    std::uint32_t flags = 0;
    sim.Read(0.0, s, wl, flags);
    EXPECT_TRUE(flags & kFlagPeakMissing) << pm;
    for (std::size_t i = 0; i < kN; ++i) EXPECT_TRUE(std::isnan(wl[i])) << pm;
  }
}

TEST(TwinExtremes, NormalForceIsNotFlagged) {
  const SkinTwin& twin = PlainTwin();
  InterrogatorSim sim(twin, 5);
  for (std::size_t g = 0; g < kN; ++g) {
    const auto& c = twin.spec().gratings[g].centre;
    std::uint32_t flags = 0;
    const Shifts s = Shift(twin, {Sphere(c.y_mm, c.r_deg, 2.5)}, flags);
    std::array<double, kN> wl{};
    sim.Read(0.0, s, wl, flags);
    EXPECT_EQ(flags, 0u) << "2.5 N on grating " << g + 1;
    EXPECT_NEAR((wl[g] - twin.reference_wavelength_nm()[g]) * 1e3, s[g], 1e-6);
  }
}

// ---------------------------------------------------------------------------------------------------
// 3. Patch edge and outside; bad contacts.

TEST(TwinExtremes, ContactOnTheExtentBoundaryCounts) {
  const SkinTwin& twin = PlainTwin();
  const double ye = twin.spec().extent_y_mm, re = twin.spec().extent_r_deg;
  for (const Contact& c : {Sphere(0, 72.5, 1.0), Sphere(ye, 72.5, 1.0), Sphere(24, 0, 1.0), Sphere(66, re, 1.0),
                           Sphere(0, 0, 1.0), Sphere(ye, re, 1.0)}) {
    std::uint32_t flags = 0;
    const Shifts s = Shift(twin, {c}, flags);
    EXPECT_TRUE(AllFinite(s)) << c.at.y_mm << ", " << c.at.r_deg;
    EXPECT_EQ(flags & kFlagOffPatch, 0u) << c.at.y_mm << ", " << c.at.r_deg;
    EXPECT_EQ(flags, 0u);
  }
  // Near a grating the edge contact really responds (Y = 24 row: R = 0 is 42.5 deg = 28 mm from FBG 1).
  std::uint32_t flags = 0;
  const Shifts near = Shift(twin, {Sphere(0, 42.5, 2.5)}, flags);
  EXPECT_GT(std::abs(near[0]), 0.0);
}

TEST(TwinExtremes, ContactOutsideThePatchContributesNothing) {
  const SkinTwin& twin = DefaultTwin();
  const Contact inside = Sphere(66, 72.5, 1.0);
  std::uint32_t flags = 0;
  const Shifts alone = Shift(twin, {inside}, flags);
  ASSERT_EQ(flags, 0u);
  for (const Contact& out : {Sphere(-1, 72.5, 1.0), Sphere(151, 72.5, 1.0), Sphere(66, 146, 1.0), Sphere(66, -5, 1.0),
                             Sphere(-1, 72.5, 10.0)}) {
    const Shifts s = Shift(twin, {out}, flags);
    EXPECT_TRUE(flags & kFlagOffPatch) << out.at.y_mm << ", " << out.at.r_deg;
    EXPECT_EQ(flags & kFlagBadContact, 0u);
    for (double v : s) EXPECT_EQ(v, 0.0);
    const Shifts both = Shift(twin, {inside, out}, flags);
    EXPECT_TRUE(flags & kFlagOffPatch);
    for (std::size_t i = 0; i < kN; ++i) EXPECT_EQ(both[i], alone[i]);
  }
}

TEST(TwinExtremes, BadContactsContributeNothingAndAreFlagged) {
  const SkinTwin& twin = DefaultTwin();
  const Contact inside = Sphere(66, 72.5, 1.0);
  std::uint32_t flags = 0;
  const Shifts alone = Shift(twin, {inside}, flags);
  ASSERT_EQ(flags, 0u);
  std::vector<Contact> bad = {Sphere(66, 72.5, kNaN), Sphere(66, 72.5, -0.5),
                              Sphere(66, 72.5, std::numeric_limits<double>::infinity()), Sphere(kNaN, 72.5, 1.0),
                              Contact{{66, 72.5}, 1.0, Probe{Probe::Shape::kSphere, 3.0}}};  // not built for 3 mm
  for (const Contact& b : bad) {
    const Shifts s = Shift(twin, {b}, flags);
    EXPECT_TRUE(flags & kFlagBadContact) << "force " << b.force_n << ", radius " << b.probe.radius_mm;
    for (double v : s) EXPECT_EQ(v, 0.0);
    const Shifts both = Shift(twin, {b, inside}, flags);
    EXPECT_TRUE(flags & kFlagBadContact);
    for (std::size_t i = 0; i < kN; ++i) EXPECT_EQ(both[i], alone[i]);
  }
  EXPECT_EQ(twin.contact_law(Probe{Probe::Shape::kSphere, 3.0}), nullptr);
  EXPECT_NE(twin.contact_law(Probe{Probe::Shape::kSphere, 5.5}), nullptr);
}

// ---------------------------------------------------------------------------------------------------
// 4. Superposition.

TEST(TwinExtremes, SimultaneousContactsSuperpose) {
  const SkinTwin& twin = DefaultTwin();
  const std::vector<std::pair<Contact, Contact>> pairs = {
      {Sphere(66, 72.5, 1.0), Sphere(84, 57.5, 2.0)},
      {Sphere(30, 50, 0.3), Sphere(31, 52, 2.5)},
      {Sphere(100, 72.5, 1.5), Sphere(100, 72.5, 1.5)},  // same point
      {Sphere(46.5, 87.5, 10.0), Sphere(46.5, 87.5, 0.05)},
  };
  for (const auto& [a, b] : pairs) {
    std::uint32_t flags = 0;
    const Shifts sa = Shift(twin, {a}, flags), sb = Shift(twin, {b}, flags), sab = Shift(twin, {a, b}, flags);
    EXPECT_TRUE(AllFinite(sab));
    double scale = 0.0;
    for (std::size_t i = 0; i < kN; ++i) scale = std::max(scale, std::abs(sa[i]) + std::abs(sb[i]));
    ASSERT_GT(scale, 1.0);  // the contacts do respond
    for (std::size_t i = 0; i < kN; ++i) EXPECT_NEAR(sab[i], sa[i] + sb[i], 1e-9 * scale) << "grating " << i + 1;
  }
}

// ---------------------------------------------------------------------------------------------------
// 5. Temperature.

TEST(TwinExtremes, TemperatureExtremesShiftEveryGratingAlike) {
  for (double dt : {40.0, -40.0}) {
    TwinEffects e;
    e.temperature = TemperatureEffect{};
    e.temperature->offset_c = dt;
    const SkinTwin twin = TwinWith(e);
    const double band_pm = twin.spec().fibre.band_half_width_nm * 1e3;
    InterrogatorSim sim(twin, 21);
    std::array<double, kN> first{};
    for (double t : {0.0, 0.01, 1.0, 150.0, 300.0, 1234.5, 1e5}) {
      std::array<double, kN> wl{};
      std::uint32_t flags = 0;
      sim.Read(t, Shifts{}, wl, flags);
      EXPECT_EQ(flags, 0u) << "dT " << dt << " t " << t;
      for (std::size_t i = 0; i < kN; ++i) {
        const double shift = (wl[i] - twin.reference_wavelength_nm()[i]) * 1e3;
        ASSERT_TRUE(std::isfinite(shift));
        EXPECT_NEAR(shift, twin.temperature_pm_per_c()[i] * dt, 1e-6);
        // about 10 pm/C * (1 +- 4 sigma of 3 %) * 40 C = 400 pm +- 48
        EXPECT_GE(std::abs(shift), 10.0 * (1 - 4 * 0.03) * 40.0) << "grating " << i + 1;
        EXPECT_LE(std::abs(shift), 10.0 * (1 + 4 * 0.03) * 40.0) << "grating " << i + 1;
        EXPECT_EQ(std::signbit(shift), std::signbit(dt));
        EXPECT_LT(std::abs(shift), band_pm);
        if (t == 0.0) {
          first[i] = wl[i];
        } else {
          EXPECT_EQ(wl[i], first[i]) << "no amplitude or ramp: constant";
        }
      }
    }
  }
}

TEST(TwinExtremes, TemperatureCoefficientsSpreadAroundTenPmPerDegree) {
  TwinEffects e;
  e.temperature = TemperatureEffect{};
  const SkinTwin twin = TwinWith(e);
  const auto& tc = twin.temperature_pm_per_c();
  const auto [lo, hi] = std::minmax_element(tc.begin(), tc.end());
  EXPECT_GT(*hi - *lo, 0.01) << "coefficients must differ between gratings";
  for (double c : tc) {
    EXPECT_GE(c, 10.0 * (1 - 4 * 0.03));
    EXPECT_LE(c, 10.0 * (1 + 4 * 0.03));
  }
  // A time-varying temperature moves the reading with time.
  e.temperature->amplitude_c = 5.0;
  e.temperature->period_s = 100.0;
  const SkinTwin varying = TwinWith(e);
  InterrogatorSim sim(varying, 1);
  EXPECT_EQ(sim.TemperatureC(0.0), 0.0);
  EXPECT_NEAR(sim.TemperatureC(25.0), 5.0, 1e-9);
}

// ---------------------------------------------------------------------------------------------------
// 6. Faults.

TEST(TwinExtremes, DeadGratingIsAlwaysMissing) {
  TwinEffects e;
  e.noise = NoiseEffect{0.3};
  e.faults.push_back(FaultEffect{5, FaultEffect::Kind::kDead, 0.0, 1.0});
  const SkinTwin twin = TwinWith(e);
  InterrogatorSim sim(twin, 31);
  const Shifts touch = PlainTwin().StrainShiftsPm(Sphere(46.5, 57.5, 1.0));  // on FBG 5
  for (int k = 0; k < 500; ++k) {
    std::array<double, kN> wl{};
    std::uint32_t flags = 0;
    sim.Read(k * 0.01, k % 2 ? touch : Shifts{}, wl, flags);
    EXPECT_TRUE(flags & kFlagPeakMissing);
    for (std::size_t i = 0; i < kN; ++i) {
      if (i == 4) {
        ASSERT_TRUE(std::isnan(wl[i])) << "frame " << k;
      } else {
        ASSERT_TRUE(std::isfinite(wl[i])) << "grating " << i + 1 << " frame " << k;
      }
    }
  }
}

TEST(TwinExtremes, DimmedGratingDropsOutAboutHalfTheTimeAndIsNoisier) {
  TwinEffects e;
  e.noise = NoiseEffect{0.3};
  e.faults.push_back(FaultEffect{9, FaultEffect::Kind::kDimmed, 0.5, 4.0});
  const SkinTwin twin = TwinWith(e);
  InterrogatorSim sim(twin, 32);
  const int frames = 2000;
  int missing = 0, flagged = 0;
  double s2_dim = 0.0, s2_ok = 0.0;
  int n_dim = 0, n_ok = 0;
  for (int k = 0; k < frames; ++k) {
    std::array<double, kN> wl{};
    std::uint32_t flags = 0;
    sim.Read(k * 0.01, Shifts{}, wl, flags);
    flagged += (flags & kFlagPeakMissing) ? 1 : 0;
    for (std::size_t i = 0; i < kN; ++i) {
      if (i == 8) continue;
      ASSERT_TRUE(std::isfinite(wl[i]));
    }
    if (std::isnan(wl[8])) {
      ++missing;
    } else {
      const double d = (wl[8] - twin.reference_wavelength_nm()[8]) * 1e3;
      s2_dim += d * d;
      ++n_dim;
    }
    const double h = (wl[3] - twin.reference_wavelength_nm()[3]) * 1e3;
    s2_ok += h * h;
    ++n_ok;
  }
  // Binomial(2000, 0.5): mean 1000, sd 22.4; +-5 sd.
  EXPECT_GE(missing, 888);
  EXPECT_LE(missing, 1112);
  EXPECT_EQ(flagged, missing);
  const double sd_dim = std::sqrt(s2_dim / n_dim), sd_ok = std::sqrt(s2_ok / n_ok);
  EXPECT_GT(sd_dim, 2.0 * sd_ok) << "dimmed " << sd_dim << " pm, healthy " << sd_ok << " pm";
  EXPECT_NEAR(sd_dim, 1.2, 0.15);
}

// ---------------------------------------------------------------------------------------------------
// 7. Skin samples.

TEST(TwinExtremes, SkinSamplesDifferBySeedAndRepeatBySeed) {
  const SkinTwin& a = SampleTwin(1);
  const SkinTwin& b = SampleTwin(2);
  const SkinTwin a2(Spec(), a.effects(), {5.5});  // same seed, built again
  const double pos = a.effects().skin_sample->position_mm;
  const Contact touch = Sphere(66, 72.5, 1.0);
  const Shifts sa = a.StrainShiftsPm(touch), sb = b.StrainShiftsPm(touch), sa2 = a2.StrainShiftsPm(touch);

  EXPECT_NE(a.layer_thickness_mm(), b.layer_thickness_mm());
  EXPECT_EQ(a.layer_thickness_mm(), a2.layer_thickness_mm());
  int centres_differ = 0, shifts_differ = 0;
  for (std::size_t i = 0; i < kN; ++i) {
    const auto& design = Spec().gratings[i].centre;
    for (const SkinTwin* t : {&a, &b}) {
      EXPECT_LE(t->geometry().SurfaceDistanceMm(t->grating_centres()[i], design), pos + 1e-9) << "grating " << i + 1;
    }
    const auto &ca = a.grating_centres()[i], &cb = b.grating_centres()[i], &ca2 = a2.grating_centres()[i];
    centres_differ += (ca.y_mm != cb.y_mm || ca.r_deg != cb.r_deg) ? 1 : 0;
    EXPECT_EQ(ca.y_mm, ca2.y_mm);
    EXPECT_EQ(ca.r_deg, ca2.r_deg);
    EXPECT_EQ(a.reference_wavelength_nm()[i], a2.reference_wavelength_nm()[i]);
    EXPECT_EQ(sa[i], sa2[i]);
    shifts_differ += sa[i] != sb[i] ? 1 : 0;
  }
  EXPECT_EQ(centres_differ, static_cast<int>(kN));
  EXPECT_GT(shifts_differ, 0);
  EXPECT_GT(std::abs(sa[6] - sb[6]), 0.01 * std::abs(sa[6])) << "FBG 7 under the touch";
  EXPECT_NE(a.reference_wavelength_nm(), b.reference_wavelength_nm());
}

TEST(TwinExtremes, WithoutASkinSampleTheDesignIsExact) {
  const SkinTwin& twin = PlainTwin();
  EXPECT_EQ(twin.layer_thickness_mm(), Spec().layer.thickness_mm);
  for (std::size_t i = 0; i < kN; ++i) {
    EXPECT_EQ(twin.grating_centres()[i].y_mm, Spec().gratings[i].centre.y_mm);
    EXPECT_EQ(twin.grating_centres()[i].r_deg, Spec().gratings[i].centre.r_deg);
    EXPECT_EQ(twin.reference_wavelength_nm()[i], Spec().gratings[i].wavelength_nm);
  }
}

// ---------------------------------------------------------------------------------------------------
// 8. Where the response peaks.

TEST(TwinExtremes, ContactOnAGratingRespondsMostOnThatGrating) {
  const SkinTwin& twin = PlainTwin();
  for (double f : {0.5, 2.5}) {
    for (std::size_t g = 0; g < kN; ++g) {
      const auto& c = twin.spec().gratings[g].centre;
      const Shifts s = twin.StrainShiftsPm(Sphere(c.y_mm, c.r_deg, f));
      const auto hot = static_cast<std::size_t>(std::max_element(s.begin(), s.end()) - s.begin());
      EXPECT_EQ(hot, g) << f << " N on grating " << g + 1;
      EXPECT_GT(s[g], 0.0);
      for (std::size_t j = 0; j < kN; ++j) {
        if (j != g) {
          EXPECT_GT(s[g], std::abs(s[j])) << f << " N on " << g + 1 << " vs " << j + 1;
        }
      }
    }
  }
}

TEST(TwinExtremes, ResponseGrowsWithForce) {
  for (const SkinTwin* twin : {&PlainTwin(), &DefaultTwin()}) {
    for (std::size_t g = 0; g < kN; ++g) {
      const auto& c = twin->grating_centres()[g];
      const double s05 = twin->StrainShiftsPm(Sphere(c.y_mm, c.r_deg, 0.5))[g];
      const double s1 = twin->StrainShiftsPm(Sphere(c.y_mm, c.r_deg, 1.0))[g];
      const double s2 = twin->StrainShiftsPm(Sphere(c.y_mm, c.r_deg, 2.0))[g];
      EXPECT_GT(s05, 0.0) << "grating " << g + 1;
      EXPECT_GT(s1, s05) << "grating " << g + 1;
      EXPECT_GT(s2, s1) << "grating " << g + 1;
    }
  }
}

// ---------------------------------------------------------------------------------------------------
// 9. Effects not named are not built.

TEST(TwinExtremes, UnnamedEffectsAreNotBuilt) {
  const TwinEffects none;
  EXPECT_EQ(none.Summary(), "none");
  EXPECT_EQ(none.fabrication_seed(), 0u);
  const SkinTwin& twin = PlainTwin();
  for (std::size_t i = 0; i < kN; ++i) {
    EXPECT_EQ(twin.gain()[i], 1.0);
    EXPECT_EQ(twin.temperature_pm_per_c()[i], 0.0);
  }
  InterrogatorSim sim(twin, 1);
  EXPECT_EQ(sim.TemperatureC(100.0), 0.0);
  // Named effects are built: the default scene's gain spread moves the gains.
  const SkinTwin& full = DefaultTwin();
  EXPECT_NE(full.effects().Summary(), "none");
  int not_one = 0;
  for (double g : full.gain()) not_one += g != 1.0 ? 1 : 0;
  EXPECT_EQ(not_one, static_cast<int>(kN));
}

// ---------------------------------------------------------------------------------------------------
// 10. Effects naming a grating that does not exist.

TEST(TwinExtremes, EffectsNamingAMissingGratingThrow) {
  for (int g : {0, 17, -1}) {
    TwinEffects fault;
    fault.faults.push_back(FaultEffect{g, FaultEffect::Kind::kDead, 0.0, 1.0});
    EXPECT_THROW((void)TwinWith(fault), InputError) << "fault on grating " << g;
    TwinEffects irregular;
    irregular.irregular = IrregularEffect{{IrregularGrating{g, {Lobe{}}}}};
    EXPECT_THROW((void)TwinWith(irregular), InputError) << "irregular grating " << g;
  }
  TwinEffects ok;
  ok.faults.push_back(FaultEffect{16, FaultEffect::Kind::kDead, 0.0, 1.0});
  ok.faults.push_back(FaultEffect{1, FaultEffect::Kind::kDimmed, 0.2, 4.0});
  EXPECT_NO_THROW((void)TwinWith(ok));
}

}  // namespace
}  // namespace ruffini::twin

namespace ruffini::twin {
namespace {

// Two or more probes at once on one patch (issue 16): each probe's field comes from its own force through
// its own contact law, and the fields add. In the linear range that is elasticity's superposition, exact;
// beyond it (hard presses) it is our approximation (two bottomed-out footprints would interact).
TEST(TwinMultiProbe, TwoProbesOnOnePatchSuperpose) {
  const SkinTwin& twin = fixtures::DefaultTwin();
  const Probe sphere{};
  for (double f : {0.5, 2.0, 20.0}) {
    const Contact a{{46.5, 57.5}, f, sphere}, b{{84.0, 87.5}, 0.7 * f, sphere};  // FBG 5 and FBG 9, 45 mm apart
    const Contact both[2] = {a, b};
    Shifts sa{}, sb{}, sab{};
    std::uint32_t flags = 0;
    twin.StrainShiftsPm(std::span<const Contact>(&a, 1), sa, flags);
    twin.StrainShiftsPm(std::span<const Contact>(&b, 1), sb, flags);
    twin.StrainShiftsPm(both, sab, flags);
    for (std::size_t i = 0; i < patch::kGratings; ++i) EXPECT_NEAR(sab[i], sa[i] + sb[i], 1e-9) << f << " N, grating " << i + 1;
    // Both presses are seen: each one's grating moves by more than it does under the other alone.
    EXPECT_GT(sab[4], sb[4] + 0.5 * sa[4]);
    EXPECT_GT(sab[8], sa[8] + 0.5 * sb[8]);
  }
  // A pinch by either probe darkens the fibre beyond it, whatever the other does.
  const Contact light{{46.5, 57.5}, 0.5, sphere}, hard{{84.0, 87.5}, 200.0, sphere};
  const Contact both[2] = {light, hard};
  Shifts s{};
  std::uint32_t flags = 0;
  twin.StrainShiftsPm(both, s, flags);
  EXPECT_TRUE(std::isfinite(s[4]));  // FBG 5 lies before the pinch on the fibre
  EXPECT_TRUE(std::isnan(s[8]));     // FBG 9 is under it
  EXPECT_TRUE(flags & kFlagPeakMissing);
}

}  // namespace
}  // namespace ruffini::twin

namespace ruffini::twin {
namespace {

TwinEffects WithEdges(TwinEffects e, EdgeEffect::Kind kind) {
  EdgeEffect ed;
  ed.kind.fill(kind);
  e.edges = ed;
  return e;
}

// Edges (docs/twin.md, "Edges"): the edge model leaves the interior alone, bit for bit. Every contact
// farther than zone_mm (12 mm) from every edge, the whole indented area included, gives the same shifts.
TEST(TwinEdges, TheInteriorIsUnchanged) {
  const SkinTwin& plain = fixtures::DefaultTwin();
  const SkinTwin free_edges(fixtures::Spec(), WithEdges(fixtures::DefaultScene().effects, EdgeEffect::Kind::kFree), {5.5});
  const patch::Geometry g(fixtures::Spec());
  const double zone_deg = g.RDeg(12.0);
  for (double y = 12.0; y <= 138.0; y += 3.0) {
    for (double r = zone_deg; r <= 145.0 - zone_deg; r += 3.0) {
      for (double f : {0.3, 2.5, 50.0}) {
        const Contact c{{y, r}, f, Probe{}};
        const Shifts a = plain.StrainShiftsPm(c), b = free_edges.StrainShiftsPm(c);
        for (std::size_t i = 0; i < patch::kGratings; ++i) {
          if (std::isnan(a[i])) {
            ASSERT_TRUE(std::isnan(b[i]));
          } else {
            ASSERT_EQ(a[i], b[i]) << y << " " << r << " " << f;
          }
        }
      }
    }
  }
}

// Near an edge the image changes what the nearest gratings see: a free edge (the material escapes through
// the traction-free face; Hetenyi's symmetric image) raises it, a bonded edge (a clamped face, the
// antisymmetric image) lowers it; continued is the old twin. The taper is continuous at zone_mm.
TEST(TwinEdges, AFreeEdgeRaisesABondedEdgeLowersTheNearestGratingsResponse) {
  const auto& scene = fixtures::DefaultScene();
  const SkinTwin plain(fixtures::Spec(), scene.effects, {5.5});
  const SkinTwin free_edges(fixtures::Spec(), WithEdges(scene.effects, EdgeEffect::Kind::kFree), {5.5});
  const SkinTwin bonded(fixtures::Spec(), WithEdges(scene.effects, EdgeEffect::Kind::kBonded), {5.5});
  // FBG 1 (Y 24, R 42.5) and a press 4 mm inside the Y = 0 edge, 20 mm away along Y.
  const Contact c{{4.0, 42.5}, 2.0, Probe{}};
  const double p = plain.StrainShiftsPm(c)[0], fr = free_edges.StrainShiftsPm(c)[0], bo = bonded.StrainShiftsPm(c)[0];
  EXPECT_NE(p, 0.0);
  EXPECT_GT(std::abs(fr), std::abs(p));
  EXPECT_LT(std::abs(bo), std::abs(p));
  // Continuous at the zone's border: 11.99 and 12.01 mm from the edge differ by what 0.02 mm of travel does.
  const Contact in{{11.99, 42.5}, 2.0, Probe{}}, out{{12.01, 42.5}, 2.0, Probe{}};
  EXPECT_NEAR(free_edges.StrainShiftsPm(in)[0], free_edges.StrainShiftsPm(out)[0], 0.05);
}

// At a free edge the part of the footprint still on the cover bears the whole force: a hard press there
// bottoms out sooner. 30 N 0.5 mm inside the elbow edge, on the fibre's entry (R 18), pinches the fibre
// (every peak lost) with the cover ending there; with the layer continued it does not yet.
TEST(TwinEdges, AHardPressOnAFreeEdgeBottomsOutSooner) {
  const SkinTwin plain(fixtures::Spec(), TwinEffects{}, {5.5});
  const SkinTwin free_edges(fixtures::Spec(), WithEdges(TwinEffects{}, EdgeEffect::Kind::kFree), {5.5});
  const Contact c{{0.5, 18.0}, 30.0, Probe{}};
  const Shifts a = plain.StrainShiftsPm(c), b = free_edges.StrainShiftsPm(c);
  EXPECT_TRUE(std::isfinite(a[0]));
  for (std::size_t i = 0; i < patch::kGratings; ++i) EXPECT_TRUE(std::isnan(b[i])) << i + 1;
}

}  // namespace
}  // namespace ruffini::twin
