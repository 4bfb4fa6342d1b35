// Re-tare (issue 17, decode/retare.h): the way out of a stale baseline refuses while something presses (a
// real press on the twin, at the centre and at the edges, including one the networks read as nothing),
// accepts after the release, and a stale patch decodes again after it. Through the twin of the shipped
// cobot forearm (its response map) and decode::Pipeline as the decoder service configures it.
#include "ruffini/decode/retare.h"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "ruffini/decode/model_io.h"
#include "ruffini/error.h"
#include "ruffini/sim/scenario.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

namespace ruffini::decode {
namespace {

constexpr double kRate = 100.0;
constexpr double kLevel = 0.75;  // half the cobot forearm's 1.5 N threshold

struct Shipped {
  twin::Scene scene;
  std::size_t patch = 0;
  v1::DecoderModel model;
  std::unique_ptr<sim::MountedScene> mounts;
  std::unique_ptr<twin::SkinTwin> skin;
  explicit Shipped(const std::string& scene_path = RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml",
                   const std::string& patch_name = "forearm_a")
      : scene(twin::LoadScene(scene_path)) {
    while (scene.patches[patch].name != patch_name) ++patch;
    model = LoadModel(scene.patches[patch].model_path);
    mounts = sim::LoadMounts(scene);
    skin = std::make_unique<twin::SkinTwin>(scene.patches[patch].spec, sim::EffectsFor(scene, mounts.get(), patch),
                                            std::vector<double>{scene.probe.radius_mm});
  }
};
const Shipped& Get() {
  static const Shipped s;
  return s;
}

// One stream: the twin under a probe (or none), the interrogator's noise, the service's pipeline, an
// optional error on one grating's peak (pm) standing for a baseline that kept a released press.
class Stream {
 public:
  explicit Stream(double max_frozen_s = 300.0, std::uint64_t seed = 7, const Shipped& shipped = Get())
      : s_(shipped), pipe_(s_.model, s_.scene.patches[s_.patch].spec, Config(max_frozen_s, shipped)), data_(pipe_),
        sim_(*s_.skin, seed), retare_(&s_.model.response(), pipe_.config().baseline, RetareConfig{kLevel}) {}

  static PipelineConfig Config(double max_frozen_s, const Shipped& shipped = Get()) {
    PipelineConfig c;
    c.baseline = BaselineFor(shipped.model, kRate);
    c.baseline.max_frozen_s = max_frozen_s;
    // These tests make a patch stale with a grating left a fraction of a pm off (finding 1(a)); the field
    // model refuses such faint frames and no longer latches on them (Preprocessing.faint_refuse_below_n), yet
    // a re-tare must still recover a stale baseline, however it came about: flag only here.
    c.faint_refuse = false;
    return c;
  }

  // n frames with the probe at (y, r) pressing force_n (0: nothing touches); error_pm on grating `grating`.
  PipelineOutput Run(int n, double y_mm = 75.0, double r_deg = 72.5, double force_n = 0.0) {
    PipelineOutput o;
    for (int k = 0; k < n; ++k) o = Step(y_mm, r_deg, force_n);
    return o;
  }
  PipelineOutput Step(double y_mm, double r_deg, double force_n, std::uint32_t extra_flags = 0) {
    const double t = static_cast<double>(frame_++) / kRate;
    twin::Shifts sh{};
    std::uint32_t flags = 0;
    std::vector<twin::Contact> contacts;
    if (force_n > 0) contacts.push_back(twin::Contact{{y_mm, r_deg}, force_n, s_.scene.probe});
    s_.skin->StrainShiftsPm(contacts, sh, flags);
    std::array<double, kGratings> wl{};
    sim_.Read(t, sh, wl, flags);
    if (std::isfinite(wl[error_grating_])) wl[error_grating_] += error_pm_ * 1e-3;
    last_wl_ = wl;
    const PipelineOutput o = pipe_.Process(wl, flags | extra_flags, data_);
    if (retare_.active()) {
      if (auto r = retare_.Feed(wl, o, data_.baseline())) {
        result_ = *r;
        if (r->outcome == RetareOutcome::kAccepted) pipe_.Retare(retare_.baseline_nm(), data_);
      }
    }
    return o;
  }
  // Asks for a re-tare and runs frames until it ends; the probe as given.
  RetareResult Retare(double y_mm = 75.0, double r_deg = 72.5, double force_n = 0.0) {
    result_.reset();
    EXPECT_TRUE(retare_.Start());
    for (int k = 0; k < 1000 && !result_; ++k) Step(y_mm, r_deg, force_n);
    EXPECT_TRUE(result_.has_value());
    return result_.value_or(RetareResult{RetareOutcome::kInterrupted});
  }
  void SetError(std::size_t grating, double pm) {
    error_grating_ = grating;
    error_pm_ = pm;
  }
  // Ramps the probe from 0 to force_n over 0.3 s (at (y, r)), returns the largest force decoded.
  float Ramp(double y_mm, double r_deg, double force_n) {
    float peak = 0.0f;
    for (int k = 1; k <= 30; ++k) peak = std::max(peak, Step(y_mm, r_deg, force_n * k / 30.0).force_n);
    return peak;
  }
  // Ramp, then 0.5 s of hold: the largest force decoded.
  float Press(double y_mm, double r_deg, double force_n) {
    float peak = Ramp(y_mm, r_deg, force_n);
    for (int k = 0; k < 50; ++k) peak = std::max(peak, Step(y_mm, r_deg, force_n).force_n);
    return peak;
  }
  decode::Retare& retare() { return retare_; }
  [[nodiscard]] const std::optional<RetareResult>& last() const { return result_; }
  Pipeline<float>::Data& data() { return data_; }

 private:
  const Shipped& s_;
  Pipeline<float> pipe_;
  Pipeline<float>::Data data_;
  twin::InterrogatorSim sim_;
  decode::Retare retare_;
  std::optional<RetareResult> result_;
  std::uint64_t frame_ = 0;
  std::size_t error_grating_ = 15;
  double error_pm_ = 0.0;
  std::array<double, kGratings> last_wl_{};
};

double MaxShiftPm(double y_mm, double r_deg, double force_n) {
  twin::Shifts sh{};
  std::uint32_t flags = 0;
  const std::vector<twin::Contact> c{twin::Contact{{y_mm, r_deg}, force_n, Get().scene.probe}};
  Get().skin->StrainShiftsPm(c, sh, flags);
  double m = 0;
  for (double v : sh) m = std::max(m, std::abs(v));
  return m;
}

struct Place {
  double y_mm, r_deg, force_n;
  float decoded_below_n;  // the networks read the press below this (the ones they read as light)
};

// A held press at least the level: at the centre and at three edges, two of which the networks read at a
// fraction of their force. The re-tare refuses, names a force at least the level, and the baseline is as
// before. After the release it is accepted.
TEST(Retare, RefusesWhileARealPressIsHeldAcceptsAfterTheRelease) {
  const Place places[] = {{75.0, 72.5, 0.8, 10.0f}, {134.8, 70.6, 0.8, 10.0f}, {127.7, 63.6, 1.0, 0.35f},
                          {16.0, 30.0, 1.5, 0.45f}};
  for (const Place& p : places) {
    SCOPED_TRACE(testing::Message() << p.force_n << " N at (" << p.y_mm << ", " << p.r_deg << ")");
    Stream st;
    st.Run(150);
    float decoded = st.Ramp(p.y_mm, p.r_deg, p.force_n);
    for (int k = 0; k < 100; ++k) decoded = std::max(decoded, st.Step(p.y_mm, p.r_deg, p.force_n).force_n);
    EXPECT_LT(decoded, p.decoded_below_n);
    const Wavelengths before = st.data().baseline().baseline_nm();
    const RetareResult refused = st.Retare(p.y_mm, p.r_deg, p.force_n);
    EXPECT_EQ(refused.outcome, RetareOutcome::kPressing);
    EXPECT_GE(refused.force_n, kLevel);
    EXPECT_EQ(refused.frames, st.data().baseline().config().capture_frames);
    // Frozen under the press, the baseline only follows the common mode (noise here): the press is not in it.
    for (std::size_t i = 0; i < kGratings; ++i) EXPECT_NEAR(st.data().baseline().baseline_nm()[i], before[i], 0.3e-3) << i;
    st.Run(100);  // released (the probe gone), 1 s
    const RetareResult accepted = st.Retare();
    EXPECT_EQ(accepted.outcome, RetareOutcome::kAccepted) << accepted.force_n << " N at (" << accepted.y_mm << ", "
                                                          << accepted.r_deg << ")";
    EXPECT_LT(accepted.force_n, kLevel);
  }
}

// The stuck patch of the field review: a grating 0.8 pm low after a release (its baseline kept the press)
// reads as a phantom touch, the gate never closes, the baseline goes stale and stays stale. A re-tare while a
// press is held is refused and leaves it stale; after the release it is accepted, the frames are valid with
// no contact, and a press after it decodes (it was not absorbed).
TEST(Retare, AStaleBaselineRecoversAfterTheReleaseNotDuringThePress) {
  Stream st(3.0);
  st.Run(150);
  EXPECT_GT(st.Press(75.0, 72.5, 1.0), 0.8f);
  st.Run(100);
  st.SetError(15, -0.8);
  PipelineOutput o = st.Run(600);  // 6 s: frozen past max_frozen_s (3 s)
  ASSERT_EQ(o.reason, Reason::kBaselineStale);
  o = st.Run(1000);  // it stays stale: nothing ends it by itself
  ASSERT_EQ(o.reason, Reason::kBaselineStale);

  st.Ramp(75.0, 72.5, 1.0);
  const RetareResult refused = st.Retare(75.0, 72.5, 1.0);
  EXPECT_EQ(refused.outcome, RetareOutcome::kPressing);
  EXPECT_EQ(st.Step(75.0, 72.5, 1.0).reason, Reason::kBaselineStale);

  st.Run(100);
  const RetareResult accepted = st.Retare();
  ASSERT_EQ(accepted.outcome, RetareOutcome::kAccepted) << accepted.force_n;
  EXPECT_EQ(st.data().baseline().state(), BaselineTracker::State::kTracking);
  EXPECT_FALSE(st.data().baseline().stale());
  int valid = 0, contact = 0;
  for (int k = 0; k < 200; ++k) {
    o = st.Step(75.0, 72.5, 0.0);
    valid += o.valid ? 1 : 0;
    contact += o.in_contact ? 1 : 0;
  }
  EXPECT_EQ(valid, 200);
  EXPECT_EQ(contact, 0);
  EXPECT_GT(st.Press(75.0, 72.5, 1.0), 0.8f) << "the press after the re-tare decodes as before";
}

// The shipped forearm models (the paper scene's and the field scene's) carry a response map with limit 0 (no
// two-touch check: docs/decoders.md "Two touches"), so their decoders can judge a re-tare: the stuck patch
// above, in each model's own scene, is refused under a press and recovers after the release.
TEST(Retare, TheShippedForearmModelsJudgeAReTare) {
  for (const char* scene : {"forearm.yaml", "forearm-field.yaml"}) {
    SCOPED_TRACE(scene);
    const Shipped shipped(std::string(RUFFINI_SOURCE_DIR "/config/scenes/") + scene, "forearm");
    ASSERT_TRUE(shipped.model.has_response()) << shipped.scene.patches[shipped.patch].model_path;
    EXPECT_EQ(shipped.model.response().multiple_misfit(), 0.0);
    Stream st(3.0, 7, shipped);
    st.Run(150);
    EXPECT_GT(st.Press(75.0, 72.5, 1.0), 0.8f);
    st.Run(100);
    st.SetError(15, -0.8);
    ASSERT_EQ(st.Run(600).reason, Reason::kBaselineStale);
    st.Ramp(75.0, 72.5, 1.0);
    EXPECT_EQ(st.Retare(75.0, 72.5, 1.0).outcome, RetareOutcome::kPressing);
    st.Run(100);
    const RetareResult accepted = st.Retare();
    ASSERT_EQ(accepted.outcome, RetareOutcome::kAccepted) << accepted.force_n;
    EXPECT_FALSE(st.data().baseline().stale());
    EXPECT_FALSE(st.Run(100).in_contact);
  }
}

// A press that starts inside the window (here at an edge, where 1.5 N moves no grating by the 3 pm capture
// tolerance, so the window is not `moving`) is judged at its force at the window's end, not at the window's
// mean (a quarter of it): refused. (Found on the field hours: docs/experiments/retare.md.)
TEST(Retare, APressStartingInsideTheWindowIsRefused) {
  const double y = 16.0, r = 30.0, f = 1.5;
  EXPECT_LT(MaxShiftPm(y, r, f), 3.0);
  Stream st;
  st.Run(150);
  ASSERT_TRUE(st.retare().Start());
  const int n = st.data().baseline().config().capture_frames;
  for (int k = 0; k < n && st.retare().active(); ++k) {
    const int into = k - (n - 25);  // the last 25 frames: a 50 ms ramp, then held
    st.Step(y, r, into < 0 ? 0.0 : f * std::min(1.0, (into + 1) / 5.0));
  }
  ASSERT_TRUE(st.last().has_value());
  EXPECT_NE(st.last()->outcome, RetareOutcome::kAccepted) << st.last()->force_n;
}

// What the rule lets through, stated: at a place the gratings barely see, a press moves no grating by
// min_shift_pm, and the re-tare absorbs it. There the networks read it as almost nothing too (the skin is
// blind there: docs/safety.md "Re-tare").
TEST(Retare, APressTheGratingsBarelySeeIsAbsorbedAndIsBelowTheMinimumShift) {
  const double y = 134.4, r = 58.6, f = 1.5;
  EXPECT_LT(MaxShiftPm(y, r, f), RetareConfig{}.min_shift_pm);
  Stream st;
  st.Run(150);
  float decoded = st.Ramp(y, r, f);
  for (int k = 0; k < 100; ++k) decoded = std::max(decoded, st.Step(y, r, f).force_n);
  EXPECT_LT(decoded, 0.2f);
  EXPECT_EQ(st.Retare(y, r, f).outcome, RetareOutcome::kAccepted);
}

TEST(Retare, EveryOtherRefusalHasItsReason) {
  {  // a ramp during the window: moving (the capture tolerance)
    Stream st;
    st.Run(150);
    ASSERT_TRUE(st.retare().Start());
    for (int k = 0; k < 100 && st.retare().active(); ++k) st.Step(75.0, 72.5, 1.0 * k / 100.0);
    ASSERT_TRUE(st.last().has_value());
    EXPECT_EQ(st.last()->outcome, RetareOutcome::kMoving);
    EXPECT_GT(st.last()->motion_pm, st.data().baseline().config().capture_tolerance_pm);
  }
  Stream st;
  // Still capturing at start-up: nothing to re-tare.
  st.Run(10);
  EXPECT_EQ(st.Retare().outcome, RetareOutcome::kNoBaseline);
  st.Run(150);
  // Twice at once: the second is refused, the first goes on.
  ASSERT_TRUE(st.retare().Start());
  EXPECT_FALSE(st.retare().Start());
  EXPECT_TRUE(st.retare().active());
  // The stream breaks: interrupted, nothing changed.
  const auto interrupted = st.retare().Interrupt();
  ASSERT_TRUE(interrupted.has_value());
  EXPECT_EQ(interrupted->outcome, RetareOutcome::kInterrupted);
  EXPECT_FALSE(st.retare().Interrupt().has_value());
  // A saturated frame in the window: over range, which is a press.
  ASSERT_TRUE(st.retare().Start());
  st.Step(75.0, 72.5, 0.0, Pipeline<float>::kSourceSaturated);
  EXPECT_FALSE(st.retare().active());
  ASSERT_TRUE(st.last().has_value());
  EXPECT_EQ(st.last()->outcome, RetareOutcome::kPressing);
  // A model without a response map cannot judge: refused.
  Retare no_map(nullptr, Stream::Config(300.0).baseline);
  ASSERT_TRUE(no_map.Start());
  const auto r = no_map.Feed(Wavelengths{}, PipelineOutput{}, st.data().baseline());
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->outcome, RetareOutcome::kNoMap);
  EXPECT_THROW(Retare(nullptr, Stream::Config(300.0).baseline, RetareConfig{0.0}), InputError);
  EXPECT_THROW(Retare(nullptr, Stream::Config(300.0).baseline, RetareConfig{0.75, -1.0}), InputError);
}

TEST(Retare, OutcomeNamesAreDistinct) {
  std::set<std::string_view> names;
  for (std::size_t i = 0; i < kRetareOutcomeCount; ++i) names.insert(RetareOutcomeName(static_cast<RetareOutcome>(i)));
  EXPECT_EQ(names.size(), kRetareOutcomeCount);
  EXPECT_EQ(names.count("unknown"), 0u);
}

}  // namespace
}  // namespace ruffini::decode
