// Review 6 of the field-separating re-tare judge (commit 4e97a65, decode/retare.h RetareConfig::separate_field, on in
// the decoder service). The risk: a re-tare accepted while something presses absorbs the press into the baseline.
// Each window here is the twin's strain for a held press on a shipped model's patch, plus a temperature field at the
// grating centres (each grating seeing it with the model's thermal_ratio, the sensitivity the common-mode removal
// assumes), the common mode removed as Retare::Feed removes it, judged as the service judges it (SeparateField) and
// as before (the plain judge). DISABLED_ tests document open problems (docs/reviews/retare-field.md); the others
// hold. Own binary: it counts allocations with a replaced global operator new (tests/common/alloc_counter.h).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <vector>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#include "../common/alloc_counter.h"
#pragma GCC diagnostic pop
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/decode/retare.h"
#include "ruffini/sim/scenario.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

namespace ruffini::decode {
namespace {

constexpr double kLevel = 0.75;  // half the cobot forearm's 1.5 N threshold (the service's min_force_n)

struct Rig {
  twin::Scene scene;
  std::size_t patch = 0;
  v1::DecoderModel model;
  std::unique_ptr<sim::MountedScene> mounts;
  std::unique_ptr<twin::SkinTwin> skin;
  BaselineConfig baseline;
  std::unique_ptr<RetareJudge> plain, sep;
  Rig(const std::string& scene_file, const std::string& name)
      : scene(twin::LoadScene(std::string(RUFFINI_SOURCE_DIR "/config/scenes/") + scene_file)) {
    while (scene.patches[patch].name != name) ++patch;
    model = LoadModel(scene.patches[patch].model_path);
    mounts = sim::LoadMounts(scene);
    skin = std::make_unique<twin::SkinTwin>(scene.patches[patch].spec, sim::EffectsFor(scene, mounts.get(), patch),
                                            std::vector<double>{scene.probe.radius_mm});
    baseline = BaselineFor(model, 100.0);
    plain = std::make_unique<RetareJudge>(model.response(), RetareConfig{kLevel});
    RetareConfig c{kLevel};
    c.SeparateField(spec());
    sep = std::make_unique<RetareJudge>(model.response(), c);
  }
  const patch::PatchSpec& spec() const { return scene.patches[patch].spec; }
  std::array<double, kGratings> Press(const std::vector<twin::Contact>& c, std::uint32_t* flags = nullptr) const {
    twin::Shifts sh{};
    std::uint32_t f = 0;
    skin->StrainShiftsPm(c, sh, f);
    if (flags != nullptr) *flags = f;
    return sh;
  }
  std::array<double, kGratings> Press(double y, double r, double f, std::uint32_t* flags = nullptr) const {
    return Press({twin::Contact{{y, r}, f, scene.probe}}, flags);
  }
  // A field (pm at a grating's centre for a grating of thermal_ratio 1) as the gratings see it.
  template <typename F>
  std::array<double, kGratings> Field(F&& f) const {
    std::array<double, kGratings> v{};
    for (std::size_t i = 0; i < kGratings; ++i) {
      v[i] = baseline.thermal_ratio[i] * f(spec().gratings[i].centre.y_mm, spec().gratings[i].centre.r_deg);
    }
    return v;
  }
  // As Retare::Feed hands the window to the judge: the common mode removed.
  ShiftsPm Window(const std::array<double, kGratings>& v) const {
    ShiftsPm s;
    for (std::size_t i = 0; i < kGratings; ++i) s[i] = static_cast<float>(v[i]);
    const float cm = MedianOfPresent(s, baseline.min_common_mode_gratings);
    if (baseline.common_mode && std::isfinite(cm)) {
      for (std::size_t i = 0; i < kGratings; ++i) s[i] -= baseline.thermal_ratio[i] * cm;
    }
    return s;
  }
};
const Rig& Cobot() {
  static const Rig r("cobot.yaml", "forearm_a");
  return r;
}
const Rig& FieldScene() {
  static const Rig r("forearm-field-gradient.yaml", "forearm");
  return r;
}

double Rad(double deg) { return deg * std::numbers::pi / 180.0; }
// The field scene's field (40 pm/C: 3 C end to end along, 2 C around), its warm side at r0_deg.
auto SceneField(double r0_deg) {
  return [r0_deg](double y, double r) { return -120.0 * (y / 150.0 - 0.5) + 40.0 * std::cos(Rad(r - r0_deg)); };
}
std::array<double, kGratings> Sum(std::array<double, kGratings> a, const std::array<double, kGratings>& b) {
  for (std::size_t i = 0; i < kGratings; ++i) a[i] += b[i];
  return a;
}
// The cobot scene's uncovered edge bands, where the re-tare's blindness is accepted.
bool InBands(double y, double r) { return y < 22.5 || y > 122.5 || r < 19.0 || r > 126.5; }

// Presses on a 5 mm x 5 deg grid at these forces (those the twin does not take over range: Feed refuses those),
// each with a field: how many the plain judge refuses ALONE (no field) and the separating judge accepts under the
// field. only_covered: count only places outside the edge bands.
struct Flips {
  int seen = 0, flips = 0;
  std::string worst;
  double worst_alone = 0;
};
Flips CountFlips(const Rig& rig, const std::array<double, kGratings>& field, std::initializer_list<double> forces,
                 bool only_covered) {
  Flips out;
  for (const double f : forces) {
    for (double y = 2.5; y < 150.0; y += 5.0) {
      for (double r = 2.5; r < 145.0; r += 5.0) {
        if (only_covered && InBands(y, r)) continue;
        std::uint32_t flags = 0;
        const auto p = rig.Press(y, r, f, &flags);
        if ((flags & (twin::kFlagSaturated | twin::kFlagPeakMissing)) != 0) continue;
        const RetareResult alone = rig.plain->Judge(rig.Window(p));
        if (alone.outcome != RetareOutcome::kPressing) continue;
        ++out.seen;
        const RetareResult b = rig.sep->Judge(rig.Window(Sum(p, field)));
        if (b.outcome != RetareOutcome::kAccepted) continue;
        ++out.flips;
        if (alone.force_n > out.worst_alone) {
          out.worst_alone = alone.force_n;
          out.worst = ::testing::PrintToString(f) + " N at (" + ::testing::PrintToString(y) + ", " + ::testing::PrintToString(r) +
                      "): plain alone " + ::testing::PrintToString(alone.force_n) + " N, separated under the field " +
                      ::testing::PrintToString(b.force_n) + " N";
        }
      }
    }
  }
  return out;
}

// The header says "a press with no field under it is never judged lighter than by the plain judge". It is, where
// the twin's press is not touch-shaped on the map (misfit > kTouchLikeMisfit: the edge bands, outside the map's
// grid): there only the field-separated reading counts, and it is lower. Measured: 14 of 3182 (cobot) and 14 of
// 3106 (field scene) places the plain judge refuses are accepted, the worst a 3 N press at (7.5, 137.5) the plain
// judge reads at 1.13 N and the separating one at 0.66 N. All in the edge bands.
TEST(RetareFieldReview, DISABLED_WithNoFieldAPressThePlainJudgeRefusesIsRefused) {
  for (const Rig* rig : {&Cobot(), &FieldScene()}) {
    const Flips f = CountFlips(*rig, {}, {0.75, 1.0, 1.5, 2.0, 3.0}, false);
    EXPECT_GT(f.seen, 1000);
    EXPECT_EQ(f.flips, 0) << rig->scene.name << ": of " << f.seen << " refused presses; worst " << f.worst;
  }
}

// The single worst case of the above, as a window: 3 N held at (7.5, 137.5) on the cobot forearm, no field.
TEST(RetareFieldReview, DISABLED_AThreeNewtonCornerPressWithNoFieldIsRefused) {
  const Rig& rig = Cobot();
  const ShiftsPm s = rig.Window(rig.Press(7.5, 137.5, 3.0));
  ASSERT_EQ(rig.plain->Judge(s).outcome, RetareOutcome::kPressing);
  const RetareResult r = rig.sep->Judge(s);
  EXPECT_EQ(r.outcome, RetareOutcome::kPressing) << r.force_n << " N at (" << r.y_mm << ", " << r.r_deg << ")";
}

// Under a first-order field (the kind the fit removes exactly, up to the gratings' thermal ratios), a press the
// plain judge refuses on its own is accepted at places across the patch: the field-separated reading alone counts
// there (the field makes the shifts not touch-shaped), and it reads low wherever the twin's press differs from the
// map's response in the field's span. Measured on the cobot forearm, 0.75-3 N on a 5 mm grid (3182 places refused
// alone): 54 (warm side R 0), 44 (R 72.5), 9 (R 250), 46 / 29 (along only, either sign), 99 / 79 (around only);
// the worst a 3 N press at (132.5, 107.5) the plain judge reads at 9.6 N alone.
TEST(RetareFieldReview, DISABLED_UnderAFirstOrderFieldAPressThePlainJudgeRefusesAloneIsRefused) {
  const Rig& rig = Cobot();
  for (const double r0 : {0.0, 72.5, 250.0}) {
    const Flips f = CountFlips(rig, rig.Field(SceneField(r0)), {0.75, 1.0, 1.5, 3.0}, false);
    EXPECT_EQ(f.flips, 0) << "warm side at R " << r0 << ": of " << f.seen << " refused presses; worst " << f.worst;
  }
  const Flips around = CountFlips(rig, rig.Field([](double, double r) { return 40.0 * std::cos(Rad(r)); }),
                                  {0.75, 1.0, 1.5, 3.0}, false);
  EXPECT_EQ(around.flips, 0) << "around only: of " << around.seen << " refused presses; worst " << around.worst;
}

// The same outside the edge bands (the covered area where no blindness is accepted): the cobot forearm under an
// around-only field (1 C amplitude, warm at R 0) accepts presses of 0.75-1.5 N the plain judge refuses alone,
// e.g. 1.5 N at (37.5, 22.5).
TEST(RetareFieldReview, DISABLED_OutsideTheEdgeBandsAPressThePlainJudgeRefusesAloneIsRefusedUnderAField) {
  const Rig& rig = Cobot();
  for (const double r0 : {0.0, 145.0}) {
    const Flips f = CountFlips(rig, rig.Field([r0](double, double r) { return 40.0 * std::cos(Rad(r - r0)); }),
                               {0.75, 1.0, 1.5, 2.0, 3.0}, true);
    EXPECT_GT(f.seen, 500);
    EXPECT_EQ(f.flips, 0) << "around only, warm at R " << r0 << ": of " << f.seen << " refused presses; worst "
                          << f.worst;
  }
}

// A press plus one grating's baseline error (the stuck patch's cause: a grating whose baseline kept part of a
// released press), with NO field: the error makes the shifts not touch-shaped, the plain reading is dropped, and the
// field fit takes part of the press. Outside the edge bands, 1-1.5 N presses the plain judge refuses (alone and with
// the error) are accepted.
TEST(RetareFieldReview, DISABLED_APressWithAOneGratingBaselineErrorAndNoFieldIsRefused) {
  const Rig& rig = Cobot();
  int seen = 0, flips = 0;
  std::string worst;
  double worst_alone = 0;
  for (const double f : {1.0, 1.5}) {
    for (double y = 22.5; y <= 122.5; y += 5.0) {
      for (double r = 22.5; r <= 122.5; r += 5.0) {
        const auto p = rig.Press(y, r, f);
        const RetareResult alone = rig.plain->Judge(rig.Window(p));
        if (alone.outcome != RetareOutcome::kPressing) continue;
        for (std::size_t g = 0; g < kGratings; ++g) {
          for (const double e : {-3.0, 3.0}) {
            auto q = p;
            q[g] += e;
            const ShiftsPm s = rig.Window(q);
            if (rig.plain->Judge(s).outcome != RetareOutcome::kPressing) continue;  // the plain judge's own miss
            ++seen;
            if (rig.sep->Judge(s).outcome != RetareOutcome::kAccepted) continue;
            ++flips;
            if (alone.force_n > worst_alone) {
              worst_alone = alone.force_n;
              worst = ::testing::PrintToString(f) + " N at (" + ::testing::PrintToString(y) + ", " +
                      ::testing::PrintToString(r) + "), grating " + ::testing::PrintToString(g) + " " +
                      ::testing::PrintToString(e) + " pm: plain alone " + ::testing::PrintToString(alone.force_n) +
                      " N, plain with the error " + ::testing::PrintToString(rig.plain->Judge(s).force_n) +
                      " N, separated " + ::testing::PrintToString(rig.sep->Judge(s).force_n) + " N";
            }
          }
        }
      }
    }
  }
  EXPECT_GT(seen, 1000);
  EXPECT_EQ(flips, 0) << "of " << seen << " windows; worst " << worst;
}

// The findings above through Retare::Feed and the pipeline as the decoder service runs them (the twin's noise, the
// tracker, the window's mean, head and tail), on the cobot forearm, outside the edge bands: a press held while an
// offset (a field, or one grating's baseline error) that came after the baseline stands on the peaks. The plain
// judge refuses each re-tare; the service's (SeparateField) accepts it, and the press is then in the baseline.
struct FeedCase {
  const char* what;
  double y_mm, r_deg, force_n;
  std::array<double, kGratings> offset_pm;  // on the peaks from 2 s before the press on (ramped in over 1 s)
};
RetareResult FeedRetare(const Rig& rig, const FeedCase& fc, bool separate) {
  PipelineConfig pc;
  pc.baseline = rig.baseline;
  Pipeline<float> pipe(rig.model, rig.spec(), pc);
  Pipeline<float>::Data data(pipe);
  twin::InterrogatorSim sim(*rig.skin, 7);
  RetareConfig rc{kLevel};
  if (separate) rc.SeparateField(rig.spec());
  Retare retare(&rig.model.response(), pipe.config().baseline, rc);
  std::uint64_t frame = 0;
  std::optional<RetareResult> result;
  auto step = [&](double force_n, double offset_share) -> PipelineOutput {
    twin::Shifts sh{};
    std::uint32_t flags = 0;
    const std::vector<twin::Contact> c{twin::Contact{{fc.y_mm, fc.r_deg}, force_n, rig.scene.probe}};
    rig.skin->StrainShiftsPm(force_n > 0 ? std::span<const twin::Contact>(c) : std::span<const twin::Contact>(), sh, flags);
    std::array<double, kGratings> wl{};
    sim.Read(static_cast<double>(frame++) / 100.0, sh, wl, flags);
    for (std::size_t i = 0; i < kGratings; ++i) wl[i] += offset_share * fc.offset_pm[i] * 1e-3;
    const PipelineOutput o = pipe.Process(wl, flags, data);
    if (retare.active()) {
      if (auto r = retare.Feed(wl, o, data.baseline())) result = r;
    }
    return o;
  };
  for (int k = 0; k < 200; ++k) step(0.0, 0.0);
  for (int k = 1; k <= 100; ++k) step(0.0, k / 100.0);
  for (int k = 0; k < 100; ++k) step(0.0, 1.0);
  for (int k = 1; k <= 30; ++k) step(fc.force_n * k / 30.0, 1.0);
  for (int k = 0; k < 50; ++k) step(fc.force_n, 1.0);
  float before = 0.0f;
  for (int k = 0; k < 50; ++k) before = std::max(before, step(fc.force_n, 1.0).force_n);
  EXPECT_TRUE(retare.Start());
  for (int k = 0; k < 1000 && !result; ++k) step(fc.force_n, 1.0);
  EXPECT_TRUE(result.has_value());
  if (result && result->outcome == RetareOutcome::kAccepted) {
    pipe.Retare(retare.baseline_nm(), data);
    float after = 0.0f;
    for (int k = 0; k < 100; ++k) after = std::max(after, step(fc.force_n, 1.0).force_n);
    ADD_FAILURE() << "accepted under the press: the networks read the press and the field at " << before
                  << " N before (the field reads as a phantom), " << after
                  << " N after the re-tare with the press still held (absorbed)";
  }
  return result.value_or(RetareResult{RetareOutcome::kInterrupted});
}

TEST(RetareFieldReview, DISABLED_ThroughThePipelineAHeldPressIsRefusedWhereThePlainJudgeRefusesIt) {
  const Rig& rig = Cobot();
  std::array<double, kGratings> error{};
  error[2] = -3.0;
  // (Two more of the judge-level cases, 1.5 N at (57.5, 117.5) with grating 2 3 pm low and 1.5 N at (122.5, 22.5)
  // under an around-only field warm at R 145, are refused through the pipeline: the window's noise lifts the
  // separated reading over the level there.)
  const FeedCase cases[] = {
      {"around-only field warm at R 0", 57.5, 122.5, 0.75,
       rig.Field([](double, double r) { return 40.0 * std::cos(Rad(r)); })},
      {"around-only field warm at R 0", 37.5, 22.5, 1.5,
       rig.Field([](double, double r) { return 40.0 * std::cos(Rad(r)); })},
  };
  for (const FeedCase& fc : cases) {
    SCOPED_TRACE(::testing::Message() << fc.force_n << " N at (" << fc.y_mm << ", " << fc.r_deg << "), " << fc.what);
    const RetareResult plain = FeedRetare(rig, fc, false), sep = FeedRetare(rig, fc, true);
    EXPECT_EQ(plain.outcome, RetareOutcome::kPressing) << RetareOutcomeName(plain.outcome) << " " << plain.force_n;
    EXPECT_EQ(sep.outcome, RetareOutcome::kPressing)
        << RetareOutcomeName(sep.outcome) << ", " << sep.force_n << " N at (" << sep.y_mm << ", " << sep.r_deg << ")";
  }
}

// The judge's own arithmetic, exactly: on a map whose every node holds one response g (the twin's at a place, per
// newton), shifts F g plus a first-order field are read at F, with every peak present and with peaks missing (the
// per-node path that removes the field over the present gratings only). This pins that path: using the every-peak
// field-free responses with peaks missing (a plausible slip) passes the commit's tests but not this one. (On the
// shipped maps the judge's largest force is over every node, and a node whose response is mostly field reads a map
// touch several times heavier than it is: conservative, but no place to check the arithmetic.)
TEST(RetareFieldReview, AOneResponseTouchUnderAFirstOrderFieldIsReadAtItsForceWithPeaksMissing) {
  const Rig& rig = FieldScene();
  RetareConfig c{kLevel};
  c.SeparateField(rig.spec());
  const double f = 1.5;
  int judged = 0;
  for (const auto& [y, r] : std::vector<std::pair<double, double>>{{30, 40}, {75, 72.5}, {60, 100}, {110, 55}}) {
    const auto g = rig.Press(y, r, 1.0);
    v1::ResponseMap map;
    map.set_y0_mm(0.0);
    map.set_r0_deg(0.0);
    map.set_dy_mm(50.0);
    map.set_dr_deg(50.0);
    map.set_ny(2);
    map.set_nr(2);
    for (int node = 0; node < 4; ++node) {
      for (const double v : g) map.add_g_pm_per_n(static_cast<float>(v));
    }
    const RetareJudge judge(map, c);
    for (const double scale : {1.0, 10.0}) {
      ShiftsPm s;
      for (std::size_t i = 0; i < kGratings; ++i) {
        const auto& at = rig.spec().gratings[i].centre;
        s[i] = static_cast<float>(f * g[i] + scale * SceneField(30.0)(at.y_mm, at.r_deg));
      }
      for (const std::vector<std::size_t>& missing : {std::vector<std::size_t>{}, {2, 9, 15}, {0, 5, 7, 11, 13}}) {
        ShiftsPm m = s;
        for (const std::size_t i : missing) m[i] = std::numeric_limits<float>::quiet_NaN();
        ++judged;
        EXPECT_NEAR(judge.Judge(m).force_n, f, 0.01 * f)
            << "g of (" << y << ", " << r << "), field x" << scale << ", " << missing.size() << " missing";
      }
    }
  }
  EXPECT_EQ(judged, 24);
}

// Nothing the judge is handed makes it crash or answer NaN: all missing, all infinite, huge, the largest floats,
// denormals. (All missing is accepted with 0 N, as by the plain judge: Retare::Feed cannot hand it over, its
// frames would be kTooManyMissing.)
TEST(RetareFieldReview, DegenerateShiftsGiveAnAnswerWithoutNaN) {
  const Rig& rig = Cobot();
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity(),
              big = std::numeric_limits<float>::max(), tiny = std::numeric_limits<float>::denorm_min();
  std::vector<ShiftsPm> cases;
  ShiftsPm s;
  for (const float v : {nan, inf, -inf, big, -big, tiny, 0.0f, 1e30f}) {
    s.fill(v);
    cases.push_back(s);
  }
  for (std::size_t i = 0; i < kGratings; ++i) s[i] = (i % 2 != 0) ? big : -big;
  cases.push_back(s);
  s.fill(0.0f);
  s[5] = 1e30f;
  cases.push_back(s);
  s[5] = big;
  s[6] = inf;
  s[7] = nan;
  cases.push_back(s);
  // 8 present, the rest NaN, and 7 present: both sides of kMinPeaksForField.
  s.fill(nan);
  for (std::size_t i = 0; i < 8; ++i) s[i] = 1e20f;
  cases.push_back(s);
  s[7] = nan;
  cases.push_back(s);
  for (const ShiftsPm& c : cases) {
    for (const RetareJudge* j : {rig.plain.get(), rig.sep.get()}) {
      const RetareResult r = j->Judge(c);
      EXPECT_FALSE(std::isnan(r.force_n)) << ::testing::PrintToString(c);
      EXPECT_TRUE(r.outcome == RetareOutcome::kAccepted || r.outcome == RetareOutcome::kPressing);
      EXPECT_EQ(r.outcome == RetareOutcome::kPressing, r.force_n >= kLevel);
    }
  }
  // A single grating far out is a press for both judges (no field is one grating).
  s.fill(0.0f);
  s[6] = 1e30f;
  EXPECT_EQ(rig.sep->Judge(s).outcome, RetareOutcome::kPressing);
  EXPECT_EQ(rig.plain->Judge(s).outcome, RetareOutcome::kPressing);
}

// Real-time safety: the separating Judge (every peak present, and with peaks missing, the per-node path) and
// Retare::Feed over a whole window allocate nothing.
TEST(RetareFieldReview, JudgeAndFeedDoNotAllocate) {
  const Rig& rig = Cobot();
  ShiftsPm all = rig.Window(Sum(rig.Press(75.0, 72.5, 1.0), rig.Field(SceneField(0.0)))), some = all;
  some[2] = some[9] = some[15] = std::numeric_limits<float>::quiet_NaN();
  double sink = 0;
  EXPECT_EQ(ruffini::testing::CountAllocations([&] { sink += rig.sep->Judge(all).force_n + rig.sep->Judge(some).force_n; }), 0);
  EXPECT_GT(sink, 0.0);

  PipelineConfig pc;
  pc.baseline = rig.baseline;
  Pipeline<float> pipe(rig.model, rig.spec(), pc);
  Pipeline<float>::Data data(pipe);
  twin::InterrogatorSim sim(*rig.skin, 7);
  RetareConfig rc{kLevel};
  rc.SeparateField(rig.spec());
  Retare retare(&rig.model.response(), pipe.config().baseline, rc);
  const std::vector<twin::Contact> press{twin::Contact{{75.0, 72.5}, 1.0, rig.scene.probe}};
  std::uint64_t frame = 0;
  auto step = [&](bool pressed, std::optional<RetareResult>* result) {
    twin::Shifts sh{};
    std::uint32_t flags = 0;
    rig.skin->StrainShiftsPm(pressed ? std::span<const twin::Contact>(press) : std::span<const twin::Contact>(), sh, flags);
    std::array<double, kGratings> wl{};
    sim.Read(static_cast<double>(frame++) / 100.0, sh, wl, flags);
    wl[4] = std::numeric_limits<double>::quiet_NaN();  // a missing peak: the judge's per-node path
    const PipelineOutput o = pipe.Process(wl, flags, data);
    if (result == nullptr) return 0L;
    return ruffini::testing::CountAllocations([&] { *result = retare.Feed(wl, o, data.baseline()); });
  };
  for (int k = 0; k < 200; ++k) step(false, nullptr);
  for (int k = 0; k < 30; ++k) step(true, nullptr);
  ASSERT_TRUE(retare.Start());
  std::optional<RetareResult> result;
  long allocations = 0;
  for (int k = 0; k < 1000 && !result; ++k) {
    allocations += step(true, &result);
  }
  ASSERT_TRUE(result.has_value());
  EXPECT_EQ(result->outcome, RetareOutcome::kPressing) << result->force_n;
  EXPECT_EQ(allocations, 0);
}

}  // namespace
}  // namespace ruffini::decode
