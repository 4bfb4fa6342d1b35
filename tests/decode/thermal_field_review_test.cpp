// Review 5: probes of the thermal-field follower (BaselineConfig::thermal_field, commit 019af08). Can it carry
// off a real held press, so that a STOP becomes CLEAR? A failing probe is a finding; a passing one documents a
// property. Own binary: it counts allocations with a replaced global operator new (tests/common/alloc_counter.h).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <numbers>

#include "../common/alloc_counter.h"
#include "ruffini/decode/baseline.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/patch/spec_loader.h"

namespace ruffini::decode {
namespace {

using Gate = BaselineTracker::Gate;

const patch::PatchSpec& Spec() {
  static const patch::PatchSpec s = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  return s;
}

BaselineConfig FieldConfig(double rate_hz = 100.0) {
  BaselineConfig c;
  c.thermal_field = true;
  c.sample_rate_hz = rate_hz;
  c.capture_frames = static_cast<int>(std::lround(c.capture_frames * rate_hz / 100.0));
  c.release_frames = static_cast<int>(std::lround(c.release_frames * rate_hz / 100.0));
  const double mm_per_deg = Spec().surface_radius_mm * std::numbers::pi / 180.0;
  for (std::size_t i = 0; i < 16; ++i) {
    c.grating_y_mm[i] = static_cast<float>(Spec().gratings[i].centre.y_mm);
    c.grating_arc_mm[i] = static_cast<float>(Spec().gratings[i].centre.r_deg * mm_per_deg);
  }
  return c;
}

Wavelengths Nominal() {
  Wavelengths wl;
  for (std::size_t i = 0; i < 16; ++i) wl[i] = 1530.0 + 2.3 * static_cast<double>(i);
  return wl;
}

// Captures on the nominal wavelengths, then holds `press` (pm per grating, no temperature change at all) for
// hold_s with the given gate and place; returns the last frame's shifts.
ShiftsPm Hold(BaselineTracker& t, const BaselineConfig& c, const std::array<float, 16>& press, double hold_s, Gate gate,
              float place_y, float place_arc) {
  const Wavelengths nominal = Nominal();
  ShiftsPm s;
  for (int k = 0; k < c.capture_frames; ++k) t.Update(nominal, s);
  Wavelengths wl = nominal;
  for (std::size_t i = 0; i < 16; ++i) wl[i] += press[i] * 1e-3;
  const auto frames = static_cast<long>(std::lround(hold_s * c.sample_rate_hz));
  for (long k = 0; k < frames; ++k) {
    t.Measure(wl, s);
    t.Advance(wl, s, gate, place_y, place_arc);
  }
  t.Measure(wl, s);
  return s;
}

// Each pressed grating keeps at least `keep` of its shift.
void ExpectKept(const std::array<float, 16>& press, const ShiftsPm& s, double keep, const char* what) {
  for (std::size_t i = 0; i < 16; ++i) {
    if (press[i] == 0) continue;
    EXPECT_GE(s[i] / press[i], keep) << what << ": FBG " << i + 1 << " pressed " << press[i] << " pm reads " << s[i];
  }
}

// FBG places (forearm.yaml): FBG 1-3 at y 24 mm, 4-5 at 46.5, 6-8 at 66, ..., 16 at 122.5 (the far end).
constexpr std::size_t kFar = 15;  // FBG 16

// ---------------------------------------------------------------------------------------------------
// Wrong (phantom) places.

TEST(ThermalFieldReview, EveryShippedModelHasTheFollowerOff) {
  // Until the disabled probes below pass, no shipped model may switch the follower on.
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(RUFFINI_SOURCE_DIR "/config/models")) {
    if (e.path().extension() != ".rmodel") continue;
    ++n;
    EXPECT_FALSE(LoadModel(e.path().string()).preprocessing().thermal_field()) << e.path();
  }
  EXPECT_GE(n, 5);
}

TEST(ThermalFieldReview, APlacedLightPressBetweenGratingsIsKept) {
  // Control for the next probe: a long light press between FBG 1 and 2 (no grating reaches touch_off_pm), the
  // gate open, placed where it is. The gratings within field_exclude_mm stay frozen: the press is kept.
  const std::array<float, 16> press = {1.2f, 1.0f, 0, 0, 0.8f, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  const BaselineConfig c = FieldConfig();
  BaselineTracker t(c);
  const float y = 0.5f * (c.grating_y_mm[0] + c.grating_y_mm[1]), arc = 0.5f * (c.grating_arc_mm[0] + c.grating_arc_mm[1]);
  ExpectKept(press, Hold(t, c, press, 120.0, Gate::kOpen, y, arc), 0.9, "placed light press");
}

// Open finding of review 5 (fails today): the follower stays off in every shipped model until it passes.
TEST(ThermalFieldReview, DISABLED_APhantomPlaceEatsALightPressTheGateSees) {
  // The same light press, the gate open (the decoder sees it), but the networks place it at the far end of
  // the patch (FBG 16, ~100 mm away). baseline.h promises the gate-driven freeze never eats a press the gate
  // sees, "a long light press between gratings that moves no grating by touch_on_pm included". With the field
  // on, every grating below touch_off_pm and beyond field_exclude_mm of the place follows its own shift with
  // field_far_tau_s (10 s): the press is gone in well under max_frozen_s, and the gate closes on a held press.
  const std::array<float, 16> press = {1.2f, 1.0f, 0, 0, 0.8f, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  const BaselineConfig c = FieldConfig();
  BaselineTracker t(c);
  const ShiftsPm s = Hold(t, c, press, 30.0, Gate::kOpen, c.grating_y_mm[kFar], c.grating_arc_mm[kFar]);
  ExpectKept(press, s, 0.9, "phantom-placed light press");
  // Without the field the frozen baseline keeps it whatever the place.
  BaselineConfig off = c;
  off.thermal_field = false;
  BaselineTracker u(off);
  ExpectKept(press, Hold(u, off, press, 120.0, Gate::kOpen, c.grating_y_mm[kFar], c.grating_arc_mm[kFar]), 0.99,
             "field off");
}

// Open finding of review 5 (fails today): the follower stays off in every shipped model until it passes.
TEST(ThermalFieldReview, DISABLED_APhantomPlaceAndAPressHaloCarryThePressAlongThePlane) {
  // A firm press on FBG 1 (20 pm) whose neighbours move a little (below touch_off_pm: they count as "far" and
  // quiet), placed at the far end. The neighbours' baselines follow their shifts, the plane through what
  // the far baselines moved tilts toward the press, and FBG 1 (near: moving) is carried along that plane.
  // Held for max_frozen_s (the longest a freeze is trusted).
  const std::array<float, 16> press = {20.0f, 1.4f, 0, 1.4f, 1.4f, 1.4f, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  const BaselineConfig c = FieldConfig();
  BaselineTracker t(c);
  const ShiftsPm s = Hold(t, c, press, c.max_frozen_s, Gate::kOpen, c.grating_y_mm[kFar], c.grating_arc_mm[kFar]);
  EXPECT_GE(s[0] / press[0], 0.9) << "FBG 1 reads " << s[0] << " of " << press[0] << " pm";
}

// Open finding of review 5 (fails today): the follower stays off in every shipped model until it passes.
TEST(ThermalFieldReview, DISABLED_ASecondLightTouchIsEatenWhileTheFirstIsPlacedAndLostWhenTheFirstLifts) {
  // Two touches: A firm on FBG 2 (placed there), B light on FBG 15 (~90 mm away, every grating below
  // touch_off_pm; the gate sees such a press alone, baseline.h). While A is held, B's gratings are "far and
  // quiet" and follow their own shift with field_far_tau_s: B is eaten. A lifts, B is still held: the shifts
  // no longer show B, so the gate that A held open closes on a held touch (STOP -> CLEAR). Field off: B stays.
  std::array<float, 16> both{};
  both[1] = 20.0f;   // A: FBG 2
  both[0] = 4.0f;
  both[14] = 1.3f;   // B: FBG 15 and its neighbours 14, 16
  both[13] = 0.9f;
  both[15] = 0.9f;
  for (const bool on : {true, false}) {
    BaselineConfig c = FieldConfig();
    c.thermal_field = on;
    BaselineTracker t(c);
    Hold(t, c, both, 60.0, Gate::kOpen, c.grating_y_mm[1], c.grating_arc_mm[1]);
    // A lifts: B alone; the gate still open on B, placed at B now, for 1 s.
    Wavelengths wl = Nominal();
    for (std::size_t i : {13u, 14u, 15u}) wl[i] += both[i] * 1e-3;
    ShiftsPm s;
    for (int k = 0; k < 100; ++k) {
      t.Measure(wl, s);
      t.Advance(wl, s, Gate::kOpen, c.grating_y_mm[14], c.grating_arc_mm[14]);
    }
    t.Measure(wl, s);
    std::array<float, 16> b{};
    for (std::size_t i : {13u, 14u, 15u}) b[i] = both[i];
    ExpectKept(b, s, 0.9, on ? "second touch, field on" : "second touch, field off");
  }
}

// ---------------------------------------------------------------------------------------------------
// Touched, not placed: the robust plane runs through the press itself (trim 4).

// Open finding of review 5 (fails today): the follower stays off in every shipped model until it passes.
TEST(ThermalFieldReview, DISABLED_ABroadUnplacedPressOnFiveOrMoreGratingsIsCarriedOff) {
  // A broad press at the near end moving 6 gratings by 8 pm (FBG 1-6), the gate open but no place (the
  // nets' Fuse had nothing, or the shift-driven freeze that has no decoder place at all). Trim leaves out
  // 4; the other 2 tilt the plane, and the baseline under the press climbs at up to field_max_rate_pm_s
  // (field_tau_s 1 s) - 8 pm in about 8 s, far inside max_frozen_s.
  const std::array<float, 16> press = {8.0f, 8.0f, 8.0f, 8.0f, 8.0f, 8.0f, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  for (const Gate gate : {Gate::kOpen, Gate::kNone}) {
    const BaselineConfig c = FieldConfig();
    BaselineTracker t(c);
    const ShiftsPm s = Hold(t, c, press, 20.0, gate, BaselineTracker::kNoPlace, BaselineTracker::kNoPlace);
    ExpectKept(press, s, 0.8, gate == Gate::kOpen ? "gate open, unplaced" : "shift-driven freeze, unplaced");
    EXPECT_EQ(t.state(), BaselineTracker::State::kFrozen) << "the freeze let go of a held press";
  }
}

// Open finding of review 5 (fails today): the follower stays off in every shipped model until it passes.
TEST(ThermalFieldReview, DISABLED_AnUnplacedPressOnFourGratingsIsKeptByTheTrim) {
  // The header and the doc say the trim leaves out "a touch the gate has not seen" of up to field_trim (4)
  // gratings: FBG 1, 2, 3, 5 at 8 pm, unplaced, 20 s.
  const std::array<float, 16> press = {8.0f, 8.0f, 8.0f, 0, 8.0f, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  const BaselineConfig c = FieldConfig();
  BaselineTracker t(c);
  ExpectKept(press, Hold(t, c, press, 20.0, Gate::kOpen, BaselineTracker::kNoPlace, BaselineTracker::kNoPlace), 0.9,
             "4 gratings, unplaced");
}

// Open finding of review 5 (fails today): the follower stays off in every shipped model until it passes.
TEST(ThermalFieldReview, DISABLED_TheTrimDoesNotKeepAnUnplacedPressOnOneRowOfThreeGratings) {
  // The trim is one shot: the 4 largest residuals from a first fit that the press itself has tilted. A press on
  // the 3 gratings of the end row (FBG 1-3, y 24 mm) is not all trimmed; what stays in tilts the plane, the
  // baseline under the press climbs, and as the press shrinks the trim lets more of it in. 1 and 2: kept.
  for (std::size_t n = 1; n <= 3; ++n) {
    std::array<float, 16> press{};
    for (std::size_t i = 0; i < n; ++i) press[i] = 8.0f;  // FBG 1..n (y 24 mm, one end)
    const BaselineConfig c = FieldConfig();
    BaselineTracker t(c);
    const ShiftsPm s = Hold(t, c, press, 20.0, Gate::kOpen, BaselineTracker::kNoPlace, BaselineTracker::kNoPlace);
    ExpectKept(press, s, 0.9, n == 1 ? "1 grating" : (n == 2 ? "2 gratings" : "3 gratings"));
  }
}

// Open finding of review 5 (fails today): the follower stays off in every shipped model until it passes.
TEST(ThermalFieldReview, DISABLED_APressBuildingSlowlyBeforeTheGateOpensIsFollowedAsAField) {
  // Pipeline-reachable without any wrong place: the gate is closed (tracking) while a broad contact builds at
  // 0.4 pm/s for 60 s on FBG 1-6 (to 24 pm). Without the field the 30 s filter lags it by about
  // rate x tau (1 - exp(-t/tau)), over 10 pm: the decoder sees it and opens the gate. With the field the plane
  // (tau 1 s, up to 1 pm/s) follows the ramp's tilt, and most of the contact never reaches the shifts.
  const std::array<float, 16> shape = {1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  float seen[2] = {0, 0};
  for (const bool on : {false, true}) {
    BaselineConfig c = FieldConfig();
    c.thermal_field = on;
    BaselineTracker t(c);
    const Wavelengths nominal = Nominal();
    ShiftsPm s;
    for (int k = 0; k < c.capture_frames; ++k) t.Update(nominal, s);
    const int frames = static_cast<int>(60.0 * c.sample_rate_hz);
    for (int k = 0; k <= frames; ++k) {
      Wavelengths wl = nominal;
      for (std::size_t i = 0; i < 16; ++i) wl[i] += shape[i] * 0.4 * (k / c.sample_rate_hz) * 1e-3;
      t.Measure(wl, s);
      if (k < frames) t.Advance(wl, s, Gate::kClosed);
    }
    for (std::size_t i = 0; i < 6; ++i) seen[on ? 1 : 0] = std::max(seen[on ? 1 : 0], s[i]);
  }
  EXPECT_GT(seen[0], 8.0f) << "field off: the contact shows";
  EXPECT_GE(seen[1], 0.8f * seen[0]) << "field on: largest shift under the contact " << seen[1] << " pm, field off "
                                     << seen[0] << " pm";
}

TEST(ThermalFieldReview, TheStepBoundIsPerSecondAtEveryRate) {
  // Property: the broad unplaced press loses about the same in 10 s at 100 Hz and at 5 kHz (the per-frame
  // step is field_max_rate_pm_s / rate), and never more than field_max_rate_pm_s x 10 s.
  const std::array<float, 16> press = {8.0f, 8.0f, 8.0f, 8.0f, 8.0f, 8.0f, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  float lost[2] = {0, 0};
  int k = 0;
  for (const double rate : {100.0, 5000.0}) {
    const BaselineConfig c = FieldConfig(rate);
    BaselineTracker t(c);
    const ShiftsPm s = Hold(t, c, press, 10.0, Gate::kOpen, BaselineTracker::kNoPlace, BaselineTracker::kNoPlace);
    for (std::size_t i = 0; i < 6; ++i) {
      lost[k] = std::max(lost[k], press[i] - s[i]);
      // Each baseline steps at most field_max_rate_pm_s; the shift also carries what the common mode takes
      // (the median moves with the others' baselines, which step at most as fast) : 2x the bound.
      EXPECT_LE(press[i] - s[i], 2.0 * c.field_max_rate_pm_s * 10.0 + 0.05) << "rate " << rate;
    }
    ++k;
  }
  EXPECT_NEAR(lost[0], lost[1], 0.1 * std::max(lost[0], lost[1]) + 0.05);
}

// ---------------------------------------------------------------------------------------------------
// Missing peaks, bad places, numerical extremes.

TEST(ThermalFieldReview, MissingPeaksMidHoldDoNotEatAPlacedPress) {
  // A placed press on FBG 6-8 (y 66); mid-hold FBG 7's peak and two far gratings' peaks vanish for 30 s, then
  // come back. Property: the press is kept, nothing turns NaN.
  const std::array<float, 16> press = {0, 0, 0, 0, 0, -15.0f, 20.0f, -6.0f, 0, 0, 0, 0, 0, 0, 0, 0};
  const BaselineConfig c = FieldConfig();
  BaselineTracker t(c);
  const Wavelengths nominal = Nominal();
  ShiftsPm s;
  for (int k = 0; k < c.capture_frames; ++k) t.Update(nominal, s);
  Wavelengths wl = nominal;
  for (std::size_t i = 0; i < 16; ++i) wl[i] += press[i] * 1e-3;
  const float y = c.grating_y_mm[6], arc = c.grating_arc_mm[6];
  for (int k = 0; k < 12000; ++k) {
    Wavelengths w = wl;
    if (k >= 3000 && k < 6000) {
      w[6] = w[0] = w[15] = std::numeric_limits<double>::quiet_NaN();
    }
    t.Measure(w, s);
    t.Advance(w, s, Gate::kOpen, y, arc);
  }
  t.Measure(wl, s);
  for (std::size_t i = 0; i < 16; ++i) ASSERT_TRUE(std::isfinite(t.baseline_nm()[i])) << i;
  ExpectKept(press, s, 0.95, "placed press, peaks missing mid-hold");
}

TEST(ThermalFieldReview, NonFiniteOrHugePlacesAndHugeShiftsStayFiniteAndBounded) {
  // Places NaN/inf/huge (finite), shifts of a few nm: baselines stay finite and each field step stays within
  // field_max_rate_pm_s / rate (beyond the common-mode follower, which moves every grating alike).
  const float inf = std::numeric_limits<float>::infinity(), big = std::numeric_limits<float>::max();
  const std::array<std::pair<float, float>, 6> places = {{{BaselineTracker::kNoPlace, 10.0f}, {inf, 10.0f}, {-inf, -inf},
                                                         {big, -big}, {1e30f, 0.0f}, {0.0f, 0.0f}}};
  for (const auto& [py, pa] : places) {
    const BaselineConfig c = FieldConfig();
    BaselineTracker t(c);
    const Wavelengths nominal = Nominal();
    ShiftsPm s;
    for (int k = 0; k < c.capture_frames; ++k) t.Update(nominal, s);
    Wavelengths wl = nominal;
    for (std::size_t i = 0; i < 16; ++i) wl[i] += (i % 2 == 0 ? 3.0 : -2.0) * (1.0 + static_cast<double>(i));  // nm
    for (int k = 0; k < 200; ++k) {
      const Wavelengths before = t.baseline_nm();
      t.Measure(wl, s);
      t.Advance(wl, s, Gate::kOpen, py, pa);
      const double cm0 = (t.baseline_nm()[0] - before[0]) * 1e3 / c.thermal_ratio[0];
      for (std::size_t i = 0; i < 16; ++i) {
        ASSERT_TRUE(std::isfinite(t.baseline_nm()[i])) << "place " << py << "," << pa;
        const double field_step = (t.baseline_nm()[i] - before[i]) * 1e3 - cm0 * c.thermal_ratio[i];
        EXPECT_LE(std::abs(field_step), 2.0 * c.field_max_rate_pm_s / c.sample_rate_hz + 1e-6) << "place " << py;
      }
    }
    EXPECT_TRUE(std::isfinite(t.field_slope_y()) && std::isfinite(t.field_slope_arc()));
  }
}

TEST(ThermalFieldReview, RetareSeedClearsTheFieldState) {
  // Property: Seed() mid-freeze forgets what the far baselines moved (moved_pm_), so the plane after a re-tare
  // starts from nothing: a placed press right after Seed is kept.
  const std::array<float, 16> press = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 25.0f, 4.0f, 0, 0, 0, 0};
  const BaselineConfig c = FieldConfig();
  BaselineTracker t(c);
  ShiftsPm s = Hold(t, c, press, 60.0, Gate::kOpen, c.grating_y_mm[10], c.grating_arc_mm[10]);
  t.Seed(t.baseline_nm());
  Wavelengths wl = Nominal();
  for (std::size_t i = 0; i < 16; ++i) wl[i] += press[i] * 1e-3;
  for (int k = 0; k < 6000; ++k) {
    t.Measure(wl, s);
    t.Advance(wl, s, Gate::kOpen, c.grating_y_mm[10], c.grating_arc_mm[10]);
  }
  t.Measure(wl, s);
  ExpectKept(press, s, 0.95, "after Seed");
}

// ---------------------------------------------------------------------------------------------------
// Real time.

TEST(ThermalFieldReview, AdvanceAllocatesNothingOnEveryFieldPath) {
  const BaselineConfig c = FieldConfig();
  BaselineTracker t(c);
  const Wavelengths nominal = Nominal();
  ShiftsPm s;
  for (int k = 0; k < c.capture_frames; ++k) t.Update(nominal, s);
  Wavelengths wl = nominal;
  wl[3] += 10e-3;
  wl[9] += 1e-3;
  const long n = ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 200; ++k) {
      t.Measure(wl, s);
      t.Advance(wl, s, Gate::kClosed);  // tracking: the robust plane
      t.Measure(wl, s);
      t.Advance(wl, s, Gate::kOpen, c.grating_y_mm[3], c.grating_arc_mm[3]);  // placed
      t.Measure(wl, s);
      t.Advance(wl, s, Gate::kOpen);  // frozen, unplaced
    }
  });
  EXPECT_EQ(n, 0);
}

}  // namespace
}  // namespace ruffini::decode
