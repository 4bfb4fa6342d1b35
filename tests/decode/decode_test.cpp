#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>

#include "ruffini/decode/baseline.h"
#include "ruffini/decode/grids.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/error.h"
#include "ruffini/patch/geometry.h"
#include "ruffini/patch/spec_loader.h"
#include "ruffini/stats.h"
#include "../common/golden.h"
#include "synthetic_model.h"

namespace ruffini::decode {
namespace {

const patch::PatchSpec& Spec() {
  static const patch::PatchSpec s = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  return s;
}
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

ShiftsPm Shifts(float v) {
  ShiftsPm s;
  s.fill(v);
  return s;
}

// ---------------------------------------------------------------------------------------------------
// Grids and NIP.

TEST(GridsTest, PaperGridSizes) {
  const auto g = PaperGrids(Spec().indented_area);
  EXPECT_EQ(g[0].classes(), 30);
  EXPECT_EQ(g[1].classes(), 35);
  EXPECT_EQ(g[2].classes(), 36);
  EXPECT_EQ(g[3].classes(), 42);
  EXPECT_DOUBLE_EQ(g[0].cell_y_mm, 20.0);
  EXPECT_DOUBLE_EQ(g[0].cell_r_deg, 18.0);
  // Every point of the indented area falls in exactly one cell of every grid.
  for (double y = 15.01; y < 135; y += 3.7) {
    for (double r = 27.51; r < 117.5; r += 2.9) {
      for (const auto& gr : g) EXPECT_GE(gr.ClassOf(y, r), 0) << gr.name << " " << y << " " << r;
    }
  }
  EXPECT_EQ(g[0].ClassOf(14.0, 50.0), -1);
}

// The whole-surface grids (train --area whole): the paper's four grids over the patch's extent, cells of
// about the paper's size; every point of the patch, edges included, has a cell in every grid, and soft
// answers at an edge point are fused to a point near it (nothing pulls them into the indented area).
TEST(GridsTest, WholeSurfaceGridsSpanThePatchEdgeToEdge) {
  const patch::PatchSpec& spec = Spec();
  const auto g = WholeSurfaceGrids(spec);
  const auto paper = PaperGrids(spec.indented_area);
  ASSERT_EQ(g[0].name, "SG");
  ASSERT_EQ(g[3].name, "DSG");
  EXPECT_EQ(g[0].ny, static_cast<int>(std::lround(spec.extent_y_mm / paper[0].cell_y_mm)));
  EXPECT_EQ(g[0].nr, static_cast<int>(std::lround(spec.extent_r_deg / paper[0].cell_r_deg)));
  for (const auto& gr : g) {
    EXPECT_NEAR(gr.cell_y_mm / paper[0].cell_y_mm, 1.0, 0.25) << gr.name;
    EXPECT_NEAR(gr.cell_r_deg / paper[0].cell_r_deg, 1.0, 0.25) << gr.name;
  }
  EXPECT_DOUBLE_EQ(g[0].y0_mm, 0.0);
  EXPECT_DOUBLE_EQ(g[0].r0_deg, 0.0);
  EXPECT_NEAR(g[0].y0_mm + g[0].ny * g[0].cell_y_mm, spec.extent_y_mm, 1e-9);
  EXPECT_NEAR(g[0].r0_deg + g[0].nr * g[0].cell_r_deg, spec.extent_r_deg, 1e-9);
  EXPECT_EQ(g[1].classes(), (g[0].ny + 1) * g[0].nr);
  EXPECT_EQ(g[3].classes(), (g[0].ny + 1) * (g[0].nr + 1));
  for (double y = 0.0; y < spec.extent_y_mm; y += 3.7) {
    for (double r = 0.0; r < spec.extent_r_deg; r += 2.9) {
      for (const auto& gr : g) EXPECT_GE(gr.ClassOf(y, r), 0) << gr.name << " " << y << " " << r;
    }
  }
  EXPECT_EQ(paper[0].ClassOf(2.0, 2.0), -1) << "the paper's grids do not reach the corner";
  const Nip nip(g);
  ASSERT_LE(nip.fine_cells(), Nip::kMaxFineCells);
  const patch::Geometry geo(spec.surface_radius_mm);
  std::vector<float> p(nip.inputs());
  for (const patch::SurfacePoint at : {patch::SurfacePoint{2.0, 2.0}, patch::SurfacePoint{148.0, 72.5},
                                       patch::SurfacePoint{75.0, 143.0}, patch::SurfacePoint{3.0, 100.0}}) {
    std::size_t off = 0;
    for (const auto& gr : g) {
      gr.SoftLabels(at.y_mm, at.r_deg, 3.0, spec.surface_radius_mm, std::span<float>(p.data() + off, static_cast<std::size_t>(gr.classes())));
      off += static_cast<std::size_t>(gr.classes());
    }
    double y = 0, r = 0;
    nip.Locate(p, y, r);
    EXPECT_LT(geo.SurfaceDistanceMm({y, r}, at), 5.0) << at.y_mm << ", " << at.r_deg << " -> " << y << ", " << r;
  }
  EXPECT_THROW(PaperGrids(spec.indented_area, 0, 5), std::invalid_argument);
}

TEST(GridsTest, NipPutsAOneHotContactAtTheSharedFineCell) {
  const auto g = PaperGrids(Spec().indented_area);
  const Nip nip(g);
  EXPECT_EQ(nip.inputs(), 30u + 35u + 36u + 42u);
  EXPECT_EQ(nip.fine_cells(), 14u * 12u);
  // Each net certain of the cell containing (y, r): the fused estimate is the centre of the fine cell
  // (10 mm x 9 deg) that holds the point.
  const double y = 61.0, r = 70.0;
  std::vector<float> p(nip.inputs(), 0.0f);
  std::size_t off = 0;
  for (const auto& gr : g) {
    p[off + static_cast<std::size_t>(gr.ClassOf(y, r))] = 1.0f;
    off += static_cast<std::size_t>(gr.classes());
  }
  double ey = 0, er = 0;
  const double conf = nip.Locate(p, ey, er);
  EXPECT_NEAR(ey, 60.0, 1e-9);   // fine cell 55..65 mm
  EXPECT_NEAR(er, 68.0, 1e-9);   // fine cell 63.5..72.5 deg
  EXPECT_NEAR(conf, 1.0, 1e-9);
  // The fused weight also covers the neighbouring fine cells of each one-hot cell: a spread of a few mm,
  // far below that of uninformative (uniform) probabilities.
  const double sharp = nip.Fuse(p, 37.4).spread_mm;
  std::vector<float> flat(nip.inputs(), 0.03f);
  EXPECT_GT(sharp, 1.0);
  EXPECT_LT(sharp, 0.5 * nip.Fuse(flat, 37.4).spread_mm);
  // All zero: no estimate, confidence 0, inputs untouched.
  std::fill(p.begin(), p.end(), 0.0f);
  ey = -1;
  EXPECT_EQ(nip.Locate(p, ey, er), 0.0);
  EXPECT_EQ(ey, -1);
}

TEST(GridsTest, SoftLabelsAreTheGaussiansShareOfEachCell) {
  const auto g = PaperGrids(Spec().indented_area)[0];
  std::vector<float> p(static_cast<std::size_t>(g.classes()));
  // Centre of a cell, sigma far below the cell: (almost) one-hot.
  const auto c = g.Centre(7);
  g.SoftLabels(c.y_mm, c.r_deg, 0.5, 37.4, p);
  EXPECT_NEAR(p[7], 1.0f, 1e-6);
  // On the Y border between two cells (and central in R): half each.
  g.SoftLabels(g.y0_mm + g.cell_y_mm, c.r_deg, 3.0, 37.4, p);
  const int a = g.ClassOf(g.y0_mm + 0.5 * g.cell_y_mm, c.r_deg), b = g.ClassOf(g.y0_mm + 1.5 * g.cell_y_mm, c.r_deg);
  EXPECT_NEAR(p[static_cast<std::size_t>(a)], p[static_cast<std::size_t>(b)], 1e-6);
  EXPECT_GT(p[static_cast<std::size_t>(a)], 0.45f);
  double total = 0;
  for (float v : p) total += v;
  EXPECT_NEAR(total, 1.0, 1e-5);
  // Far off the grid: one-hot on the nearest cell, never NaN.
  g.SoftLabels(-500.0, 0.0, 1.0, 37.4, p);
  EXPECT_EQ(std::count(p.begin(), p.end(), 1.0f), 1);
}

// Why soft labels (docs/experiments/knobs.md): with perfect one-cell answers the NIP barycentre lands on a
// fine-cell centre, a median error of about 3.1 mm for uniform contacts; with probabilities that are each
// cell's share of a 4 mm Gaussian it interpolates to a fraction of a millimetre.
TEST(GridsTest, NipFloorWithPerfectOneHotAndSoftAnswers) {
  const auto grids = PaperGrids(Spec().indented_area);
  const Nip nip(grids);
  const patch::Geometry geo(Spec().surface_radius_mm);
  const auto& a = Spec().indented_area;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uy(a.y_min_mm, a.y_max_mm), ur(a.r_min_deg, a.r_max_deg);
  const std::array<double, 6> sigmas = {0.0, 3.0, 4.0, 5.0, 6.0, 8.0};  // 0: one-hot
  std::array<std::vector<double>, sigmas.size()> err;
  std::vector<float> p(nip.inputs());
  for (int n = 0; n < 5000; ++n) {
    const double y = uy(rng), r = ur(rng);
    for (std::size_t mode = 0; mode < sigmas.size(); ++mode) {
      std::fill(p.begin(), p.end(), 0.0f);
      std::size_t off = 0;
      for (const auto& g : grids) {
        const std::span<float> mine(p.data() + off, static_cast<std::size_t>(g.classes()));
        if (mode == 0) {
          mine[static_cast<std::size_t>(g.ClassOf(y, r))] = 1.0f;
        } else {
          g.SoftLabels(y, r, sigmas[mode], Spec().surface_radius_mm, mine);
        }
        off += mine.size();
      }
      double ey = 0, er = 0;
      nip.Locate(p, ey, er);
      err[mode].push_back(geo.SurfaceDistanceMm({ey, er}, {y, r}));
    }
  }
  std::array<double, sigmas.size()> median{};
  std::printf("NIP floor, median (IQR) error over 5000 uniform contacts with exact answers:\n");
  for (std::size_t k = 0; k < sigmas.size(); ++k) {
    const auto s = stats::Summarize(err[k]);
    median[k] = s.median;
    if (k == 0) {
      std::printf("  one-hot: %.2f mm (%.2f)\n", s.median, s.iqr());
    } else {
      std::printf("  soft, sigma %.0f mm: %.2f mm (%.2f)\n", sigmas[k], s.median, s.iqr());
    }
  }
  EXPECT_GT(median[0], 2.8);
  EXPECT_LT(median[0], 3.4);
  EXPECT_LT(median[2], 0.5);               // sigma 4 mm
  EXPECT_GT(median[5], median[2]);         // wide Gaussians: the renormalisation pulls edge contacts inward
}

// ---------------------------------------------------------------------------------------------------
// Baseline.

// The shipped defaults (tau 30 s, 100 Hz): these tests use BaselineConfig{} as the decoder does.
Wavelengths Nominal(double offset_nm = 0.0) {
  Wavelengths wl;
  for (std::size_t i = 0; i < 16; ++i) wl[i] = 1530.0 + 2.3 * static_cast<double>(i) + offset_nm;
  return wl;
}

TEST(BaselineTest, CapturesThenFollowsUniformDriftWhilePressedAndNeverEatsAWeakPress) {
  const BaselineConfig c;  // shipped: common mode removed, tau 30 s, touch_on 3 pm
  ASSERT_TRUE(c.common_mode);
  BaselineTracker t(c);
  Wavelengths wl = Nominal(0.4);  // +40 C: +400 pm
  ShiftsPm s;
  for (int k = 0; k < c.capture_frames; ++k) EXPECT_FALSE(t.Update(wl, s));
  EXPECT_EQ(t.state(), BaselineTracker::State::kTracking);
  // A weak press between gratings: 1.5 pm on one grating (below touch_on, so the shifts alone never freeze
  // the baseline), held 120 s while the temperature ramps at 10 C/h (0.028 pm/s on every grating). The
  // decoder's gate is open: the press must survive at full size and the drift must not
  // show (common mode removed).
  wl[5] += 0.0015;
  const double ramp_nm_per_frame = 10.0 / 3600.0 * 10e-3 / c.sample_rate_hz;
  for (int k = 0; k < 12000; ++k) {
    for (auto& w : wl) w += ramp_nm_per_frame;
    ASSERT_TRUE(t.Update(wl, s, BaselineTracker::Gate::kOpen));
  }
  EXPECT_EQ(t.state(), BaselineTracker::State::kFrozen);
  EXPECT_NEAR(s[5], 1.5f, 0.05f);  // not eaten
  for (std::size_t i = 0; i < 16; ++i) {
    if (i != 5) {
      EXPECT_NEAR(s[i], 0.0f, 0.05f) << "grating " << i + 1;  // 3.3 pm of drift removed
    }
  }
  // The baseline followed the 3.3 pm of uniform drift under the press (its 1 s common-mode filter lags by
  // 0.03 pm), while the per-grating slow filter stayed frozen.
  EXPECT_NEAR(t.drift_pm(), 10.0 / 3600.0 * 10.0 * 120.0, 0.1);
  EXPECT_NEAR(t.common_mode_pm(), 0.028f, 0.02f);
  EXPECT_NEAR(t.frozen_s(), 120.0, 0.02);
  EXPECT_FALSE(t.stale());
  // Shift-driven (no gate) the same weak press is slowly absorbed by the 30 s filter: this is why the
  // pipeline feeds the gate back. (Measured, so the test fails if the filter stops following.)
  BaselineTracker u(c);
  Wavelengths w2 = Nominal();
  for (int k = 0; k < c.capture_frames; ++k) u.Update(w2, s);
  w2[5] += 0.0015;
  for (int k = 0; k < 12000; ++k) u.Update(w2, s);
  EXPECT_LT(s[5], 0.1f);
  // Gate closed: tracking again after release_frames, whatever the shifts (here a 5 pm residual).
  wl[5] += 0.0035;
  for (int k = 0; k < c.release_frames - 1; ++k) t.Update(wl, s, BaselineTracker::Gate::kClosed);
  EXPECT_EQ(t.state(), BaselineTracker::State::kFrozen);
  t.Update(wl, s, BaselineTracker::Gate::kClosed);
  EXPECT_EQ(t.state(), BaselineTracker::State::kTracking);
  EXPECT_EQ(t.frozen_s(), 0.0);
}

// Review 10, finding 1: a decoder restarted under a held press captured the press as its rest. With the rest
// reference (the baseline the patch last had at rest), a capture that differs from it on any grating by more
// than rest_tolerance_pm, after the common mode, is refused and starts again; the patch keeps capturing until
// the press is lifted. A uniform temperature change since (thermal ratios applied) is not a press; one grating
// missing is not judged.
TEST(BaselineTest, ACaptureThatIsNotThePatchsRestIsRefusedUntilItIs) {
  BaselineConfig c;
  c.thermal_ratio[3] = 1.02f;  // this grating moves 2 % more with temperature than the median one
  c.rest_nm = Nominal();
  ShiftsPm s;
  const auto capture = [&](BaselineTracker& t, const Wavelengths& wl, int frames) {
    for (int k = 0; k < frames; ++k) t.Update(wl, s);
  };
  // A press held through the restart: 12 pm on two gratings, still. Refused capture after capture.
  Wavelengths pressed = Nominal();
  pressed[5] += 0.012;
  pressed[6] += 0.007;
  BaselineTracker t(c);
  capture(t, pressed, 10 * c.capture_frames);
  EXPECT_EQ(t.state(), BaselineTracker::State::kCapturing);
  EXPECT_EQ(t.captures_refused(), 10u);
  EXPECT_NEAR(t.refused_residual_pm(), 12.0f, 0.01f);
  // Lifted: the peaks move (the capture starts again), then rest: accepted.
  capture(t, Nominal(), c.capture_frames);
  EXPECT_EQ(t.state(), BaselineTracker::State::kTracking);
  EXPECT_EQ(t.captures_refused(), 10u);
  // 20 C warmer (+200 pm common; grating 4 +204 pm): the patch's rest, accepted at once.
  Wavelengths warm = Nominal(0.2);
  warm[3] += 0.004;
  BaselineTracker w(c);
  capture(w, warm, c.capture_frames);
  EXPECT_EQ(w.state(), BaselineTracker::State::kTracking);
  EXPECT_EQ(w.captures_refused(), 0u);
  // Just over the tolerance on one grating: refused; just under: accepted.
  for (const double off_pm : {c.rest_tolerance_pm + 0.2, c.rest_tolerance_pm - 0.2}) {
    Wavelengths one = Nominal();
    one[10] -= off_pm * 1e-3;
    BaselineTracker o(c);
    capture(o, one, c.capture_frames);
    EXPECT_EQ(o.state() == BaselineTracker::State::kTracking, off_pm < c.rest_tolerance_pm) << off_pm;
  }
  // A missing grating is not judged; too few present is refused (NaN residual).
  Wavelengths dark = pressed;
  dark[5] = dark[6] = std::numeric_limits<double>::quiet_NaN();
  BaselineTracker d(c);
  capture(d, dark, c.capture_frames);
  EXPECT_EQ(d.state(), BaselineTracker::State::kTracking);
  Wavelengths few = Nominal();
  for (std::size_t i = 0; i < 8; ++i) few[i] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(std::isnan(BaselineTracker::RestResidualPm(few, Nominal(), c)));
  // Without a reference the press is taken for the rest, as before.
  BaselineTracker none{BaselineConfig{}};
  capture(none, pressed, BaselineConfig{}.capture_frames);
  EXPECT_EQ(none.state(), BaselineTracker::State::kTracking);
}

TEST(BaselineTest, RawModeFreezesOnUniformDriftCommonModeDoesNot) {
  // The paper's raw shifts: a fast uniform drift (a 1 C step: 10 pm on every grating) reads as a touch and
  // freezes the baseline; with the common mode removed nothing moves.
  BaselineConfig raw;
  raw.common_mode = false;
  for (const bool cm : {false, true}) {
    BaselineConfig c = raw;
    c.common_mode = cm;
    BaselineTracker t(c);
    Wavelengths wl = Nominal();
    ShiftsPm s;
    for (int k = 0; k < c.capture_frames; ++k) t.Update(wl, s);
    for (auto& w : wl) w += 0.010;
    for (int k = 0; k < 100; ++k) t.Update(wl, s);
    if (cm) {
      EXPECT_EQ(t.state(), BaselineTracker::State::kTracking);
      for (float v : s) EXPECT_NEAR(v, 0.0f, 1e-3f);
      EXPECT_NEAR(t.common_mode_pm(), 10.0f - 10.0f * (1.0f - std::pow(1.0f - 1.0f / 3000.0f, 100.0f)), 0.05f);
    } else {
      EXPECT_EQ(t.state(), BaselineTracker::State::kFrozen);
      EXPECT_NEAR(s[0], 10.0f, 1e-3f);
    }
  }
}

TEST(BaselineTest, FrozenTooLongIsStaleAndNotReleased) {
  BaselineConfig c;
  c.max_frozen_s = 2.0;
  BaselineTracker t(c);
  Wavelengths wl = Nominal();
  ShiftsPm s;
  for (int k = 0; k < c.capture_frames; ++k) t.Update(wl, s);
  wl[3] += 0.050;  // a 50 pm press
  for (int k = 0; k < 250; ++k) t.Update(wl, s);
  EXPECT_TRUE(t.stale());
  EXPECT_EQ(t.state(), BaselineTracker::State::kFrozen);
  EXPECT_NEAR(s[3], 50.0f, 0.5f);  // still measured against the old baseline: the press is not eaten
}

TEST(BaselineTest, MedianOfPresentGratings) {
  ShiftsPm s;
  for (std::size_t i = 0; i < 16; ++i) s[i] = static_cast<float>(i);
  EXPECT_FLOAT_EQ(MedianOfPresent(s, 9), 7.5f);
  s[15] = std::nanf("");
  EXPECT_FLOAT_EQ(MedianOfPresent(s, 9), 7.0f);
  for (std::size_t i = 0; i < 8; ++i) s[i] = std::nanf("");
  EXPECT_TRUE(std::isnan(MedianOfPresent(s, 9)));  // 7 present: no estimate
  EXPECT_FLOAT_EQ(MedianOfPresent(s, 7), 11.0f);
}

TEST(BaselineTest, TouchDuringCaptureRestartsItAndMissingPeaksStayNaN) {
  BaselineConfig c;
  c.capture_frames = 10;
  BaselineTracker t(c);
  Wavelengths wl;
  wl.fill(1550.0);
  wl[2] = std::nan("");
  ShiftsPm s;
  for (int k = 0; k < 5; ++k) t.Update(wl, s);
  wl[0] += 0.050;  // a touch: capture starts again
  for (int k = 0; k < 9; ++k) EXPECT_FALSE(t.Update(wl, s));
  t.Update(wl, s);
  EXPECT_EQ(t.state(), BaselineTracker::State::kTracking);
  t.Update(wl, s);
  EXPECT_NEAR(s[0], 0.0f, 1e-3f);  // the baseline is the new level, not a mix
  EXPECT_TRUE(std::isnan(s[2]));
  EXPECT_TRUE(std::isnan(t.baseline_nm()[2]));
}

// The thermal field (BaselineConfig::thermal_field): the gratings' places from the forearm patch.
BaselineConfig FieldConfig() {
  BaselineConfig c;
  c.thermal_field = true;
  const double mm_per_deg = Spec().surface_radius_mm * std::numbers::pi / 180.0;
  for (std::size_t i = 0; i < 16; ++i) {
    c.grating_y_mm[i] = static_cast<float>(Spec().gratings[i].centre.y_mm);
    c.grating_arc_mm[i] = static_cast<float>(Spec().gratings[i].centre.r_deg * mm_per_deg);
  }
  return c;
}

// A field across the patch at time t s: builds over 120 s to pm_per_mm along (warm elbow) and around.
double FieldPm(const BaselineConfig& c, std::size_t i, double t, double along_pm_per_mm, double around_pm_per_mm) {
  const double s = std::min(1.0, t / 120.0);
  return s * (along_pm_per_mm * (75.0 - c.grating_y_mm[i]) + around_pm_per_mm * (60.0 - c.grating_arc_mm[i]));
}

TEST(ThermalField, AGradientUnderAPlacedPressIsFollowedAndThePressKept) {
  // A held press on FBG 12 (its neighbours 13 and 14 move too) while a field builds over 2 min: 10 pm along
  // the patch, 4 pm around (beyond the common mode, which the median takes). The decoder's gate is open and
  // places the touch at FBG 12. With the thermal field the gratings away from the touch follow their own
  // drift and the ones under it move with the plane through the others: the press stays, the field goes.
  // Without it the field stays in the shifts (what latched the gate open in the field hours).
  const std::array<float, 16> press = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, -18.0f, -4.0f, 3.0f, 0, 0};
  for (const bool on : {true, false}) {
    BaselineConfig c = FieldConfig();
    c.thermal_field = on;
    BaselineTracker t(c);
    const Wavelengths nominal = Nominal();
    ShiftsPm s;
    for (int k = 0; k < c.capture_frames; ++k) t.Update(nominal, s);
    const float touch_y = c.grating_y_mm[11], touch_arc = c.grating_arc_mm[11];
    for (int k = 0; k < 18000; ++k) {  // 3 min
      const double time_s = k / c.sample_rate_hz;
      Wavelengths wl = nominal;
      for (std::size_t i = 0; i < 16; ++i) wl[i] += (press[i] + FieldPm(c, i, time_s, 0.1, 0.1)) * 1e-3;
      ASSERT_TRUE(t.Measure(wl, s));
      t.Advance(wl, s, BaselineTracker::Gate::kOpen, touch_y, touch_arc);
    }
    float worst_field = 0, worst_press = 0;
    for (std::size_t i = 0; i < 16; ++i) {
      ASSERT_TRUE(std::isfinite(s[i]));
      if (press[i] != 0) {
        worst_press = std::max(worst_press, std::abs(s[i] - press[i]));
      } else {
        worst_field = std::max(worst_field, std::abs(s[i]));
      }
    }
    if (on) {
      EXPECT_LT(worst_field, 0.3f);
      EXPECT_LT(worst_press, 0.6f);  // the plane through the far gratings, carried under the touch
      EXPECT_NE(t.field_slope_y(), 0.0f);
    } else {
      EXPECT_GT(std::max(worst_field, worst_press), 2.0f);
    }
  }
}

TEST(ThermalField, NeverCarriesOffAHeldPress) {
  // No temperature change at all: a placed press held 5 min, then an unplaced light one (1.2 pm on one
  // grating, the gate open) held 2 min, then the same light one with the gate closed for 5 s (below the gate:
  // the robust fit leaves it out). Each must stay at its size.
  BaselineConfig c = FieldConfig();
  BaselineTracker t(c);
  const Wavelengths nominal = Nominal();
  ShiftsPm s;
  for (int k = 0; k < c.capture_frames; ++k) t.Update(nominal, s);
  Wavelengths wl = nominal;
  wl[4] += -20e-3;
  wl[3] += -6e-3;
  wl[5] += 4e-3;
  for (int k = 0; k < 30000; ++k) {
    t.Measure(wl, s);
    t.Advance(wl, s, BaselineTracker::Gate::kOpen, c.grating_y_mm[4], c.grating_arc_mm[4]);
  }
  EXPECT_NEAR(s[4], -20.0f, 0.05f);
  EXPECT_NEAR(s[3], -6.0f, 0.05f);
  EXPECT_NEAR(s[5], 4.0f, 0.05f);
  for (std::size_t i : {0u, 9u, 15u}) EXPECT_NEAR(s[i], 0.0f, 0.05f);
  wl = nominal;
  wl[9] += 1.2e-3;
  for (int k = 0; k < 12000; ++k) {
    t.Measure(wl, s);
    t.Advance(wl, s, BaselineTracker::Gate::kOpen);
  }
  EXPECT_NEAR(s[9], 1.2f, 0.05f);
  for (int k = 0; k < 500; ++k) {
    t.Measure(wl, s);
    t.Advance(wl, s, BaselineTracker::Gate::kClosed);
  }
  // The slow filter (30 s) takes its usual share of 5 s: 1 - exp(-5/30) = 15 %; the field follower nothing.
  EXPECT_NEAR(s[9], 1.2f * std::exp(-(500 - c.release_frames) / (c.drift_tau_s * c.sample_rate_hz)), 0.05f);
}

TEST(ThermalField, StepsAreBoundedAndBadPlacesOrMissingPeaksDoNothing) {
  // A sudden 100 pm field (no temperature does that in 10 ms): each frame moves a baseline by at most
  // field_max_rate_pm_s / rate. Gratings all in one row, or too few present, pin no plane: no step and no NaN.
  BaselineConfig c = FieldConfig();
  BaselineTracker t(c);
  const Wavelengths nominal = Nominal();
  ShiftsPm s;
  for (int k = 0; k < c.capture_frames; ++k) t.Update(nominal, s);
  Wavelengths wl = nominal;
  for (std::size_t i = 0; i < 16; ++i) wl[i] += FieldPm(c, i, 1e9, 1.0, 1.0) * 1e-3;
  const Wavelengths before = t.baseline_nm();
  t.Measure(wl, s);
  t.Advance(wl, s, BaselineTracker::Gate::kOpen);  // unplaced: the robust plane through the shifts
  const double limit_pm = c.field_max_rate_pm_s / c.sample_rate_hz + 1e-9;
  double largest = 0;
  for (std::size_t i = 0; i < 16; ++i) {
    // the common-mode follower moves every grating alike; what differs between gratings is the field's step
    largest = std::max(largest, std::abs((t.baseline_nm()[i] - before[i]) - (t.baseline_nm()[0] - before[0])) * 1e3);
  }
  EXPECT_GT(largest, 0.5 * limit_pm);
  EXPECT_LE(largest, 2 * limit_pm);

  // Places that pin no plane (every grating in one row around the limb: y is constant), and too few peaks
  // (5 present, 6 needed): the follower takes no step, so the baselines are exactly those of a tracker
  // without it.
  auto same_as_without_field = [&](const BaselineConfig& cfg, const Wavelengths& frame) {
    BaselineConfig off = cfg;
    off.thermal_field = false;
    BaselineTracker with(cfg), without(off);
    ShiftsPm a, b;
    for (int k = 0; k < cfg.capture_frames; ++k) {
      with.Update(nominal, a);
      without.Update(nominal, b);
    }
    for (int k = 0; k < 10; ++k) {
      with.Measure(frame, a);
      with.Advance(frame, a, BaselineTracker::Gate::kClosed);
      without.Measure(frame, b);
      without.Advance(frame, b, BaselineTracker::Gate::kClosed);
    }
    EXPECT_EQ(with.field_slope_y(), 0.0f);
    EXPECT_EQ(with.field_slope_arc(), 0.0f);
    for (std::size_t i = 0; i < 16; ++i) {
      if (std::isfinite(frame[i])) {
        ASSERT_TRUE(std::isfinite(with.baseline_nm()[i]));
      }
      EXPECT_EQ(std::isfinite(with.baseline_nm()[i]), std::isfinite(without.baseline_nm()[i]));
      if (std::isfinite(without.baseline_nm()[i])) {
        EXPECT_EQ(with.baseline_nm()[i], without.baseline_nm()[i]) << i;
      }
    }
  };
  BaselineConfig row = FieldConfig();
  for (std::size_t i = 0; i < 16; ++i) row.grating_y_mm[i] = 50.0f;
  same_as_without_field(row, wl);
  Wavelengths sparse = wl;
  for (std::size_t i = 0; i < 11; ++i) sparse[i] = std::numeric_limits<double>::quiet_NaN();
  same_as_without_field(c, sparse);
}

// ---------------------------------------------------------------------------------------------------
// The network runtime at the extremes (synthetic model with a known force function).

TEST(DecoderTest, KnownForceFunction) {
  const auto m = testing::SyntheticModel(Spec());
  NetworkDecoder<float> d(m);
  NetworkDecoder<float>::Data data(d);
  ShiftsPm s = Shifts(0.0f);
  s[3] = 120.0f;   // max of gratings 0..7
  s[12] = 30.0f;   // max of gratings 8..15
  const auto o = d.Decode(s, data);
  EXPECT_TRUE(o.valid);
  EXPECT_NEAR(o.force_n, 0.150f, 1e-6f);
  EXPECT_TRUE(o.in_contact);
  EXPECT_TRUE(o.located);
}

TEST(DecoderTest, AllZeroAndHugeInputsStayFinite) {
  for (int window : {1, 8, -8}) {  // -8: W = 8 with unit-pattern location input (norm 0 and norm ~2e4 pm)
    auto m = testing::SyntheticModel(Spec(), std::abs(window), 1.0f);
    if (window < 0) {
      for (auto& l : *m.mutable_location()) {
        l.set_input_kind(v1::LocationNet::UNIT);
        l.set_unit_floor_pm(1.0f);
      }
    }
    window = std::abs(window);
    NetworkDecoder<float> d(m);
    NetworkDecoder<double> dd(m);
    NetworkDecoder<float>::Data a(d);
    NetworkDecoder<double>::Data ad(dd);
    for (float v : {0.0f, 5000.0f, -5000.0f}) {  // 0 and +-5 nm on every grating
      for (int k = 0; k < window + 2; ++k) {
        const auto o = d.Decode(Shifts(v), a);
        const auto od = dd.Decode(Shifts(v), ad);
        // The known function with z clamped at +-1000 (std 1 pm): +5 nm reads 2 x 1000 pm -> 2.0 N, -5 nm
        // (ReLU) 0 N, exactly, in float and double; a located estimate lies on the patch's extended grids.
        const float want = v > 0 ? 2.0f : 0.0f;
        EXPECT_NEAR(o.force_n, want, 1e-5f) << v;
        EXPECT_NEAR(od.force_n, want, 1e-9f) << v;
        EXPECT_EQ(o.in_contact, v > 0);
        if (v > 0) {
          ASSERT_TRUE(o.located);
          EXPECT_GT(o.confidence, 0.0f);
          EXPECT_LE(o.confidence, 1.0f);
        }
      }
    }
    EXPECT_EQ(d.Decode(Shifts(0.0f), a).force_n, 0.0f);
  }
}

TEST(DecoderTest, NotEnoughHistoryIsInvalidNotGarbage) {
  const auto m = testing::SyntheticModel(Spec(), 8);
  NetworkDecoder<float> d(m);
  NetworkDecoder<float>::Data a(d);
  for (int k = 0; k < 7; ++k) EXPECT_FALSE(d.Decode(Shifts(100.0f), a).valid);
  EXPECT_TRUE(d.Decode(Shifts(100.0f), a).valid);
}

TEST(DecoderTest, MissingChannelsAreDecodedFromTheOthersOrFlagged) {
  const auto m = testing::SyntheticModel(Spec());
  NetworkDecoder<float> d(m);
  NetworkDecoder<float>::Data a(d);
  ShiftsPm s = Shifts(0.0f);
  s[3] = 120.0f;
  s[9] = kNaN;                                      // a dead grating
  s[10] = std::numeric_limits<float>::infinity();  // a garbled one
  const auto o = d.Decode(s, a);
  EXPECT_TRUE(o.valid);
  EXPECT_EQ(o.missing, 2);
  EXPECT_NEAR(o.force_n, 0.120f, 1e-6f);
  // More than max_missing (3): invalid, force 0, never NaN.
  for (std::size_t i = 0; i < 4; ++i) s[i + 4] = kNaN;
  const auto bad = d.Decode(s, a);
  EXPECT_FALSE(bad.valid);
  EXPECT_FALSE(bad.located);
  EXPECT_EQ(bad.force_n, 0.0f);
}

TEST(DecoderTest, HugeLogitsGiveAProperSoftmax) {
  const auto m = testing::SyntheticModel(Spec(), 1, 1e6f);  // logits ~ 1e6 x shifts
  NetworkDecoder<float> d(m);
  NetworkDecoder<float>::Data a(d);
  ShiftsPm s = Shifts(0.0f);
  s[0] = 400.0f;
  s[1] = 300.0f;
  std::vector<float> p;
  d.Probabilities(s, a, p);
  double sum = 0;
  for (float v : p) {
    ASSERT_TRUE(std::isfinite(v));
    ASSERT_GE(v, 0.0f);
    sum += v;
  }
  EXPECT_NEAR(sum, 4.0, 1e-4);  // four nets, each sums to 1
  const auto o = d.Decode(s, a);
  EXPECT_TRUE(o.located);
  EXPECT_TRUE(std::isfinite(o.y_mm) && std::isfinite(o.r_deg));
}

TEST(DecoderTest, NearZeroStdChannelStaysFinite) {
  const auto m = testing::SyntheticModel(Spec(), 1, 1.0f, 1e-3f);  // every channel std 1e-3 pm
  NetworkDecoder<float> d(m);
  NetworkDecoder<float>::Data a(d);
  const auto o = d.Decode(Shifts(5000.0f), a);
  EXPECT_TRUE(o.valid);
  EXPECT_NEAR(o.force_n, 2.0f, 1e-5f);  // z = 5e6 clamped to 1000 on both halves: 2 x 1000 x 0.001 N
}

// Forces hovering around the 50 mN gate: the gate opens once and does not flap.
TEST(DecoderTest, GateHysteresisDoesNotFlap) {
  const auto m = testing::SyntheticModel(Spec());
  NetworkDecoder<float> d(m);
  NetworkDecoder<float>::Data a(d);
  int changes = 0;
  bool last = false;
  for (int k = 0; k < 200; ++k) {
    ShiftsPm s = Shifts(0.0f);
    s[0] = 50.0f + 3.0f * static_cast<float>(std::sin(k * 0.7));  // 47..53 mN: crosses 50 often
    const auto o = d.Decode(s, a);
    if (o.in_contact != last) ++changes;
    last = o.in_contact;
  }
  EXPECT_EQ(changes, 1);
  EXPECT_TRUE(last);
  ShiftsPm s = Shifts(0.0f);
  s[0] = 39.0f;  // below off (40 mN): closes
  EXPECT_FALSE(d.Decode(s, a).in_contact);
  EXPECT_FALSE(d.Decode(s, a).located);
}

// ---------------------------------------------------------------------------------------------------
// Model files.

class ModelFileTest : public ::testing::Test {
 protected:
  // One file per test (ctest runs them as parallel processes).
  std::string path = (std::filesystem::temp_directory_path() /
                      ("ruffini_decode_test_" +
                       std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + ".rmodel"))
                         .string();
  void TearDown() override { std::filesystem::remove(path); }
  std::string Error() {
    try {
      (void)LoadModel(path);
    } catch (const InputError& e) {
      return e.what();
    }
    return "no error";
  }
};

TEST_F(ModelFileTest, RoundTrip) {
  const auto m = testing::SyntheticModel(Spec(), 4);
  SaveModel(path, m);
  EXPECT_EQ(LoadModel(path).SerializeAsString(), m.SerializeAsString());
}

TEST_F(ModelFileTest, TruncatedFileIsRejected) {
  SaveModel(path, testing::SyntheticModel(Spec()));
  const auto size = std::filesystem::file_size(path);
  std::filesystem::resize_file(path, size - 100);
  EXPECT_NE(Error().find("truncated or padded model file"), std::string::npos) << Error();
}

TEST_F(ModelFileTest, CorruptedFileIsRejected) {
  SaveModel(path, testing::SyntheticModel(Spec()));
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(200);
    f.put('\x7f');
  }
  EXPECT_NE(Error().find("checksum mismatch"), std::string::npos) << Error();
  std::ofstream(path) << "hello";
  EXPECT_NE(Error().find("not a ruffini model file"), std::string::npos) << Error();
}

TEST_F(ModelFileTest, WrongVersionIsRejected) {
  auto m = testing::SyntheticModel(Spec());
  m.set_format_version(2);
  SaveModel(path, m);
  EXPECT_NE(Error().find("model format version 2, this build reads version 1"), std::string::npos) << Error();
}

TEST_F(ModelFileTest, ShapeMismatchesAreRejected) {
  auto m = testing::SyntheticModel(Spec());
  m.mutable_force()->mutable_conv(1)->mutable_weight()->mutable_values()->RemoveLast();
  SaveModel(path, m);
  EXPECT_NE(Error().find("force net conv[1] weight declares 4096 values but holds 4095"), std::string::npos) << Error();
  m = testing::SyntheticModel(Spec());
  m.mutable_location(2)->mutable_grid()->set_nr(7);
  SaveModel(path, m);
  EXPECT_NE(Error().find("location net HSG outputs do not match its grid's 42 cells"), std::string::npos) << Error();
  m = testing::SyntheticModel(Spec());
  m.mutable_force()->mutable_input()->set_std(3, 0.0f);
  SaveModel(path, m);
  EXPECT_NE(Error().find("force net normalisation entry 3 has std 0"), std::string::npos) << Error();
  m = testing::SyntheticModel(Spec());
  m.mutable_location(1)->set_input_kind(v1::LocationNet::UNIT);
  SaveModel(path, m);
  EXPECT_NE(Error().find("location net VSG has UNIT input with unit_floor_pm 0"), std::string::npos) << Error();
  m.mutable_location(1)->set_input_kind(static_cast<v1::LocationNet::Input>(7));
  SaveModel(path, m);
  EXPECT_NE(Error().find("location net VSG has an unknown input kind 7"), std::string::npos) << Error();
}

TEST_F(ModelFileTest, ModelForAnotherPatchIsRejected) {
  const auto m = testing::SyntheticModel(Spec());
  patch::PatchSpec other = Spec();
  other.gratings[4].centre.y_mm += 1.0;
  EXPECT_NO_THROW(CheckModelMatchesPatch(m, Spec(), "m"));
  try {
    CheckModelMatchesPatch(m, other, "m.rmodel");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("m.rmodel: model was trained for patch 'forearm' (spec fingerprint"), std::string::npos);
  }
}

}  // namespace
}  // namespace ruffini::decode

namespace ruffini::decode {
namespace {

// The model shipped in config/models/ loads, was trained for the shipped patch spec (a spec edit without
// retraining fails here), and the runtime reproduces its golden vectors (libtorch's outputs) to 1e-5.
TEST(ShippedModelTest, LoadsMatchesThePatchAndDecodesItsGoldenVectors) {
  const auto m = LoadModel(RUFFINI_SOURCE_DIR "/config/models/forearm.rmodel");
  EXPECT_NO_THROW(CheckModelMatchesPatch(m, Spec(), "config/models/forearm.rmodel"));
  ASSERT_GE(m.golden_size(), 1);
  NetworkDecoder<float> d(m);
  NetworkDecoder<float>::Data a(d);
  for (const auto& g : m.golden()) {
    EXPECT_NEAR(d.ForceOnWindow(g.window_shift_pm().data(), a), g.force_n(), 1e-5 * std::max(1.0f, std::abs(g.force_n())));
    const ShiftsPm last = ruffini::testing::LastFrame(g, m);
    std::vector<float> p;
    d.Probabilities(last, a, p);
    ASSERT_EQ(static_cast<int>(p.size()), g.probabilities_size());
    for (std::size_t k = 0; k < p.size(); ++k) EXPECT_NEAR(p[k], g.probabilities(static_cast<int>(k)), 1e-5);
    d.Reset(a, &last);  // a window of W frames of history
    const auto o = d.Decode(last, a);
    EXPECT_TRUE(o.valid);
    EXPECT_TRUE(std::isfinite(o.force_n));
  }
  EXPECT_EQ(m.training().folds_size(), 5 * 6);
}

}  // namespace
}  // namespace ruffini::decode
