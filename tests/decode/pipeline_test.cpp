// decode::Pipeline: every kind of bad input gets its named reason (never a force), the networks are not
// poisoned by it, uniform drift never reaches them, and the uncertainty is the model's calibration.
#include "ruffini/decode/pipeline.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <functional>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "ruffini/decode/model_io.h"
#include "ruffini/error.h"
#include "ruffini/patch/spec_loader.h"
#include "synthetic_model.h"

namespace ruffini::decode {
namespace {

const patch::PatchSpec& Spec() {
  static const patch::PatchSpec s = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  return s;
}
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Wavelengths Nominal() {
  Wavelengths wl;
  for (std::size_t i = 0; i < 16; ++i) wl[i] = Spec().gratings[i].wavelength_nm;
  return wl;
}

// A pipeline around the synthetic model (force = 0.001 (max(s[0..7], 0) + max(s[8..15], 0)) N) that has
// captured its baseline on the nominal wavelengths.
// The synthetic model's std is 1 pm, so the default z limit (40) would make every press out of range:
// fixtures lift it unless a test sets its own.
PipelineConfig Open() {
  PipelineConfig c;
  c.z_limit = 1e6;
  return c;
}

PipelineConfig ConfigFor(const v1::DecoderModel& m, PipelineConfig cfg) {
  cfg.baseline.common_mode = m.preprocessing().common_mode_removed();
  cfg.baseline.sample_rate_hz = 100.0;
  return cfg;
}

struct Fixture {
  explicit Fixture(v1::DecoderModel model, PipelineConfig cfg = Open())
      : m(std::move(model)), pipe(m, Spec(), ConfigFor(m, cfg)), data(pipe) {
    for (int k = 0; k < pipe.config().baseline.capture_frames; ++k) {
      const auto o = pipe.Process(Nominal(), 0, data);
      EXPECT_EQ(o.reason, Reason::kCapturing);
    }
  }
  PipelineOutput Press(float pm_on_grating_4, std::uint32_t flags = 0) {
    Wavelengths wl = Nominal();
    wl[3] += pm_on_grating_4 * 1e-3;
    return pipe.Process(wl, flags, data);
  }
  v1::DecoderModel m;
  Pipeline<float> pipe;
  Pipeline<float>::Data data;
};

v1::DecoderModel WithRange(v1::DecoderModel m, float lo, float hi, float margin) {
  auto* r = m.mutable_input_range();
  for (int i = 0; i < 16; ++i) {
    r->add_min_shift_pm(lo);
    r->add_max_shift_pm(hi);
  }
  r->set_margin_pm(margin);
  return m;
}

TEST(PipelineTest, DecodesAPressAfterCapture) {
  Fixture f(testing::SyntheticModel(Spec()));
  const auto o = f.Press(120.0f);
  EXPECT_TRUE(o.valid);
  EXPECT_EQ(o.reason, Reason::kOk);
  EXPECT_NEAR(o.force_n, 0.120f, 1e-4f);
  EXPECT_TRUE(o.in_contact);
  EXPECT_TRUE(o.located);
  EXPECT_EQ(f.data.counters().frames, 101u);
  EXPECT_EQ(f.data.counters().invalid[static_cast<std::size_t>(Reason::kCapturing)], 100u);
  EXPECT_EQ(f.data.counters().onsets, 1u);
}

// The bad-input table: each row is a frame a real interrogator or a broken fibre can send.
TEST(PipelineTest, BadInputGetsItsReasonNeverAForce) {
  struct Row {
    std::string what;
    std::function<void(Wavelengths&, std::uint32_t&)> make;
    Reason reason;
    bool over_range = false;  // evidence of more load than the model knows: an over-range contact
  };
  const double one_band_up = Spec().gratings[4].wavelength_nm - Spec().gratings[3].wavelength_nm;
  const std::vector<Row> table = {
      {"saturated flag", [](Wavelengths&, std::uint32_t& fl) { fl = Pipeline<float>::kSourceSaturated; }, Reason::kSaturated, true},
      {"all peaks at 0 nm", [](Wavelengths& w, std::uint32_t&) { w.fill(0.0); }, Reason::kNoSignal},
      {"all peaks missing", [](Wavelengths& w, std::uint32_t&) { w.fill(kNaN); }, Reason::kNoSignal},
      {"one grating +5 nm", [](Wavelengths& w, std::uint32_t&) { w[3] += 5.0; }, Reason::kOutOfBand, true},
      {"one grating -1.3 nm", [](Wavelengths& w, std::uint32_t&) { w[3] -= 1.3; }, Reason::kOutOfBand, true},
      {"a grating reads its neighbour's peak", [=](Wavelengths& w, std::uint32_t&) { w[3] += one_band_up; }, Reason::kOutOfBand, true},
      {"one peak at +inf", [](Wavelengths& w, std::uint32_t&) { w[3] = std::numeric_limits<double>::infinity(); }, Reason::kOk},
      {"four peaks missing", [](Wavelengths& w, std::uint32_t&) { w[1] = w[5] = w[9] = w[13] = kNaN; }, Reason::kTooManyMissing},
      {"one grating +1.1 nm (in band, beyond the known range)", [](Wavelengths& w, std::uint32_t&) { w[3] += 1.1; }, Reason::kOutOfRange, true},
      {"one grating -0.4 nm (beyond the known range)", [](Wavelengths& w, std::uint32_t&) { w[3] -= 0.4; }, Reason::kOutOfRange, true},
  };
  for (const bool with_range : {true, false}) {
    auto model = testing::SyntheticModel(Spec());
    if (with_range) model = WithRange(model, -20.0f, 150.0f, 80.0f);  // known: -100..230 pm
    PipelineConfig cfg;
    cfg.z_limit = 300.0;  // without a range: |shift| / std (1 pm here) above 300 is out of range
    Fixture f(model, cfg);
    for (const Row& row : table) {
      SCOPED_TRACE(row.what + (with_range ? " (model with an input range)" : " (z-score limit)"));
      Wavelengths wl = Nominal();
      std::uint32_t flags = 0;
      row.make(wl, flags);
      const auto before = f.data.counters();
      const auto o = f.pipe.Process(wl, flags, f.data);
      if (row.reason == Reason::kOk) {  // one non-finite peak is a missing peak: decoded from the others
        EXPECT_TRUE(o.valid);
        EXPECT_EQ(o.missing, 1);
        EXPECT_NEAR(o.force_n, 0.0f, 1e-6f);
        continue;
      }
      EXPECT_FALSE(o.valid);
      EXPECT_EQ(o.reason, row.reason) << "got " << ReasonName(o.reason);
      EXPECT_EQ(o.over_range, row.over_range);
      // Never a hard press read as light: over range is a contact of at least the stated force.
      EXPECT_EQ(o.force_n, row.over_range ? static_cast<float>(cfg.over_range_force_n) : 0.0f);
      EXPECT_EQ(o.in_contact, row.over_range);
      EXPECT_FALSE(o.located);
      const auto r = static_cast<std::size_t>(row.reason);
      EXPECT_EQ(f.data.counters().invalid[r], before.invalid[r] + 1);
      EXPECT_EQ(f.data.counters().over_range, before.over_range + (row.over_range ? 1 : 0));
      // A frame at rest ends an over-range contact the way a release ends any contact.
      f.Press(0.0f);
    }
    // Nothing of that reached the baseline or the networks: a real press decodes exactly (less the
    // 1/3000 the onset frame costs it, baseline.h).
    for (std::size_t i = 0; i < 16; ++i) EXPECT_NEAR(f.data.baseline().baseline_nm()[i], Nominal()[i], 1e-9);
    const auto o = f.Press(120.0f);
    EXPECT_TRUE(o.valid);
    EXPECT_NEAR(o.force_n, 0.120f, 1e-4f);
  }
}

// Peaks lost under load: while a contact is open, two or more peaks lost at once (a pinched fibre darkens
// every grating beyond the pinch), too many or all of them, make the frame over range; the same frames at
// rest are a dimmed grating (one peak: decoded from the others) or a fault's evidence (invalid, no contact).
TEST(PipelineTest, PeaksLostUnderLoadAreOverRangeAtRestTheyAreNot) {
  auto model = WithRange(testing::SyntheticModel(Spec()), -20.0f, 150.0f, 80.0f);
  PipelineConfig cfg = Open();
  struct Row {
    std::string what;
    std::vector<std::size_t> lost;
    Reason at_rest;
  };
  const std::vector<Row> table = {
      {"two peaks lost", {10, 11}, Reason::kOk},
      {"the fibre dark from FBG 9 on", {8, 9, 10, 11, 12, 13, 14, 15}, Reason::kTooManyMissing},
      {"every peak lost", {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15}, Reason::kNoSignal},
  };
  for (const Row& row : table) {
    SCOPED_TRACE(row.what);
    Fixture f(model, cfg);
    Wavelengths wl = Nominal();
    for (std::size_t i : row.lost) wl[i] = kNaN;
    const auto rest = f.pipe.Process(wl, kFlagPeakMissing, f.data);
    EXPECT_FALSE(rest.over_range);
    EXPECT_FALSE(rest.in_contact);
    EXPECT_EQ(rest.reason, row.at_rest);
    // Under load: a press of 120 pm on FBG 4 (0.12 N), then the same peaks lost with it.
    for (int k = 0; k < 3; ++k) ASSERT_TRUE(f.Press(120.0f).in_contact);
    wl[3] += 0.120;
    const auto o = f.pipe.Process(wl, kFlagPeakMissing, f.data);
    EXPECT_TRUE(o.over_range);
    EXPECT_TRUE(o.in_contact);
    EXPECT_FALSE(o.valid);
    EXPECT_EQ(o.force_n, 2.5f);
    // It stays over range while the peaks stay lost, whatever the rest shows.
    EXPECT_TRUE(f.pipe.Process(wl, kFlagPeakMissing, f.data).over_range);
  }
  // One lost peak under load is a dimmed grating's dropout: decoded from the others, as before.
  Fixture f(model, cfg);
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(f.Press(120.0f).in_contact);
  Wavelengths wl = Nominal();
  wl[3] += 0.120;
  wl[12] = kNaN;
  const auto o = f.pipe.Process(wl, kFlagPeakMissing, f.data);
  EXPECT_TRUE(o.valid);
  EXPECT_FALSE(o.over_range);
  EXPECT_NEAR(o.force_n, 0.120f, 1e-3f);
}

// After an over-range stretch the decoder resumes: the baseline did not move, a release is reported and a
// light press decodes exactly again.
TEST(PipelineTest, AfterOverRangeTheBaselineIsIntactAndTheNextPressDecodes) {
  auto model = WithRange(testing::SyntheticModel(Spec()), -20.0f, 150.0f, 80.0f);
  Fixture f(model, Open());
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(f.Press(120.0f).in_contact);
  for (int k = 0; k < 50; ++k) {
    const auto o = f.Press(900.0f);  // beyond the known range (230 pm)
    ASSERT_TRUE(o.over_range);
    ASSERT_GE(o.force_n, 2.5f);
  }
  EXPECT_EQ(f.data.counters().over_range, 50u);
  // Only the onset frame of the light press reached the baseline (1/3000 of 120 pm, baseline.h).
  for (std::size_t i = 0; i < 16; ++i) EXPECT_NEAR(f.data.baseline().baseline_nm()[i], Nominal()[i], 1e-4);
  bool released = false;
  for (int k = 0; k < 200 && !released; ++k) released = !f.Press(0.0f).in_contact;
  EXPECT_TRUE(released);
  const auto o = f.Press(120.0f);
  EXPECT_TRUE(o.valid);
  EXPECT_FALSE(o.over_range);
  EXPECT_NEAR(o.force_n, 0.120f, 1e-3f);
}

TEST(PipelineTest, OverRangeSettingsAreChecked) {
  const auto model = testing::SyntheticModel(Spec());
  PipelineConfig bad = Open();
  bad.over_range_force_n = 0.0;
  EXPECT_THROW(Pipeline<float>(model, Spec(), ConfigFor(model, bad)), InputError);
  bad = Open();
  bad.over_range_missing = 0;
  EXPECT_THROW(Pipeline<float>(model, Spec(), ConfigFor(model, bad)), InputError);
}

TEST(PipelineTest, ReasonNamesAreDistinct) {
  std::set<std::string> names;
  for (std::size_t r = 0; r < kReasonCount; ++r) names.insert(std::string(ReasonName(static_cast<Reason>(r))));
  EXPECT_EQ(names.size(), kReasonCount);
  EXPECT_EQ(ReasonName(Reason::kOutOfBand), "out_of_band");
}

TEST(PipelineTest, StaleBaselineIsInvalidAndThePressIsNotEaten) {
  PipelineConfig cfg = Open();
  cfg.baseline.max_frozen_s = 5.0;
  Fixture f(testing::SyntheticModel(Spec()), cfg);
  PipelineOutput o;
  for (int k = 0; k < 499; ++k) o = f.Press(120.0f);
  EXPECT_TRUE(o.valid);
  for (int k = 0; k < 3; ++k) o = f.Press(120.0f);
  EXPECT_FALSE(o.valid);
  EXPECT_EQ(o.reason, Reason::kBaselineStale);
  EXPECT_EQ(o.force_n, 0.0f);
  // The press ends: the gate closes, the baseline resumes and the fault clears by itself.
  for (int k = 0; k < 30; ++k) o = f.Press(0.0f);
  EXPECT_TRUE(o.valid);
  EXPECT_NEAR(o.force_n, 0.0f, 1e-3f);
}

TEST(PipelineTest, UniformDriftNeverReachesACommonModeModel) {
  auto m = testing::SyntheticModel(Spec());
  m.mutable_preprocessing()->set_common_mode_removed(true);
  Fixture f(m);
  // +-10 pm on every grating (a 1 C step) with and without a press: the force is the press alone.
  for (const double drift_pm : {-10.0, -0.25, 10.0}) {
    Wavelengths wl = Nominal();
    for (auto& w : wl) w += drift_pm * 1e-3;
    const auto idle = f.pipe.Process(wl, 0, f.data);
    EXPECT_TRUE(idle.valid);
    EXPECT_NEAR(idle.force_n, 0.0f, 1e-4f) << drift_pm;
    EXPECT_FALSE(idle.in_contact);
    wl[3] += 0.120;
    const auto pressed = f.pipe.Process(wl, 0, f.data);
    EXPECT_NEAR(pressed.force_n, 0.120f, 2e-3f) << drift_pm;
  }
  // A raw model reads the same uniform +10 pm as a force: the reason the shipped models remove it.
  Fixture raw(testing::SyntheticModel(Spec()));
  Wavelengths wl = Nominal();
  for (auto& w : wl) w += 0.010;
  EXPECT_NEAR(raw.pipe.Process(wl, 0, raw.data).force_n, 0.020f, 1e-3f);
}

TEST(PipelineTest, MismatchedPreprocessingIsRefused) {
  auto m = testing::SyntheticModel(Spec());
  m.mutable_preprocessing()->set_common_mode_removed(true);
  PipelineConfig cfg;
  cfg.baseline.common_mode = false;
  try {
    Pipeline<float> p(m, Spec(), cfg);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("common_mode_removed = true"), std::string::npos) << e.what();
  }
}

// Preprocessing.faint_refuse_below_n is the model's choice: a pipeline left unset takes it (on, at the
// model's force), an explicit setting overrides it, and a file outside 0..10 N is refused when loaded.
TEST(PipelineTest, FaintRefusalIsTheModelsChoiceUnlessOverridden) {
  auto m = testing::SyntheticModel(Spec());
  PipelineConfig cfg;
  cfg.baseline = BaselineFor(m, 100.0);
  EXPECT_FALSE(*Pipeline<float>(m, Spec(), cfg).config().faint_refuse) << "older files: flag only";
  m.mutable_preprocessing()->set_faint_refuse_below_n(0.8f);
  const Pipeline<float> own(m, Spec(), cfg);
  EXPECT_TRUE(*own.config().faint_refuse);
  EXPECT_DOUBLE_EQ(own.config().faint_max_n, 0.8f);
  cfg.faint_refuse = false;
  EXPECT_FALSE(*Pipeline<float>(m, Spec(), cfg).config().faint_refuse);
  cfg.faint_refuse = true;
  EXPECT_DOUBLE_EQ(Pipeline<float>(m, Spec(), cfg).config().faint_max_n, PipelineConfig{}.faint_max_n)
      << "an override uses the config's force";
  EXPECT_NO_THROW(ValidateModel(m, "m"));
  for (float bad : {-0.1f, 10.5f, std::numeric_limits<float>::quiet_NaN()}) {
    m.mutable_preprocessing()->set_faint_refuse_below_n(bad);
    EXPECT_THROW(ValidateModel(m, "m"), InputError) << bad;
  }
}

TEST(PipelineTest, UncertaintyIsTheModelsCalibration) {
  auto m = testing::SyntheticModel(Spec());
  auto* u = m.mutable_uncertainty();
  for (auto [knot, sd, scale] : {std::tuple{0.1f, 0.02f, 2.0f}, {1.0f, 0.1f, 4.0f}}) {
    u->add_force_knots_n(knot);
    u->add_force_sd_n(sd);
    u->add_position_scale(scale);
  }
  u->set_position_floor_mm2(0.25f);
  Fixture f(m);
  const auto at = [&](float pm) { return f.Press(pm); };
  EXPECT_NEAR(at(55.0f).force_sd_n, 0.02f, 1e-6f);           // below the first knot: clamped
  EXPECT_NEAR(at(550.0f).force_sd_n, 0.02f + 0.5f * 0.08f, 1e-4f);  // halfway: linear
  const auto o = at(1100.0f);
  EXPECT_NEAR(o.force_sd_n, 0.1f, 1e-6f);                     // beyond the last: clamped
  ASSERT_TRUE(o.located);
  // Position covariance: scale x the NIP's raw covariance + floor; symmetric positive definite.
  EXPECT_GT(o.cov_yy_mm2, 0.25f);
  EXPECT_GT(o.cov_rr_mm2, 0.25f);
  EXPECT_GT(o.cov_yy_mm2 * o.cov_rr_mm2 - o.cov_yr_mm2 * o.cov_yr_mm2, 0.0f);
  // Without a calibration: NaN, and the pipeline says so.
  Fixture g(testing::SyntheticModel(Spec()));
  EXPECT_FALSE(g.pipe.calibrated_uncertainty());
  const auto n = g.Press(500.0f);
  EXPECT_TRUE(std::isnan(n.force_sd_n) && std::isnan(n.cov_yy_mm2));
}

TEST(PipelineTest, AnUncertaintyWithoutTheThreeSigmaFieldsLoadsAndDecodesAsBefore) {
  // A model file written before force_within_3sd / position_within_3sd existed: it parses, validates, keeps its
  // bytes, and decodes exactly as one that carries them (they are measurements, not inputs of the runtime).
  auto old = testing::SyntheticModel(Spec());
  auto* u = old.mutable_uncertainty();
  for (auto [knot, sd, scale] : {std::tuple{0.1f, 0.02f, 2.0f}, {1.0f, 0.1f, 4.0f}}) {
    u->add_force_knots_n(knot);
    u->add_force_sd_n(sd);
    u->add_position_scale(scale);
  }
  u->set_position_floor_mm2(0.25f);
  u->set_force_within_1sd(0.7f);
  u->set_position_within_2sd(0.9f);
  const std::string bytes = old.SerializeAsString();
  v1::DecoderModel loaded;
  ASSERT_TRUE(loaded.ParseFromString(bytes));
  EXPECT_EQ(loaded.uncertainty().force_within_3sd(), 0.0f);
  EXPECT_EQ(loaded.uncertainty().position_within_3sd(), 0.0f);
  EXPECT_EQ(loaded.SerializeAsString(), bytes);
  EXPECT_NO_THROW(ValidateModel(loaded, "old"));
  auto now = loaded;
  now.mutable_uncertainty()->set_force_within_3sd(0.99f);
  now.mutable_uncertainty()->set_position_within_3sd(0.98f);
  Fixture a(loaded), b(now);
  for (float pm : {55.0f, 300.0f, 700.0f, 1100.0f}) {
    const auto x = a.Press(pm), y = b.Press(pm);
    EXPECT_EQ(x.force_sd_n, y.force_sd_n);
    EXPECT_EQ(x.located, y.located);
    if (x.located) {
      EXPECT_EQ(x.cov_yy_mm2, y.cov_yy_mm2);
      EXPECT_EQ(x.cov_yr_mm2, y.cov_yr_mm2);
      EXPECT_EQ(x.cov_rr_mm2, y.cov_rr_mm2);
    }
  }
}

TEST(PipelineTest, ALongGapRestartsTheWindow) {
  // W = 8: after more than W invalid frames the window starts again from the next valid frame, so the
  // force is that frame's, not a mix with frames from before the gap.
  // The synthetic CNN reads the newest frame of its window; rewire it to read the oldest.
  auto m = testing::SyntheticModel(Spec(), 8);
  auto* w = m.mutable_force()->mutable_conv(0)->mutable_weight();
  w->set_values((0 * 8 + 7) * 16 + 7, 0.0f);
  w->set_values((0 * 8 + 0) * 16 + 7, 1.0f);
  PipelineConfig cfg = Open();
  cfg.quiet_release_pm = 0.0;  // this test looks at the window itself
  Fixture f(m, cfg);
  for (int k = 0; k < 20; ++k) f.Press(300.0f);
  // The oldest frame of the window is still pressed (the frame before the gate opened cost the press
  // 1/3000 of itself: W / (tau x rate), documented in baseline.h).
  EXPECT_NEAR(f.Press(0.0f).force_n, 0.300f, 2e-4f);
  Wavelengths dark;
  dark.fill(0.0);
  for (int k = 0; k < 9; ++k) EXPECT_EQ(f.pipe.Process(dark, 0, f.data).reason, Reason::kNoSignal);
  const auto o = f.Press(0.0f);
  EXPECT_TRUE(o.valid);
  EXPECT_NEAR(o.force_n, 0.0f, 1e-4f);
}

}  // namespace
}  // namespace ruffini::decode

namespace ruffini::decode {
namespace {

// The creep compensation is the exact inverse of the discretised Prony filter the twin applies: a press
// held 60 s and released, seen through that filter, decodes as the applied force (no creep, no phantom).
TEST(PipelineTest, CreepCompensationInvertsThePronyFilter) {
  auto m = testing::SyntheticModel(Spec());
  const std::array<double, 3> g = {0.05, 0.04, 0.03}, tau = {1.0, 10.0, 100.0};
  auto* c = m.mutable_creep();
  for (std::size_t k = 0; k < 3; ++k) {
    c->add_g(static_cast<float>(g[k]));
    c->add_tau_s(static_cast<float>(tau[k]));
  }
  auto plain = testing::SyntheticModel(Spec());
  Fixture with(m), without(plain);
  std::array<double, 3> x{};
  double worst = 0, phantom_plain = 0;
  int worst_at = -1;
  for (int k = 0; k < 9000; ++k) {
    // 0.6 N: ramp, 60 s hold, release, 29 s rest (the synthetic model saturates at 1 N: z clamped at 1000)
    const double applied = 0.6 * (k < 100 ? 0.01 * k : (k < 6100 ? 1.0 : 0.0));
    double strain = applied;
    for (std::size_t j = 0; j < 3; ++j) {
      x[j] += (applied - x[j]) * (1.0 - std::exp(-0.01 / tau[j]));
      strain += g[j] * x[j];
    }
    const auto a = with.Press(static_cast<float>(strain * 1000.0));
    const auto b = without.Press(static_cast<float>(strain * 1000.0));
    ASSERT_TRUE(a.valid && b.valid);
    if (k < 6200 && std::abs(a.force_n - applied) > worst) {
      worst = std::abs(a.force_n - applied);
      worst_at = k;
    }
    if (k > 6200) {
      phantom_plain = std::max(phantom_plain, static_cast<double>(b.force_n));
      ASSERT_FALSE(a.in_contact) << k;
      // At rest the baseline follows what is left of the residual, so the compensation, which subtracts all
      // of it, reads a little below zero: bounded, and never a contact.
      ASSERT_GT(a.force_n, -0.02f) << k;
    }
  }
  EXPECT_LT(worst, 2e-3) << "at frame " << worst_at;  // float rounding of the shifts (1 pm = 1 mN here)
  EXPECT_GT(phantom_plain, 0.04);     // uncompensated, the release leaves a phantom at the gate
}

}  // namespace
}  // namespace ruffini::decode

namespace ruffini::decode {
namespace {

// quiet_release_pm: a frame on which no grating moves is no contact, whatever the window remembers.
TEST(PipelineTest, QuietReleaseCutsTheWindowsLag) {
  auto m = testing::SyntheticModel(Spec(), 8);
  auto* w = m.mutable_force()->mutable_conv(0)->mutable_weight();  // read the oldest frame of the window
  w->set_values((0 * 8 + 7) * 16 + 7, 0.0f);
  w->set_values((0 * 8 + 0) * 16 + 7, 1.0f);
  for (const double q : {0.0, 1.0}) {
    PipelineConfig cfg = Open();
    cfg.quiet_release_pm = q;
    Fixture f(m, cfg);
    for (int k = 0; k < 20; ++k) EXPECT_TRUE(f.Press(300.0f).in_contact);
    const auto released = f.Press(0.5f);  // 0.5 pm: noise level; the window's oldest frame still reads 0.3 N
    if (q > 0) {
      EXPECT_FALSE(released.in_contact);
      EXPECT_EQ(released.force_n, 0.0f);
      EXPECT_TRUE(f.Press(1.5f).in_contact);  // a grating above the threshold: the nets decide again
    } else {
      EXPECT_TRUE(released.in_contact);
      EXPECT_NEAR(released.force_n, 0.3f, 1e-3f);
    }
  }
}

}  // namespace
}  // namespace ruffini::decode

namespace ruffini::decode {
namespace {

// With quiet_release_drop, a light press that never moves a grating by much is left to the nets: only a
// drop from a real press is cut.
TEST(PipelineTest, QuietReleaseOnlyAfterADrop) {
  PipelineConfig cfg = Open();
  cfg.quiet_release_pm = 1.0;
  cfg.quiet_release_drop = 4.0;
  auto m = testing::SyntheticModel(Spec());
  m.mutable_force()->set_output_scale_n(0.1f);  // 0.5 pm reads 50 mN, above the gate: a "light press"
  Fixture f(m, cfg);
  for (int k = 0; k < 200; ++k) ASSERT_TRUE(f.Press(0.8f).in_contact) << k;  // never above 4 x 1 pm: kept
  for (int k = 0; k < 5; ++k) f.Press(30.0f);
  EXPECT_FALSE(f.Press(0.8f).in_contact);  // the same shift right after 30 pm: a release, cut
}

}  // namespace
}  // namespace ruffini::decode
