// The shipped model in the field, through the streaming pipeline the decoder service runs: accuracy on a
// small unseen twin run, no baseline latch-up under temperature drift at the paper's duty cycle, a long
// light press between gratings that is not eaten, and no phantom contact after a release.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <random>
#include <utility>
#include <vector>

#include "ruffini/decode/model_io.h"
#include "ruffini/eval/calibrate.h"
#include "ruffini/error.h"
#include "ruffini/eval/stream.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"
#include "ruffini/twin/viscoelastic.h"

namespace ruffini::eval {
namespace {

const char* kModel = RUFFINI_SOURCE_DIR "/config/models/forearm.rmodel";
const char* kFieldModel = RUFFINI_SOURCE_DIR "/config/models/forearm-field.rmodel";

const twin::Scene& PaperScene() {
  static const twin::Scene s = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/forearm.yaml");
  return s;
}
const twin::Scene& FieldScene() {
  static const twin::Scene s = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/forearm-field.yaml");
  return s;
}
const v1::DecoderModel& Model() {
  static const v1::DecoderModel m = decode::LoadModel(kModel);
  return m;
}

dataset::Dataset Collect(const twin::SkinTwin& t, const twin::Scene& scene, const std::string& protocol, std::uint64_t seed,
                         double rate_hz, const std::function<twin::ProtocolRun(const twin::FrameSink&)>& run) {
  dataset::Dataset d;
  d.info = twin::TwinDatasetInfo(t, scene, protocol, seed, rate_hz);
  run([&](std::span<const dataset::Frame> frames) {
    for (const auto& f : frames) d.Append(f);
  });
  return d;
}

const v1::DecoderModel& FieldModel() {
  static const v1::DecoderModel m = decode::LoadModel(kFieldModel);
  return m;
}

// faint_refuse unset: as the model says; false: every faint frame reported (flag only).
StreamPredictions Decode(const dataset::Dataset& d, const v1::DecoderModel& m = Model(),
                         std::optional<bool> faint_refuse = std::nullopt) {
  decode::PipelineConfig cfg;
  cfg.faint_refuse = faint_refuse;
  cfg.baseline = decode::BaselineFor(m, d.info.sample_rate_hz);
  const decode::Pipeline<float> pipe(m, PaperScene().Patch().spec, cfg);
  return DecodeStream(pipe, d);
}

// Scored over the indentations' frames (the opening rest holds the baseline capture); the baseline and
// false-contact figures span the whole stream either way.
StreamMetrics Score(const dataset::Dataset& d, const StreamPredictions& p) {
  std::vector<std::int32_t> ids;
  for (auto id : d.indentation) {
    if (id >= 0 && (ids.empty() || ids.back() != id)) ids.push_back(id);
  }
  return ScoreStream(d, p, PaperScene().Patch().spec, MaskOfIndentations(d, ids), {62.5, 72.5});
}

// Paper protocol, seed never used for training or calibration (1 trains, 2 calibrates, 3 tests).
dataset::Dataset PaperRun(const twin::TwinEffects& effects, int indentations, std::uint64_t seed) {
  const twin::SkinTwin t(PaperScene().Patch().spec, effects, {PaperScene().probe.radius_mm});
  twin::PaperProtocol p;
  p.indentations = indentations;
  return Collect(t, PaperScene(), "paper", seed, p.rate_hz,
                 [&](const twin::FrameSink& s) { return twin::RunPaper(t, PaperScene(), p, seed, s); });
}

TEST(ShippedModelField, AccuracySmokeOnAnUnseenPaperRun) {
  const dataset::Dataset d = PaperRun(PaperScene().effects, 40, 77);
  const auto p = Decode(d);
  const StreamMetrics m = Score(d, p);
  // Bounds about 1.5x what the shipped model measures on 2700 unseen indentations (docs/decoder-report):
  // a broken model, a wrong preprocessing or a pipeline that eats presses lands far outside them (the random
  // guess is ~190 mN / ~35 mm).
  EXPECT_LT(m.force_all_mn.median, 40.0);
  EXPECT_LT(m.force_above_mn.median, 140.0);
  EXPECT_LT(m.location_above_mm.median, 4.5);
  EXPECT_LT(m.miss_rate_above_100mn, 0.05);
  EXPECT_EQ(m.invalid, 0u);
}

// The latch-up: a -10 C/h ramp (and, separately, a +-1 C HVAC cycle) at the paper's duty cycle.
// The baseline must never stay frozen longer than the longest press plus 5 s, and drift must cost little.
TEST(ShippedModelField, NoLatchUpUnderDriftAtThePapersDutyCycle) {
  const int n = 60;  // ~10 min at 100 Hz
  const dataset::Dataset calm = PaperRun(PaperScene().effects, n, 78);
  const StreamMetrics ref = Score(calm, Decode(calm));
  for (int variant = 0; variant < 2; ++variant) {
    SCOPED_TRACE(variant == 0 ? "-10 C/h ramp" : "+-1 C, 30 min HVAC cycle");
    twin::TwinEffects e = PaperScene().effects;
    twin::TemperatureEffect te;
    if (variant == 0) {
      te.ramp_c_per_s = -10.0 / 3600.0;
    } else {
      te.amplitude_c = 1.0;
      te.period_s = 1800.0;
    }
    e.temperature = te;
    const dataset::Dataset d = PaperRun(e, n, 78);
    const StreamMetrics m = Score(d, Decode(d));
    EXPECT_LE(m.longest_frozen_s, m.longest_press_s + 5.0);
    EXPECT_LE(m.force_above_mn.median, 1.25 * ref.force_above_mn.median);
    EXPECT_LE(m.false_contact_rate, ref.false_contact_rate + 0.002);
    EXPECT_LT(m.location_above_mm.median, 1.25 * ref.location_above_mm.median);
  }
}

// The point of the indented area farthest from every grating centre ("between gratings").
patch::SurfacePoint BetweenGratings(const twin::SkinTwin& t) {
  const patch::Geometry geo(t.spec().surface_radius_mm);
  const auto& a = t.spec().indented_area;
  patch::SurfacePoint best{};
  double best_d = -1;
  for (double y = a.y_min_mm + 10; y <= a.y_max_mm - 10; y += 1.0) {
    for (double r = a.r_min_deg + 10; r <= a.r_max_deg - 10; r += 1.0) {
      double d = 1e9;
      for (const auto& c : t.grating_centres()) d = std::min(d, geo.SurfaceDistanceMm({y, r}, c));
      if (d > best_d) {
        best_d = d;
        best = {y, r};
      }
    }
  }
  return best;
}

// rest, ramp up, hold, ramp down, rest: a static probe through the field scene's effects (viscoelastic
// cover included). Returns the dataset and the frame ranges of the hold and of the final rest.
struct Press {
  dataset::Dataset data;
  std::size_t hold_first = 0, hold_last = 0, rest_first = 0;
  std::size_t again_first = 0, again_last = 0;
};
// raise_to_n > 0: after the hold the force ramps to raise_to_n over 2 s and holds 5 s there (hold_last marks
// the end of that second hold), then releases from it. again_n > 0: again_after_s after the release, a second
// press ramps to again_n over 0.3 s and holds 5 s (again_first, again_last), then releases; the final rest follows.
Press StaticPress(const twin::Scene& scene, const patch::SurfacePoint& at, double force_n, double hold_s,
                  double raise_to_n = 0.0, double again_n = 0.0, double again_after_s = 1.0) {
  const twin::SkinTwin t(scene.Patch().spec, scene.effects, {scene.probe.radius_mm});
  const double rate = 100.0, dt = 1.0 / rate;
  twin::InterrogatorSim sim(t, 5);
  twin::ViscoelasticSites visco(scene.effects.viscoelastic ? &*scene.effects.viscoelastic : nullptr, dt, scene.probe);
  visco.MoveTo(at);
  Press out;
  out.data.info = twin::TwinDatasetInfo(t, scene, "static-press", 5, rate);
  std::uint64_t serial = 0;
  auto frame = [&](double f) {
    dataset::Frame fr;
    const auto contacts = visco.Step(f);
    twin::Shifts s;
    std::uint32_t flags = 0;
    t.StrainShiftsPm(contacts, s, flags);
    const double ts = static_cast<double>(serial) * dt;
    sim.Read(ts, s, fr.wavelength_nm, flags);
    fr.t_s = ts;
    fr.serial = serial++;
    fr.flags = flags;
    fr.force_n = fr.true_force_n = static_cast<float>(f);
    fr.y_mm = static_cast<float>(at.y_mm);
    fr.r_deg = static_cast<float>(at.r_deg);
    fr.indentation = f > 0 ? 0 : -1;
    out.data.Append(fr);
  };
  for (int k = 0; k < 1000; ++k) frame(0.0);               // 10 s rest: baseline capture
  for (int k = 1; k <= 100; ++k) frame(force_n * k / 100);  // 1 s ramp
  out.hold_first = out.data.size();
  for (int k = 0; k < static_cast<int>(hold_s * rate); ++k) frame(force_n);
  if (raise_to_n > 0.0) {
    for (int k = 1; k <= 200; ++k) frame(force_n + (raise_to_n - force_n) * k / 200);
    for (int k = 0; k < 500; ++k) frame(raise_to_n);
    force_n = raise_to_n;
  }
  out.hold_last = out.data.size();
  for (int k = 49; k >= 0; --k) frame(force_n * k / 50);    // 0.5 s release
  if (again_n > 0.0) {
    for (int k = 0; k < static_cast<int>(again_after_s * rate); ++k) frame(0.0);
    for (int k = 1; k <= 30; ++k) frame(again_n * k / 30);
    out.again_first = out.data.size();
    for (int k = 0; k < 500; ++k) frame(again_n);
    out.again_last = out.data.size();
    for (int k = 49; k >= 0; --k) frame(again_n * k / 50);
  }
  out.rest_first = out.data.size();
  for (int k = 0; k < 3000; ++k) frame(0.0);               // 30 s rest
  return out;
}

double MeanForce(const StreamPredictions& p, std::size_t first, std::size_t last) {
  double s = 0;
  for (std::size_t k = first; k < last; ++k) s += p.force_n[k];
  return s / static_cast<double>(last - first);
}

TEST(ShippedModelField, ALongLightPressBetweenGratingsIsNotEaten) {
  const twin::SkinTwin t(PaperScene().Patch().spec, PaperScene().effects, {5.5});
  const patch::SurfacePoint at = BetweenGratings(t);
  const Press press = StaticPress(PaperScene(), at, 0.3, 30.0);
  const auto p = Decode(press.data);
  // 5 s means (the decoded force is noisy at the site farthest from every grating, where 0.3 N moves the
  // nearest gratings by a few pm only).
  const double early = MeanForce(p, press.hold_first + 100, press.hold_first + 600);
  const double late = MeanForce(p, press.hold_last - 500, press.hold_last);
  // The old tracker read 0.01 N after 30 s: absorbed. Now the gate holds the baseline.
  EXPECT_GT(late, 0.8 * early) << "early " << early << " N, late " << late << " N at y " << at.y_mm << " r " << at.r_deg;
  EXPECT_GT(late, 0.15);
  for (std::size_t k = press.hold_first; k < press.hold_last; ++k) ASSERT_TRUE(p.in_contact[k]) << k;
  // After release (and the window's W frames), no phantom contact.
  std::size_t phantom = 0;
  for (std::size_t k = press.rest_first + 50; k < press.data.size(); ++k) phantom += p.in_contact[k];
  // Measured: 9 frames (90 ms) of the gate's noise crossings in the 30 s after release; the target is none
  // (docs/field-report). A phantom that lasts (a latched or creeping baseline) fails this.
  EXPECT_LE(phantom, 20u);
}

// Issue 17: one grating off its baseline by a fraction of a picometre, nothing touching (review field.md
// finding 3; `ruffini grating-probe` tables it). The shipped models read -1 pm on FBG 16 as 0.5 N (p99
// 1 N); such frames are flagged `faint`. Per grating and offset, a fresh baseline over 0.3 pm noise, then
// the offset; the force reported 0.5-1.5 s into it, a flagged frame counted as 0. With the rule off the same
// stream fails (the test can tell).
struct Frames {
  std::vector<bool> contact, faint, stale;
  std::vector<float> force;
};
Frames DecodeFrames(const v1::DecoderModel& m, decode::PipelineConfig cfg, const std::vector<Wavelengths>& wl) {
  cfg.baseline = decode::BaselineFor(m, 100.0);
  const decode::Pipeline<float> pipe(m, PaperScene().Patch().spec, cfg);
  decode::Pipeline<float>::Data d(pipe);
  Frames f;
  for (const auto& w : wl) {
    const auto o = pipe.Process(w, 0, d);
    f.contact.push_back(o.in_contact);
    f.faint.push_back(o.faint);
    f.stale.push_back(o.reason == decode::Reason::kBaselineStale);
    f.force.push_back(o.in_contact ? o.force_n : 0.0f);
  }
  return f;
}
// Nominal peaks with 0.3 pm noise; from frame `from` on, `grating` is offset by offset_pm.
std::vector<Wavelengths> OneGratingOff(std::size_t grating, double offset_pm, std::size_t from, std::size_t frames,
                                       std::uint64_t seed) {
  const auto& spec = PaperScene().Patch().spec;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.3e-3);
  std::vector<Wavelengths> out(frames);
  for (std::size_t k = 0; k < frames; ++k) {
    for (std::size_t i = 0; i < kGratings; ++i) out[k][i] = spec.gratings[i].wavelength_nm + noise(rng);
    if (k >= from) out[k][grating] += offset_pm * 1e-3;
  }
  return out;
}
double ProbeP99(const v1::DecoderModel& m, const decode::PipelineConfig& cfg, std::size_t grating, double offset_pm,
                std::uint64_t seed) {
  const std::size_t from = 500;  // 1 s capture, 4 s quiet
  const Frames f = DecodeFrames(m, cfg, OneGratingOff(grating, offset_pm, from, from + 150, seed));
  std::vector<double> reported;
  for (std::size_t k = from + 50; k < f.force.size(); ++k) reported.push_back(f.faint[k] ? 0.0 : f.force[k]);
  std::sort(reported.begin(), reported.end());
  return reported[static_cast<std::size_t>(0.99 * static_cast<double>(reported.size() - 1))];
}

TEST(ShippedModelField, AMinusOnePicometreGratingDoesNotReadAsAPress) {
  const decode::PipelineConfig shipped;
  ASSERT_GT(shipped.faint_pm, 0.0) << "the faint rule ships on";
  for (const v1::DecoderModel* m : {&Model(), &FieldModel()}) {
    int over = 0;
    double worst = 0;
    for (std::size_t g = 0; g < kGratings; ++g) {
      for (const double off : {-1.0, -0.5, 0.5, 1.0}) {
        const double p99 = ProbeP99(*m, shipped, g, off, 100 + g);
        over += p99 > 0.1 ? 1 : 0;
        worst = std::max(worst, p99);
      }
    }
    EXPECT_EQ(over, 0) << "of 64 cases read above 0.1 N (p99) unflagged, largest " << worst << " N";
    // The review's case: -1 pm on FBG 16 read 0.57 N. Without the rule it still does, unflagged.
    decode::PipelineConfig off = shipped;
    off.faint_pm = 0.0;
    EXPECT_GT(ProbeP99(*m, off, 15, -1.0, 115), 0.3);
  }
}

// The flag leaves real presses alone: at FBG 16's centre a press of 0.1 N or more is never flagged; at the
// wrist edge, where a real 1-2.5 N press moves FBG 16 alone by a picometre or two and is flagged, its
// contact and force are those of the decoder without the rule (flagged, not suppressed).
TEST(ShippedModelField, PressesAtAGratingAreNotFlaggedAndAtTheEdgeNotSuppressed) {
  const twin::SkinTwin t(PaperScene().Patch().spec, PaperScene().effects, {5.5});
  const auto& a = t.spec().indented_area;
  const patch::SurfacePoint grating = t.grating_centres()[15];
  const patch::SurfacePoint edge{a.y_max_mm - 0.2, grating.r_deg};  // as the review's press 15: 0.2 mm inside the wrist border
  // A validation press of 2.1 N near here (paper seed 2) moved FBG 16 alone by -1.7 pm and was flagged.
  const patch::SurfacePoint corner{133.1, 31.8};
  decode::PipelineConfig off;
  off.faint_pm = 0.0;
  for (const auto& [at, forces] : {std::pair{grating, std::vector<double>{0.1, 0.5, 2.0}},
                                   std::pair{edge, std::vector<double>{1.0, 2.0, 2.5}},
                                   std::pair{corner, std::vector<double>{1.0, 2.0}}}) {
    for (const double force : forces) {
      const Press press = StaticPress(PaperScene(), at, force, 10.0);
      std::vector<Wavelengths> wl(press.data.size());
      for (std::size_t k = 0; k < wl.size(); ++k) std::copy_n(press.data.wavelength_nm[k].begin(), kGratings, wl[k].begin());
      const Frames on = DecodeFrames(Model(), {}, wl), plain = DecodeFrames(Model(), off, wl);
      std::size_t flagged = 0, differ = 0;
      double sum = 0;
      for (std::size_t k = press.hold_first; k < press.hold_last; ++k) {
        flagged += on.faint[k];
        differ += on.contact[k] != plain.contact[k] || on.force[k] != plain.force[k];
        sum += on.force[k];
      }
      const auto n = static_cast<double>(press.hold_last - press.hold_first);
      std::printf("%.1f N at (%.1f mm, %.1f deg): %.1f %% of the hold flagged, mean reported %.3f N\n", force, at.y_mm,
                  at.r_deg, 100.0 * static_cast<double>(flagged) / n, sum / n);
      EXPECT_EQ(differ, 0u) << force << " N at " << at.y_mm << " mm";
      if (at.y_mm == grating.y_mm) {
        EXPECT_EQ(flagged, 0u) << force << " N on FBG 16";
      }
    }
  }
}

// faint_refuse does not end finding 1(a)'s latch, and must not: a grating left 1 pm low (a press absorbed, then
// released) reads as a contact, the gate freezes the baseline and after 300 s it is stale (a FAULT, the arm
// stopped until a re-tare). Refused, the frames below 1 N are no contact, yet the gate stays open and the
// stale clock runs, so the same FAULT comes (review 7: pausing the clock let such an error hide a 2.25 N press
// with no FAULT; letting the baseline track ate a held light press). No faint frame below 1 N is a contact.
TEST(ShippedModelField, RefusedFaintFramesStillFaultABaselineLeftAPicometreOff) {
  const auto wl = OneGratingOff(15, -1.0, 500, 500 + 40000, 7);
  decode::PipelineConfig off, refuse;
  off.faint_pm = 0.0;
  refuse.faint_refuse = true;
  const Frames latched = DecodeFrames(FieldModel(), off, wl), refused = DecodeFrames(FieldModel(), refuse, wl);
  const auto count = [](const std::vector<bool>& v, std::size_t from) {
    return static_cast<std::size_t>(std::count(v.begin() + static_cast<std::ptrdiff_t>(from), v.end(), true));
  };
  const std::size_t stale_off = count(latched.stale, 500), stale_refused = count(refused.stale, 500);
  std::printf("-1 pm on FBG 16 for 400 s: stale frames flag only %zu, refusing %zu; contact frames refusing %zu\n",
              stale_off, stale_refused, count(refused.contact, 500));
  EXPECT_GT(stale_off, 1000u) << "the latch this test is about no longer happens";
  EXPECT_GT(stale_refused, stale_off - 500) << "refusing must FAULT as flag only does (within 5 s)";
  std::size_t light = 0;
  for (std::size_t k = 500; k < refused.contact.size(); ++k) {
    light += refused.contact[k] && refused.faint[k] && refused.force[k] < refuse.faint_max_n;
  }
  EXPECT_EQ(light, 0u) << "faint contact frames below faint_max_n";
}

// The 120 s press through the field scene (viscoelastic cover, temperature history): the decoded
// force at the end of the hold against the applied force, and phantom contacts after the release. Decoded
// with every faint frame reported: the guard is about the baseline eating a press, and the field model's
// refusal would report a faint light press as 0 (it holds the baseline: the raised-press test below).
TEST(ShippedModelField, HundredTwentySecondPresses) {
  const twin::SkinTwin t(FieldScene().Patch().spec, FieldScene().effects, {5.5});
  const auto& a = t.spec().indented_area;
  std::vector<double> rel;
  for (const double force : {0.1, 0.5, 2.5}) {
    for (const patch::SurfacePoint at : {patch::SurfacePoint{a.y_min_mm + 25, a.r_min_deg + 20},
                                         patch::SurfacePoint{0.5 * (a.y_min_mm + a.y_max_mm), 0.5 * (a.r_min_deg + a.r_max_deg)},
                                         BetweenGratings(t)}) {
      const Press press = StaticPress(FieldScene(), at, force, 120.0);
      const auto p = Decode(press.data, FieldModel(), false);
      const double late = MeanForce(p, press.hold_last - 100, press.hold_last);
      std::size_t phantom = 0;
      for (std::size_t k = press.rest_first + 50; k < press.data.size(); ++k) phantom += p.in_contact[k] && p.force_n[k] > 0.05f;
      std::printf("120 s press %.1f N at (%.1f mm, %.1f deg): decoded %.3f N at the end (%+.0f %%), %zu phantom frames after release\n",
                  force, at.y_mm, at.r_deg, late, 100.0 * (late / force - 1.0), phantom);
      rel.push_back(std::abs(late / force - 1.0));
      // Guards (the target, within 20 % and no phantom, is met by 3 of the 9: docs/field-report):
      // a press of 0.5 N or more is never absorbed below half its size, and its phantom stays under 2 s.
      if (force >= 0.5) {
        EXPECT_GT(late, 0.5 * force);
        EXPECT_LT(phantom, 200u);
      }
    }
  }
  std::sort(rel.begin(), rel.end());
  EXPECT_LT(rel[rel.size() / 2], 0.4);  // median relative error at the end of the hold (measured 27 %)
}

// ruffini calibrate's thermal ratios recover the cast's per-grating temperature coefficients (the twin
// draws them with a 3 % spread) from a field recording whose temperature moves, presses and all.
TEST(ShippedModelField, AFieldAtFortyPicometresPerDegreeStaysStaleLessWithTheThermalField) {
  // The embedded cast (40 pm/C) under a field building across the cover (3 C along, 2 C around, tau 10 min),
  // the first 15 min of the field protocol (the field builds fastest there), decoded by its own model
  // (forearm-embedded.rmodel: its thermal ratios) with the experimental thermal-field follower on and off
  // (off in every shipped model: review 5's open findings, tests/decode/thermal_field_review_test.cpp). Seeds 31-36 are the validation seeds the follower was built on (docs/experiments/thermal-field.md):
  // off, every run goes stale within a minute or two and stays so (59,800 of 90,000 frames each); on, two of
  // the six never go stale and the six together spend 0.58 of that. A regression guard on those figures, not a
  // held-out score (that is in the report).
  const twin::Scene scene = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/forearm-field-gradient.yaml");
  const v1::DecoderModel embedded = decode::LoadModel(RUFFINI_SOURCE_DIR "/config/models/forearm-embedded.rmodel");
  const twin::SkinTwin t(scene.Patch().spec, scene.effects, {scene.probe.radius_mm});
  twin::FieldProtocol fp;
  fp.duration_s = 900.0;
  std::size_t stale_on = 0, stale_off = 0;
  int never_stale_on = 0, never_stale_off = 0;
  for (std::uint64_t seed = 31; seed <= 36; ++seed) {
    const dataset::Dataset d = Collect(t, scene, "field", seed, fp.rate_hz,
                                       [&](const twin::FrameSink& sink) { return twin::RunField(t, scene, fp, seed, sink); });
    for (const bool field : {true, false}) {
      decode::PipelineConfig cfg;
      cfg.baseline = decode::BaselineFor(embedded, d.info.sample_rate_hz);
      cfg.baseline.thermal_field = field;
      const decode::Pipeline<float> pipe(embedded, scene.Patch().spec, cfg);
      const StreamPredictions p = DecodeStream(pipe, d);
      std::size_t stale = 0;
      for (const std::uint8_t r : p.reason) stale += r == static_cast<std::uint8_t>(decode::Reason::kBaselineStale) ? 1 : 0;
      (field ? stale_on : stale_off) += stale;
      (field ? never_stale_on : never_stale_off) += stale == 0 ? 1 : 0;
    }
  }
  EXPECT_EQ(never_stale_off, 0);
  EXPECT_GT(stale_off, 6u * 50000u);
  EXPECT_GE(never_stale_on, 1);
  EXPECT_LT(static_cast<double>(stale_on), 0.75 * static_cast<double>(stale_off));
}

TEST(Calibrate, ThermalRatiosRecoverTheCastsCoefficients) {
  const twin::SkinTwin t(FieldScene().Patch().spec, FieldScene().effects, {5.5});
  twin::FieldProtocol fp;
  fp.duration_s = 3600.0;
  const dataset::Dataset d = Collect(t, FieldScene(), "field", 21, fp.rate_hz,
                                     [&](const twin::FrameSink& s) { return twin::RunField(t, FieldScene(), fp, 21, s); });
  const std::vector<float> r = FitThermalRatio(Model(), FieldScene().Patch().spec, d);
  decode::ShiftsPm truth;
  for (std::size_t i = 0; i < 16; ++i) truth[i] = static_cast<float>(t.temperature_pm_per_c()[i]);
  const float med = decode::MedianOfPresent(truth, 1);
  double worst = 0, spread = 0;
  for (std::size_t i = 0; i < 16; ++i) {
    worst = std::max(worst, std::abs(static_cast<double>(r[i] - truth[i] / med)));
    spread = std::max(spread, std::abs(static_cast<double>(truth[i] / med - 1.0f)));
  }
  // Measured: 1.0 % worst error on a 3.3 % spread from one hour of the field scene: the ratios remove at
  // least half of every grating's differential drift (unit ratios would leave all of it).
  EXPECT_LT(worst, 0.5 * spread);
  EXPECT_GT(spread, 0.02);
  // No temperature movement: a clear refusal, not ratios fitted to noise.
  const dataset::Dataset still = PaperRun(PaperScene().effects, 5, 3);
  EXPECT_THROW(FitThermalRatio(Model(), PaperScene().Patch().spec, still), InputError);
}

// ruffini calibrate's creep fit measures the cover, not the decoder's static scale (issue 17: on the four
// field casts it came out 0 / 0 / 0, on cast 0 0.111 / 0.002 / 0.081). The same hour of the field scene (the
// twin's cover: g 0.05 / 0.04 / 0.03 at 1 / 10 / 100 s) decoded by the field model as it is, 15 % low and 15 %
// high (every grating's gain 0.85 or 1.15, as another cast or a gain fit leaves it). The fit without a scale
// per press gave 0.028 / 0 / 0.104, 0 / 0 / 0 and 0.144 / 0 / 0.133: the scale error read as creep.
TEST(Calibrate, TheCreepFitDoesNotDependOnTheDecodersScale) {
  const twin::SkinTwin t(FieldScene().Patch().spec, FieldScene().effects, {5.5});
  twin::FieldProtocol fp;
  fp.duration_s = 3600.0;
  const dataset::Dataset d = Collect(t, FieldScene(), "field", 21, fp.rate_hz,
                                     [&](const twin::FrameSink& s) { return twin::RunField(t, FieldScene(), fp, 21, s); });
  double truth = 0;
  for (const auto& term : FieldScene().effects.viscoelastic->terms) truth += term.g;
  std::vector<double> totals, fast;
  for (const float gain : {1.0f, 0.85f, 1.15f}) {
    v1::DecoderModel m = FieldModel();
    ApplyGains(m, std::vector<float>(16, gain));
    const v1::CreepCompensation c = FitCreep(m, FieldScene().Patch().spec, d);
    ASSERT_EQ(c.g_size(), 3);
    double total = 0;
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(c.g(k), 0.0f);
      total += c.g(k);
    }
    std::printf("gains %.2f: creep g %.4f / %.4f / %.4f (sum %.3f; the twin's %.3f)\n", gain, c.g(0), c.g(1), c.g(2), total, truth);
    totals.push_back(total);
    fast.push_back(c.g(0) + c.g(1));
  }
  for (std::size_t i = 0; i < totals.size(); ++i) {
    // The creep of every decoder within a factor of two of the twin's, and the three fits' 1 s and 10 s terms
    // alike (measured: 0.100-0.103 / 0.055-0.056 / 0.007-0.022, sum 0.165-0.177 against 0.12; the 100 s term
    // is the least determined: a hold lasts at most 120 s and the baseline follows a residual that slow).
    EXPECT_GT(totals[i], 0.5 * truth) << i;
    EXPECT_LT(totals[i], 2.0 * truth) << i;
    EXPECT_NEAR(fast[i], fast[0], 0.25 * fast[0]) << i;
  }
}

// With a creep compensation in the model, the gains aim at the strain force F + sum g x the networks see
// under a creeping cover (the decoder's compensation turns it back into F), not at F: fitted against F they
// took the creep's mean rise into the cast's scale, and the compensation then took it off a second time.
TEST(Calibrate, GainsAimAtTheStrainForceTheCreepCompensationUndoes) {
  const dataset::Dataset d = PaperRun(FieldScene().effects, 40, 2);  // a creeping cover, validation seed
  const auto mean_gain = [&](const v1::DecoderModel& m) {
    const GainFit fit = FitGains(m, PaperScene().Patch().spec, d, 1);
    double mean = 0;
    for (const float g : fit.gain) mean += g / 16.0;
    return mean;
  };
  v1::DecoderModel creeping = Model();
  ASSERT_FALSE(creeping.has_creep());
  const double plain = mean_gain(creeping);
  for (const double tau : {1.0, 10.0, 100.0}) {
    creeping.mutable_creep()->add_g(tau == 1.0 ? 0.3f : 0.0f);
    creeping.mutable_creep()->add_tau_s(static_cast<float>(tau));
  }
  const double with_creep = mean_gain(creeping);
  std::printf("mean gain: %.3f without creep, %.3f aiming at F + 0.3 x(1 s)\n", plain, with_creep);
  EXPECT_GT(with_creep, plain + 0.05);
}

}  // namespace
}  // namespace ruffini::eval

namespace ruffini::eval {
namespace {

// The operator's re-tare inside DecodeStream (what `ruffini field-hours --retare` runs): validation seed 805 of
// the field scene, whose baseline goes stale at 1127.6 s under a 0.41 N press held at the wrist side, stays
// stale to the end without an operator, and recovers once the press is gone and a re-tare is accepted. The
// operator's requests are refused while the press is on (it is a real press), none is accepted under a press.
TEST(OperatorRetare, RecoversAStaleBaselineAndRefusesWhileThePressIsOn) {
  const twin::SkinTwin t(FieldScene().Patch().spec, FieldScene().effects, {5.5});
  twin::FieldProtocol fp;
  fp.duration_s = 1400.0;
  const dataset::Dataset d = Collect(t, FieldScene(), "field", 805, fp.rate_hz,
                                     [&](const twin::FrameSink& s) { return twin::RunField(t, FieldScene(), fp, 805, s); });
  decode::PipelineConfig cfg;
  cfg.baseline = decode::BaselineFor(FieldModel(), d.info.sample_rate_hz);
  // This hour went stale through finding 1(a) (a faint baseline error held frozen), which the field model's
  // faint refusal ends (ShippedModelField.RefusedFaintFramesEndTheLatchOfAPicometre); the re-tare must still
  // recover a stale patch: flag only here.
  cfg.faint_refuse = false;
  const decode::Pipeline<float> pipe(FieldModel(), FieldScene().Patch().spec, cfg);
  auto stale_s = [&](const StreamPredictions& p) {
    std::size_t n = 0;
    for (const std::uint8_t r : p.reason) n += r == static_cast<std::uint8_t>(decode::Reason::kBaselineStale) ? 1 : 0;
    return static_cast<double>(n) / d.info.sample_rate_hz;
  };
  const double alone = stale_s(DecodeStream(pipe, d));
  OperatorRetare op;
  ASSERT_TRUE(FieldModel().has_response());
  op.map = &FieldModel().response();
  const double with_operator = stale_s(DecodeStream(pipe, d, op));
  EXPECT_GT(alone, 250.0);           // measured: stale from 1127.6 s to the end (272 s)
  EXPECT_LT(with_operator, 120.0);   // measured: 91 s, ten requests refused while the press was on
  EXPECT_GE(op.requests, 2);
  EXPECT_GE(op.accepted, 1);
  EXPECT_GE(op.refused_pressing, 1);
  EXPECT_EQ(op.refused_pressing_nothing, 0);
  EXPECT_EQ(op.accepted_while_pressed, 0);
}

}  // namespace
}  // namespace ruffini::eval

namespace ruffini::eval {
namespace {
// A light press held at a weak site, then raised to 1.5x the threshold (2.25 N), on the field model: the
// raised press must read above the threshold at the end of its 5 s hold, faint frames refused or not. The
// refusal's first version let the baseline track refused frames: it absorbed the light press and read the
// raised one at 1.2 N (0.9 N held 120 s at (40 mm, 47.5 deg)), a STOP cleared under 2.25 N.
TEST(ShippedModelField, AHeldLightPressRaisedToAStopIsReadAboveTheThresholdFaintFramesRefusedOrNot) {
  const twin::SkinTwin t(FieldScene().Patch().spec, FieldScene().effects, {5.5});
  const auto& a = t.spec().indented_area;
  for (const patch::SurfacePoint at : {patch::SurfacePoint{a.y_min_mm + 25, a.r_min_deg + 20}, BetweenGratings(t)}) {
    for (const double light : {0.5, 0.9}) {
      const Press press = StaticPress(FieldScene(), at, light, 120.0, 2.25);
      double late[2] = {0, 0};
      std::size_t refused_frames = 0;
      for (const bool refuse : {false, true}) {
        decode::PipelineConfig cfg;
        cfg.faint_refuse = refuse;
        cfg.baseline = decode::BaselineFor(FieldModel(), 100.0);
        const decode::Pipeline<float> pipe(FieldModel(), FieldScene().Patch().spec, cfg);
        const auto p = DecodeStream(pipe, press.data);
        late[refuse] = MeanForce(p, press.hold_last - 300, press.hold_last);
        for (std::size_t k = press.hold_first; k < press.hold_last; ++k) refused_frames += refuse && !p.in_contact[k];
        std::printf("(%.1f mm, %.1f deg) %.1f N held 120 s, raised to 2.25 N, faint refused %d: last 3 s %.3f N\n",
                    at.y_mm, at.r_deg, light, refuse, late[refuse]);
        EXPECT_GT(late[refuse], 1.5) << light << " N at " << at.y_mm << " mm, refuse " << refuse;
      }
      std::printf("  %zu frames of the light hold refused\n", refused_frames);
    }
  }
}

// Issue 17: after a press the field cover's residual strain fades over seconds, and the networks' window lags
// the release: 50-250 mN read with nothing touching, most of the field's false contact frames (validation hours,
// docs/experiments/field-hours.md). The field model refuses them (PipelineConfig::release_*): from the release
// on, no frame the twin does not press is a contact, where the same streams without the rule have some. And
// nothing else changes: every frame is as without the rule, except frames read below release_refuse_n that
// become no contact; a second press 1 s after the release (2.25 N, 1.5x the threshold) is read as before.
TEST(ShippedModelField, AfterAReleaseTheCoversFadingStrainIsNoContactAndNothingElseChanges) {
  const twin::SkinTwin t(FieldScene().Patch().spec, FieldScene().effects, {5.5});
  const auto& a = t.spec().indented_area;
  const decode::PipelineConfig shipped;
  ASSERT_GT(shipped.release_refuse_n, 0.0) << "the rule ships on";
  ASSERT_GT(FieldModel().preprocessing().faint_refuse_below_n(), 0.0f) << "the field model refuses faint frames";
  std::size_t false_off = 0, false_on = 0, changed = 0;
  for (const patch::SurfacePoint at : {t.grating_centres()[5], BetweenGratings(t),
                                       patch::SurfacePoint{a.y_min_mm + 25, a.r_min_deg + 20},
                                       patch::SurfacePoint{a.y_max_mm - 10, a.r_max_deg - 15}}) {
    for (const double force : {0.6, 2.0}) {
      const Press press = StaticPress(FieldScene(), at, force, 20.0, 0.0, 2.25, 1.0);
      StreamPredictions p[2];
      for (const bool on : {false, true}) {
        decode::PipelineConfig cfg;
        if (!on) cfg.release_refuse_n = 0.0;
        cfg.baseline = decode::BaselineFor(FieldModel(), 100.0);
        const decode::Pipeline<float> pipe(FieldModel(), FieldScene().Patch().spec, cfg);
        p[on] = DecodeStream(pipe, press.data);
      }
      std::size_t here_off = 0, here_on = 0;
      for (std::size_t k = press.hold_last; k < press.data.size(); ++k) {
        if (press.data.true_force_n[k] != 0.0f) continue;
        here_off += p[0].valid[k] && p[0].in_contact[k];
        here_on += p[1].valid[k] && p[1].in_contact[k];
      }
      for (std::size_t k = 0; k < press.data.size(); ++k) {
        const bool same = p[0].valid[k] == p[1].valid[k] && p[0].in_contact[k] == p[1].in_contact[k] &&
                          p[0].force_n[k] == p[1].force_n[k];
        if (same) continue;
        ++changed;
        // The only change: a contact below release_refuse_n reported as none.
        EXPECT_TRUE(p[0].in_contact[k] && !p[1].in_contact[k] && p[0].force_n[k] < shipped.release_refuse_n &&
                    p[1].force_n[k] == 0.0f)
            << "frame " << k << " at (" << at.y_mm << ", " << at.r_deg << "): without " << p[0].in_contact[k] << " "
            << p[0].force_n[k] << " N, with " << p[1].in_contact[k] << " " << p[1].force_n[k] << " N";
      }
      double second = 0;
      for (std::size_t k = press.again_last - 300; k < press.again_last; ++k) second += p[1].force_n[k] / 300.0;
      std::printf("%.1f N at (%.1f mm, %.1f deg): false contact frames after the release %zu without the rule, %zu "
                  "with; the second press (2.25 N) reads %.2f N\n",
                  force, at.y_mm, at.r_deg, here_off, here_on, second);
      false_off += here_off;
      false_on += here_on;
    }
  }
  std::printf("false contact frames after the releases: %zu without the rule, %zu with; %zu frames changed\n", false_off,
              false_on, changed);
  EXPECT_GT(false_off, 20u) << "the streams no longer show what the rule is for";
  EXPECT_LE(false_on * 10, false_off) << "the rule removes at least 90 % of them";
  EXPECT_GT(changed, 0u);
}

// The rule stays within the force the hello declares refused: a release force above the faint refusal's is an
// error, not a silent refusal of frames the aggregator was told are reported.
TEST(ShippedModelField, ARefusalAfterAReleaseAboveTheFaintRefusalIsAnError) {
  decode::PipelineConfig cfg;
  cfg.baseline = decode::BaselineFor(FieldModel(), 100.0);
  cfg.release_refuse_n = FieldModel().preprocessing().faint_refuse_below_n() + 0.01;
  EXPECT_THROW(decode::Pipeline<float>(FieldModel(), FieldScene().Patch().spec, cfg), InputError);
  cfg.release_refuse_n = 0.2;
  cfg.release_tau_s = 0.0;
  EXPECT_THROW(decode::Pipeline<float>(FieldModel(), FieldScene().Patch().spec, cfg), InputError);
  cfg.release_tau_s = 10.0;
  cfg.release_peak_n = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(decode::Pipeline<float>(FieldModel(), FieldScene().Patch().spec, cfg), InputError);
  // Models that report every faint frame (the lab's) never refuse after a release either.
  cfg.release_peak_n = 0.3;
  cfg.release_refuse_n = 5.0;
  EXPECT_NO_THROW(decode::Pipeline<float>(Model(), PaperScene().Patch().spec, cfg));
}

// Review 11, finding 1: the rest file's 6 pm check let a 2.25-10 N press held through a decoder restart become the
// rest where no grating moves by 6 pm (13 % of the covered surface at 2.25 N). The pipeline now decodes the
// capture's difference from the rest reference and refuses the capture when the networks read it as a contact:
// a press held from before the decoder starts is never taken for the rest, at a grating or far from every
// grating, and once it is lifted the capture is the rest again, with no lasting phantom: a few frames of the lab
// model's gate noise, as after any release, and at one weak site 1.3 s of contact (the release of 1.6 N there
// moves no grating by the capture's 3 pm, so a capture may begin before the press has fully gone: the safe side). On the field cover the recapture waits until the residual strain
// of the press has faded (measured: up to 19 s after 2.25 N held at a grating). Without a reference the same
// stream is captured under the press (the hazard, so the test can tell). 5 N saturates the twin's gratings
// here (no capture either way), so the forces stay below it.
TEST(ShippedModelField, AStartUpCaptureUnderAHeldPressIsRefusedAgainstTheRest) {
  for (const bool field : {false, true}) {
    const twin::Scene& scene = field ? FieldScene() : PaperScene();
    const v1::DecoderModel& model = field ? FieldModel() : Model();
    const twin::SkinTwin t(scene.Patch().spec, scene.effects, {5.5});
    for (const patch::SurfacePoint at : {BetweenGratings(t), t.grating_centres()[9], patch::SurfacePoint{60.0, 114.0},
                                         patch::SurfacePoint{35.0, 26.0}}) {
      for (const double force : {1.6, 2.25}) {
        const Press press = StaticPress(scene, at, force, 20.0);
        Wavelengths rest{};
        for (std::size_t k = 0; k < 1000; ++k) {
          for (std::size_t i = 0; i < kGratings; ++i) rest[i] += press.data.wavelength_nm[k][i] / 1000.0;
        }
        std::size_t valid_in_hold[2] = {0, 0}, refused = 0, phantom = 0;
        long first_valid_after = -1;
        for (const bool with_rest : {false, true}) {
          decode::PipelineConfig cfg;
          cfg.baseline = decode::BaselineFor(model, 100.0);
          if (with_rest) cfg.baseline.rest_nm = rest;
          const decode::Pipeline<float> pipe(model, scene.Patch().spec, cfg);
          decode::Pipeline<float>::Data d(pipe);
          // The decoder starts 2 s into the hold.
          for (std::size_t k = press.hold_first + 200; k < press.data.size(); ++k) {
            Wavelengths wl;
            std::copy_n(press.data.wavelength_nm[k].begin(), kGratings, wl.begin());
            const auto o = pipe.Process(wl, press.data.flags[k], d);
            if (k < press.hold_last) valid_in_hold[with_rest] += o.valid;
            if (with_rest && k >= press.rest_first) {
              if (o.valid && first_valid_after < 0) first_valid_after = static_cast<long>(k - press.rest_first);
              phantom += k >= press.rest_first + 300 && o.in_contact;
            }
          }
          if (with_rest) refused = d.baseline().captures_refused();
        }
        std::printf("%s, %.2f N at (%.1f mm, %.1f deg) held from before the start: valid frames in the hold %zu "
                    "without the rest, %zu with (%zu captures refused); recaptured %.2f s after the release, %zu "
                    "contact frames from 3 s after it\n",
                    field ? "field" : "lab", force, at.y_mm, at.r_deg, valid_in_hold[0], valid_in_hold[1], refused,
                    static_cast<double>(first_valid_after) / 100.0, phantom);
        EXPECT_GT(valid_in_hold[0], 1000u) << "without the rest the press is captured (the hazard)";
        EXPECT_EQ(valid_in_hold[1], 0u) << force << " N at " << at.y_mm << " mm, " << at.r_deg << " deg";
        EXPECT_GE(refused, 5u);
        EXPECT_GE(first_valid_after, 0) << "never recaptured after the release";
        EXPECT_LT(first_valid_after, 2500) << "recaptured more than 25 s after the release";
        EXPECT_LE(phantom, 200u);
      }
    }
  }
}
}  // namespace
}  // namespace ruffini::eval
