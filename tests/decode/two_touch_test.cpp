// Two touches on one patch (issue 16): the decoder never reports two touches as one confident place. Through
// the twin, the Hyperion bytes, the ingest codec, link::Monitor and the shipped cobot forearm model
// (tests/decode/hard_press.h), and the TouchCheck alone on a synthetic response map.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "ruffini/decode/touches.h"
#include "ruffini/error.h"
#include "two_touch.h"

namespace ruffini::testing {
namespace {

struct Shipped {
  twin::Scene scene = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml");
  std::size_t patch = 0;  // forearm_a
  v1::DecoderModel model;
  std::size_t upper = 0;  // upper_arm_a, and the file the scene names for it (kept here: a rig holds a reference)
  v1::DecoderModel upper_model;
  Shipped() {
    while (scene.patches[patch].name != "forearm_a") ++patch;
    model = decode::LoadModel(scene.patches[patch].model_path);
    while (scene.patches[upper].name != "upper_arm_a") ++upper;
    upper_model = decode::LoadModel(scene.patches[upper].model_path);
  }
};
const Shipped& Get() {
  static const Shipped s;
  return s;
}

// 2 N on FBG 1 and 2 N on FBG 13, 82 mm apart: the paper networks alone read about 2.8 N at one place between
// them. Every located frame of the hold is flagged and holds both touches within 3 sigma. The force stays the
// networks' reading (touches.h says why), so the stop rule is the same with or without the check.
TEST(TwoTouches, TwoTouchesFarApartAreFlaggedAndCovered) {
  const Shipped& s = Get();
  ASSERT_TRUE(s.model.has_response()) << "the shipped forearm model carries its response map";
  HardPressRig rig(s.scene, s.patch, s.model);
  const ProbeAt p[2] = {{24.0, 42.5, 2.0}, {100.0, 102.5, 2.0}};
  const PressOutcome o = rig.Press(std::span<const ProbeAt>(p, 2), 1.5);
  const PressJudgement j = JudgePress(o, p, MmPerDeg(s.scene, s.patch));
  ASSERT_GT(j.located, 100);
  EXPECT_EQ(j.confident_wrong, 0) << j.flagged << " of " << j.located << " flagged";
  EXPECT_GE(j.flagged, j.located * 9 / 10);
}

// The same press, one touch: never flagged, placed as before.
TEST(TwoTouches, OneTouchIsNotFlagged) {
  const Shipped& s = Get();
  HardPressRig rig(s.scene, s.patch, s.model);
  for (const ProbeAt& p : {ProbeAt{24.0, 42.5, 2.0}, ProbeAt{75.0, 72.5, 1.0}, ProbeAt{100.0, 102.5, 3.0}}) {
    const PressOutcome o = rig.Press(std::span<const ProbeAt>(&p, 1), 1.5);
    const PressJudgement j = JudgePress(o, std::span<const ProbeAt>(&p, 1), MmPerDeg(s.scene, s.patch));
    ASSERT_GT(j.located, 100);
    EXPECT_EQ(j.flagged, 0) << p.y_mm << ", " << p.r_deg;
  }
}

// The check never lowers the force, and leaves a light press alone: frame by frame, a light press between
// two rows (where a misfit is likeliest) reads the same with and without the response map, and a pair reads
// at least as much with it.
TEST(TwoTouches, TheCheckNeverLowersTheForceAndLeavesALightPressAlone) {
  const Shipped& s = Get();
  v1::DecoderModel bare = s.model;
  bare.clear_response();
  HardPressRig with(s.scene, s.patch, s.model), without(s.scene, s.patch, bare);
  const ProbeAt light{75.0, 72.5, 1.0};
  const PressOutcome a = with.Press(std::span<const ProbeAt>(&light, 1), 1.5), b = without.Press(std::span<const ProbeAt>(&light, 1), 1.5);
  ASSERT_EQ(a.hold.size(), b.hold.size());
  for (std::size_t k = 0; k < a.hold.size(); ++k) ASSERT_EQ(a.hold[k].force_n, b.hold[k].force_n) << k;
  EXPECT_EQ(a.max_force_n, b.max_force_n);
  EXPECT_FALSE(a.stops());
  const ProbeAt pair[2] = {{24.0, 42.5, 2.0}, {100.0, 102.5, 2.0}};
  const PressOutcome c = with.Press(std::span<const ProbeAt>(pair, 2), 1.5), d = without.Press(std::span<const ProbeAt>(pair, 2), 1.5);
  ASSERT_EQ(c.hold.size(), d.hold.size());
  for (std::size_t k = 0; k < c.hold.size(); ++k) ASSERT_GE(c.hold[k].force_n, d.hold[k].force_n) << k;
}

// A second touch must not hide the first one's STOP (the adversarial review's finding, issue 16). 2.88 N and
// 1.82 N, 70 mm apart (a validation pair, seed 2000): the networks read the pair as one touch they were never
// shown, at most 0.69 N. With the multiple frames' force rule (PipelineConfig::multi_force, the default) the
// pair fit's larger touch stops the robot; with the networks' force alone it does not.
TEST(TwoTouches, ASecondTouchDoesNotHideTheFirstOnesStop) {
  const Shipped& s = Get();
  const ProbeAt pair[2] = {{98.7, 33.5, 2.88}, {31.1, 62.3, 1.82}};
  HardPressRig rig(s.scene, s.patch, s.model);
  const PressOutcome o = rig.Press(std::span<const ProbeAt>(pair, 2), 1.5);
  EXPECT_TRUE(o.stops()) << "largest reported " << o.max_force_n << " N";
  HardPressRig old(s.scene, s.patch, s.model);
  old.pipeline_config().multi_force = decode::PipelineConfig::MultiForce::kNetworks;
  const PressOutcome n = old.Press(std::span<const ProbeAt>(pair, 2), 1.5);
  EXPECT_FALSE(n.stops()) << "the networks alone now stop this pair (" << n.max_force_n
                          << " N): the test no longer shows the rule's effect; pick another pair";
}

// Review 10 finding 2, on the covered surface as the scene's bands now leave it (Y 25-120 mm, R 23-122.5 deg, the
// y30-r123 band cut out): 50 N and 200 N at its four corners, each with a light touch held where a light touch
// hides a weaker press (docs/experiments/pair.md), stop on every kind of model: the scene's upper_arm_a and
// forearm_a files (the two-touch check on, since stop 33 on the upper arms too) and forearm.rmodel (the same
// networks, no check) on upper_arm_a. Each light touch is first pressed alone and must not stop (review 13: a 1 N
// touch at Y 130 R 70 stops by itself, which would pass any pair with it).
TEST(TwoTouches, ALightTouchDoesNotHideFiftyOrTwoHundredNewtonsAtTheCoveredCorners) {
  const Shipped& s = Get();
  const ProbeAt lights[3] = {{90.0, 70.0, 0.4}, {130.0, 70.0, 0.4}, {60.0, 100.0, 0.4}};
  const std::pair<const char*, std::string> cases[3] = {
      {"upper_arm_a", ""}, {"forearm_a", ""}, {"upper_arm_a", RUFFINI_SOURCE_DIR "/config/models/forearm.rmodel"}};
  for (const auto& [name, file] : cases) {
    std::size_t patch = 0;
    while (s.scene.patches[patch].name != name) ++patch;
    const std::string path = file.empty() ? s.scene.patches[patch].model_path : file;
    const v1::DecoderModel model = decode::LoadModel(path);
    HardPressRig rig(s.scene, patch, model);
    for (const ProbeAt& light : lights) {
      const PressOutcome alone = rig.Press(std::span<const ProbeAt>(&light, 1), 1.5);
      ASSERT_FALSE(alone.stops()) << name << " (" << path << "): the light touch at Y " << light.y_mm << " R "
                                  << light.r_deg << " stops alone (" << alone.max_force_n
                                  << " N): it cannot show a hard press kept";
    }
    for (const auto& [y, r] : {std::pair{25.5, 23.5}, std::pair{119.5, 23.5}, std::pair{119.5, 122.0}, std::pair{35.5, 122.0}}) {
      for (double force : {50.0, 200.0}) {
        for (const ProbeAt& light : lights) {
          const ProbeAt two[2] = {{y, r, force}, light};
          const PressOutcome o = rig.Press(std::span<const ProbeAt>(two, 2), 1.5);
          EXPECT_TRUE(o.stops()) << name << " (" << path << "): " << force << " N at Y " << y << " R " << r << " with "
                                 << light.force_n << " N at Y " << light.y_mm << " R " << light.r_deg
                                 << ": largest reported " << o.max_force_n << " N";
        }
      }
    }
  }
}

// Stop 33 (docs/experiments/pair.md): the upper arms' file carries the two-touch check (the response map's limit
// 0.07, as the forearm files), which keeps the stop review 13's worst pair hid: 5 N at the covered corner Y 119.5
// R 23.5 with 0.4 N held at Y 130 R 70. The same networks without the check (forearm.rmodel, which the upper arms
// named before) read that pair at most 0.59 N: no stop. Both touches alone behave (the hard press stops, the light
// one does not), on both files.
TEST(TwoTouches, TheUpperArmsCheckKeepsAFiveNewtonStopALightTouchHidWithoutIt) {
  const Shipped& s = Get();
  const std::size_t patch = s.upper;
  const v1::DecoderModel& checked = s.upper_model;
  ASSERT_TRUE(checked.has_response()) << s.scene.patches[patch].model_path;
  EXPECT_GT(checked.response().multiple_misfit(), 0.0) << "the upper arms' file must check for two touches";
  const v1::DecoderModel unchecked = decode::LoadModel(RUFFINI_SOURCE_DIR "/config/models/forearm.rmodel");
  const ProbeAt hard{119.5, 23.5, 5.0}, light{130.0, 70.0, 0.4};
  const ProbeAt two[2] = {hard, light};
  for (const v1::DecoderModel* m : {&checked, &unchecked}) {
    HardPressRig rig(s.scene, patch, *m);
    ASSERT_TRUE(rig.Press(std::span<const ProbeAt>(&hard, 1), 1.5).stops()) << "the hard press alone must stop";
    ASSERT_FALSE(rig.Press(std::span<const ProbeAt>(&light, 1), 1.5).stops()) << "the light touch alone must not stop";
  }
  const PressOutcome with_check = HardPressRig(s.scene, patch, checked).Press(std::span<const ProbeAt>(two, 2), 1.5);
  EXPECT_TRUE(with_check.stops()) << "largest reported " << with_check.max_force_n << " N";
  const PressOutcome without = HardPressRig(s.scene, patch, unchecked).Press(std::span<const ProbeAt>(two, 2), 1.5);
  EXPECT_FALSE(without.stops()) << "forearm.rmodel now stops this pair (" << without.max_force_n
                                << " N): the test no longer shows the check's effect; pick another pair";
}

// Since stop 35 the field scene's upper arms (each its own cast and calibrated file) check for two touches as the
// lab's do: a response map refitted from the validation recording (cast 0) with the limit 0.07. The same pair as
// above, on each field cast: with the check it stops, and the same file with the limit set to 0 (no check: what the
// field files were until stop 35) reads 0.6-0.7 N (docs/experiments/pair.md, section 5).
TEST(TwoTouches, TheFieldScenesUpperArmsCheckForTwoTouchesToo) {
  const twin::Scene field = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/cobot-field.yaml");
  const ProbeAt hard{119.5, 23.5, 5.0}, light{130.0, 70.0, 0.4};
  const ProbeAt two[2] = {hard, light};
  int upper_arms = 0;
  for (std::size_t patch = 0; patch < field.patches.size(); ++patch) {
    if (field.patches[patch].name.rfind("upper_arm", 0) != 0) continue;
    ++upper_arms;
    SCOPED_TRACE(field.patches[patch].name);
    const v1::DecoderModel checked = decode::LoadModel(field.patches[patch].model_path);
    ASSERT_TRUE(checked.has_response()) << field.patches[patch].model_path;
    EXPECT_DOUBLE_EQ(checked.response().multiple_misfit(), Get().model.response().multiple_misfit())
        << "the field upper arms' limit is the lab files' (chosen on validation, docs/experiments/two-touches.md)";
    v1::DecoderModel unchecked = checked;
    unchecked.mutable_response()->set_multiple_misfit(0.0);
    for (const v1::DecoderModel* m : std::initializer_list<const v1::DecoderModel*>{&checked, &unchecked}) {
      HardPressRig rig(field, patch, *m);
      ASSERT_TRUE(rig.Press(std::span<const ProbeAt>(&hard, 1), 1.5).stops()) << "the hard press alone must stop";
      ASSERT_FALSE(rig.Press(std::span<const ProbeAt>(&light, 1), 1.5).stops()) << "the light touch alone must not stop";
    }
    const PressOutcome with_check = HardPressRig(field, patch, checked).Press(std::span<const ProbeAt>(two, 2), 1.5);
    EXPECT_TRUE(with_check.stops()) << "largest reported " << with_check.max_force_n << " N";
    const PressOutcome without = HardPressRig(field, patch, unchecked).Press(std::span<const ProbeAt>(two, 2), 1.5);
    EXPECT_FALSE(without.stops()) << "without the check this pair now stops (" << without.max_force_n
                                  << " N): the test no longer shows the check's effect; pick another pair";
  }
  EXPECT_EQ(upper_arms, 2);
}

// OPEN (review 10 finding 2, docs/experiments/pair.md): at the covered corner Y 119.5 R 23.5, 5 N alone stops;
// with a 0.4 N touch held at Y 110 R 70 (alone: no stop) the upper arms' file (the check on) reads it at most 1.07 N,
// every hold frame flagged `multiple`. The networks know one touch, and the response map sees a press there as a
// lighter touch nearer the gratings, so the fitted force stays below the threshold. With other noise seeds the
// pair stops on 2 of 10 (review 14): enable it when a decoder keeps this stop on every seed (and sweep them).
TEST(TwoTouches, DISABLED_ALightTouchHidesFiveNewtonsAtACoveredCorner) {
  const Shipped& s = Get();
  HardPressRig rig(s.scene, s.upper, s.upper_model);
  const ProbeAt hard{119.5, 23.5, 5.0}, light{110.0, 70.0, 0.4};
  ASSERT_TRUE(rig.Press(std::span<const ProbeAt>(&hard, 1), 1.5).stops()) << "the hard press alone must stop";
  ASSERT_FALSE(rig.Press(std::span<const ProbeAt>(&light, 1), 1.5).stops()) << "the light touch alone must not stop";
  const ProbeAt two[2] = {hard, light};
  const PressOutcome o = rig.Press(std::span<const ProbeAt>(two, 2), 1.5);
  EXPECT_TRUE(o.stops()) << "largest reported " << o.max_force_n << " N";
}

// Why the corner above stays open (docs/experiments/pair.md, section 4): at the wrist end the gratings see 5 N at the
// covered corner Y 119.5 R 23.5 almost as they see 0.75 N at Y 117.5 R 47, 24 deg inward (3 N there almost as 0.5 N at
// Y 116 R 48.5), and 5 N at R 122 almost as 0.75 N at Y 119 R 101. Noise-free (the twin's strain, the common mode
// removed as the decoder removes it: the mean of the two middle shifts), the two presses' shifts differ by |d| of
// 2-6 sigma of one grating's noise (0.3 pm) on one frame: a decoder would need a model of the corner accurate to well
// under a picometre per grating to tell them apart, and the shipped one reads both at about 2 N. The corner press
// alone must stop (it does). If the separation test fails, the twin or the fibre changed: measure pair.md again.
TEST(TwoTouches, AWristEndCornerPressAndALightPressInwardMoveTheGratingsAlike) {
  const Shipped& s = Get();
  const HardPressRig rig(s.scene, s.upper, s.upper_model);
  const auto shifts = [&](double y, double r, double f) {
    const std::vector<twin::Contact> c{twin::Contact{{y, r}, f, s.scene.probe}};
    twin::Shifts raw{};
    std::uint32_t flags = 0;
    rig.twin().StrainShiftsPm(c, raw, flags);
    std::vector<double> v(raw.begin(), raw.end()), sorted = v;
    std::sort(sorted.begin(), sorted.end());
    const double median = 0.5 * (sorted[7] + sorted[8]);
    for (double& x : v) x -= median;
    return v;
  };
  constexpr double kNoisePm = 0.3;
  struct LookAlike {
    double y, r, f, light_y, light_r, light_f;
  };
  for (const LookAlike& c : {LookAlike{119.5, 23.5, 5.0, 117.5, 47.0, 0.75}, LookAlike{119.5, 23.5, 3.0, 116.0, 48.5, 0.5},
                             LookAlike{119.5, 122.0, 5.0, 119.0, 101.0, 0.75}}) {
    const std::vector<double> hard = shifts(c.y, c.r, c.f), light = shifts(c.light_y, c.light_r, c.light_f);
    double hh = 0, diff = 0;
    for (std::size_t i = 0; i < hard.size(); ++i) {
      hh += hard[i] * hard[i];
      diff += (hard[i] - light[i]) * (hard[i] - light[i]);
    }
    ASSERT_GT(std::sqrt(hh) / kNoisePm, 10.0) << "the corner press must move the gratings far above the noise";
    EXPECT_LT(std::sqrt(diff) / kNoisePm, 6.0) << c.f << " N at Y " << c.y << " R " << c.r << " against " << c.light_f
                                                << " N at Y " << c.light_y << " R " << c.light_r << " (" << hh << " pm^2)";
    const ProbeAt hard_press{c.y, c.r, c.f};
    EXPECT_TRUE(rig.Press(std::span<const ProbeAt>(&hard_press, 1), 1.5).stops()) << "the corner press alone must stop";
  }
}

// OPEN (docs/experiments/pair.md, section 4): the look-alike of the 5 N corner press above, 0.75 N at Y 117.5 R 47
// (half the threshold, on the covered surface), alone reads 1.83-1.86 N and stops on every seed. Enable it when a
// decoder tells the two apart (and keeps the corner press's stop).
TEST(TwoTouches, DISABLED_ALightPressInwardOfTheWristEndCornerDoesNotStop) {
  const Shipped& s = Get();
  const HardPressRig rig(s.scene, s.upper, s.upper_model);
  const ProbeAt light{117.5, 47.0, 0.75};
  const PressOutcome o = rig.Press(std::span<const ProbeAt>(&light, 1), 1.5);
  EXPECT_FALSE(o.stops()) << "largest reported " << o.max_force_n << " N";
}

// The pipeline hands PipelineConfig::multi_window_nodes to the check (review 15 finding 7): review 14's single 0.5 N
// touch at Y 100 R 85, which the networks place a few mm off, is flagged on many hold frames with the shipped window
// (+-2 nodes: 216 of 500 on the default seed) and on far fewer with +-8.
TEST(TwoTouches, ThePipelineUsesTheCheckWindowItIsGiven) {
  const Shipped& s = Get();
  const ProbeAt light{100.0, 85.0, 0.5};
  const auto flagged = [&](int window) {
    HardPressRig rig(s.scene, s.upper, s.upper_model);
    rig.pipeline_config().multi_window_nodes = window;
    const PressOutcome o = rig.Press(std::span<const ProbeAt>(&light, 1), 1.5);
    std::size_t n = 0;
    for (const auto& c : o.hold) n += c.multiple ? 1 : 0;
    return std::pair<std::size_t, std::size_t>{n, o.hold.size()};
  };
  const auto [shipped, frames] = flagged(2);
  const auto [wide, frames_wide] = flagged(8);
  ASSERT_GT(frames, 100u);
  EXPECT_GT(shipped, frames / 4) << "the shipped window should flag this touch on many hold frames";
  EXPECT_LT(wide, shipped / 2) << wide << " of " << frames_wide << " flagged with +-8, " << shipped << " of " << frames
                               << " with +-2";
}

// Without a response map the gratings' groups still flag two touches on gratings far apart.
TEST(TwoTouches, WithoutAResponseMapTheGratingsGroupsFlagThem) {
  const Shipped& s = Get();
  v1::DecoderModel bare = s.model;
  bare.clear_response();
  HardPressRig rig(s.scene, s.patch, bare);
  const ProbeAt p[2] = {{24.0, 42.5, 2.0}, {100.0, 102.5, 2.0}};
  const PressOutcome o = rig.Press(std::span<const ProbeAt>(p, 2), 1.5);
  const PressJudgement j = JudgePress(o, p, MmPerDeg(s.scene, s.patch));
  ASSERT_GT(j.located, 100);
  EXPECT_GE(j.flagged, j.located * 9 / 10);
  EXPECT_EQ(j.confident_wrong, 0);
}

// A map stored with limit 0 (the shipped forearm models': it is there for the re-tare, docs/safety.md) changes
// no frame: a small recording through the twin (a light press, then two pairs of touches far apart, which the
// gratings' groups flag) decodes field for field the same with it as without a map. The same map with its
// limit (0.07) does change frames: the recording reaches the check.
bool SameBits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

TEST(TwoTouches, AMapWithLimitZeroChangesNoFrame) {
  const Shipped& s = Get();
  const auto mounts = sim::LoadMounts(s.scene);
  const twin::SkinTwin skin(s.scene.patches[s.patch].spec, sim::EffectsFor(s.scene, mounts.get(), s.patch),
                            {s.scene.probe.radius_mm});
  twin::InterrogatorSim interrogator(skin, 11);
  constexpr double kRate = 100.0;
  const std::vector<std::vector<ProbeAt>> presses = {
      {{75.0, 72.5, 1.0}}, {{24.0, 42.5, 2.0}, {100.0, 102.5, 2.0}}, {{98.7, 33.5, 2.88}, {31.1, 62.3, 1.82}}};
  std::vector<std::pair<Wavelengths, std::uint32_t>> recording;
  auto record = [&](const std::vector<ProbeAt>& probes, double w) {
    std::vector<twin::Contact> contacts;
    for (const ProbeAt& p : probes) contacts.push_back(twin::Contact{{p.y_mm, p.r_deg}, w * p.force_n, s.scene.probe});
    twin::Shifts sh{};
    std::uint32_t flags = 0;
    skin.StrainShiftsPm(contacts, sh, flags);
    Wavelengths wl{};
    interrogator.Read(static_cast<double>(recording.size()) / kRate, sh, wl, flags);
    recording.emplace_back(wl, flags);
  };
  for (int k = 0; k < 150; ++k) record({}, 0.0);  // the baseline's capture
  for (const auto& probes : presses) {
    for (int k = 1; k <= 30; ++k) record(probes, k / 30.0);
    for (int k = 0; k < 50; ++k) record(probes, 1.0);
    for (int k = 29; k >= 0; --k) record(probes, k / 30.0);
    for (int k = 0; k < 40; ++k) record({}, 0.0);
  }

  auto run = [&](const v1::DecoderModel& model) {
    decode::PipelineConfig config;
    config.baseline = decode::BaselineFor(model, kRate);
    const decode::Pipeline<float> pipe(model, s.scene.patches[s.patch].spec, config);
    decode::Pipeline<float>::Data data(pipe);
    std::vector<decode::PipelineOutput> out;
    for (const auto& [wl, flags] : recording) out.push_back(pipe.Process(wl, flags, data));
    return std::pair(out, data.counters());
  };
  v1::DecoderModel bare = s.model, zero = s.model;
  bare.clear_response();
  zero.mutable_response()->set_multiple_misfit(0.0);
  const auto [without, without_counters] = run(bare);
  const auto [with, with_counters] = run(zero);
  const auto [checked, checked_counters] = run(s.model);
  ASSERT_GT(s.model.response().multiple_misfit(), 0.0);
  ASSERT_GT(without_counters.located, 100u);
  ASSERT_GT(without_counters.multiple, 50u) << "the gratings' groups flag no pair: the recording shows nothing";

  ASSERT_EQ(with.size(), without.size());
  for (std::size_t k = 0; k < with.size(); ++k) {
    const decode::PipelineOutput &a = with[k], &b = without[k];
    SCOPED_TRACE("frame " + std::to_string(k));
    EXPECT_TRUE(SameBits(a.force_n, b.force_n)) << a.force_n << " vs " << b.force_n;
    EXPECT_TRUE(SameBits(a.force_sd_n, b.force_sd_n));
    EXPECT_TRUE(SameBits(a.y_mm, b.y_mm));
    EXPECT_TRUE(SameBits(a.r_deg, b.r_deg));
    EXPECT_TRUE(SameBits(a.cov_yy_mm2, b.cov_yy_mm2)) << a.cov_yy_mm2 << " vs " << b.cov_yy_mm2;
    EXPECT_TRUE(SameBits(a.cov_yr_mm2, b.cov_yr_mm2));
    EXPECT_TRUE(SameBits(a.cov_rr_mm2, b.cov_rr_mm2));
    EXPECT_TRUE(SameBits(a.confidence, b.confidence));
    EXPECT_TRUE(SameBits(a.common_mode_pm, b.common_mode_pm));
    EXPECT_EQ(a.valid, b.valid);
    EXPECT_EQ(a.in_contact, b.in_contact);
    EXPECT_EQ(a.located, b.located);
    EXPECT_EQ(a.over_range, b.over_range);
    EXPECT_EQ(a.multiple, b.multiple);
    EXPECT_EQ(a.touch_groups, b.touch_groups);
    EXPECT_EQ(a.faint, b.faint);
    EXPECT_EQ(a.reason, b.reason);
    EXPECT_EQ(a.missing, b.missing);
    if (::testing::Test::HasFailure()) break;  // the first frame that differs says enough
  }
  EXPECT_EQ(with_counters.multiple, without_counters.multiple);
  EXPECT_EQ(with_counters.located, without_counters.located);
  EXPECT_EQ(with_counters.onsets, without_counters.onsets);

  std::size_t changed = 0;
  for (std::size_t k = 0; k < checked.size(); ++k) {
    if (checked[k].touch_groups != without[k].touch_groups || !SameBits(checked[k].cov_yy_mm2, without[k].cov_yy_mm2)) ++changed;
  }
  EXPECT_GT(changed, 0u) << "the map with its limit changes no frame either: the recording never reaches the check";
}

// The check alone, on a synthetic map: one Gaussian bump of sensitivity per grating.
v1::ResponseMap SyntheticMap(double misfit) {
  decode::ResponseModel m;
  m.y0_mm = 0;
  m.r0_deg = 0;
  m.dy_mm = 2;
  m.dr_deg = 2;
  m.ny = 51;
  m.nr = 51;
  m.g.resize(static_cast<std::size_t>(m.ny * m.nr));
  for (int iy = 0; iy < m.ny; ++iy) {
    for (int ir = 0; ir < m.nr; ++ir) {
      for (std::size_t i = 0; i < 16; ++i) {
        const double gy = 12.0 + 25.0 * static_cast<double>(i % 4), gr = 12.0 + 25.0 * static_cast<double>(i / 4);
        const double d2 = std::pow(iy * 2.0 - gy, 2) + std::pow(ir * 2.0 - gr, 2);
        m.g[static_cast<std::size_t>(iy * m.nr + ir)][i] = static_cast<float>(100.0 * std::exp(-d2 / (2 * 10.0 * 10.0)));
      }
    }
  }
  return decode::ToProto(m, misfit, "test");
}

decode::ShiftsPm Shifts(const decode::ResponseModel& m, std::initializer_list<decode::Touch> touches) {
  decode::ShiftsPm s{};
  for (const decode::Touch& t : touches) {
    std::array<double, 16> g{};
    m.Eval(t.y_mm, t.r_deg, g);
    for (std::size_t i = 0; i < 16; ++i) s[i] += static_cast<float>(t.force_n * g[i]);
  }
  return s;
}

TEST(TouchCheck, OneTouchPassesTwoAreFoundWithTheirForces) {
  const decode::TouchCheck check(SyntheticMap(0.05));
  const decode::ResponseModel& m = check.model();
  const decode::TouchVerdict one = check.Check(Shifts(m, {{40, 40, 2.0}}), 41, 39);
  EXPECT_FALSE(one.multiple);
  EXPECT_LT(one.misfit, 0.01);
  const decode::TouchVerdict two = check.Check(Shifts(m, {{20, 20, 2.0}, {80, 70, 1.5}}), 50, 45);
  ASSERT_TRUE(two.multiple);
  ASSERT_EQ(two.found, 2);
  EXPECT_LT(two.misfit_two, 0.01);
  // Either order; places to a node, forces to 5 %.
  const bool swapped = two.touch[0].y_mm > two.touch[1].y_mm;
  const decode::Touch& a = two.touch[swapped ? 1 : 0];
  const decode::Touch& b = two.touch[swapped ? 0 : 1];
  EXPECT_NEAR(a.y_mm, 20, 2.1);
  EXPECT_NEAR(a.r_deg, 20, 2.1);
  EXPECT_NEAR(a.force_n, 2.0, 0.1);
  EXPECT_NEAR(b.y_mm, 80, 2.1);
  EXPECT_NEAR(b.r_deg, 70, 2.1);
  EXPECT_NEAR(b.force_n, 1.5, 0.075);
}

// confirm_anywhere (review 14 finding 3; PipelineConfig::multi_confirm_anywhere, off by default): one touch whose
// start lies beyond the 5 x 5 node window is flagged by the window alone, and is one touch when the best single
// touch anywhere on the map is asked too; a pair stays flagged and found either way.
TEST(TouchCheck, ConfirmAnywhereClearsAFlagOneTouchExplainsAndKeepsAPair) {
  const decode::TouchCheck check(SyntheticMap(0.05));
  const decode::ResponseModel& m = check.model();
  const decode::ShiftsPm one = Shifts(m, {{40, 40, 2.0}});
  const decode::TouchVerdict window = check.Check(one, 52, 52);  // 12 mm and 12 deg off: outside the window
  ASSERT_TRUE(window.multiple) << "misfit " << window.misfit << ": the window should miss this touch";
  const decode::TouchVerdict anywhere = check.Check(one, 52, 52, true, true);
  EXPECT_FALSE(anywhere.multiple);
  EXPECT_LT(anywhere.misfit, 0.01);
  const decode::ShiftsPm two = Shifts(m, {{20, 20, 2.0}, {80, 70, 1.5}});
  const decode::TouchVerdict pair = check.Check(two, 50, 45, true, true);
  EXPECT_TRUE(pair.multiple);
  EXPECT_EQ(pair.found, 2);
}

// The single check's window (PipelineConfig::multi_window_nodes; measured wider and left at +-2 nodes,
// docs/experiments/pair.md section 4): a touch 12 mm off the start is outside +-2 nodes (2 mm each) and inside +-6;
// a pair stays flagged with either; a window the pipeline cannot use is refused.
TEST(TouchCheck, AWiderWindowFindsATouchPlacedFartherOffAndStillFlagsAPair) {
  const decode::TouchCheck check(SyntheticMap(0.05));
  const decode::ResponseModel& m = check.model();
  const decode::ShiftsPm one = Shifts(m, {{40, 40, 2.0}});
  EXPECT_TRUE(check.Check(one, 52, 52, true, false, 2).multiple);
  const decode::TouchVerdict wide = check.Check(one, 52, 52, true, false, 6);
  EXPECT_FALSE(wide.multiple);
  EXPECT_LT(wide.misfit, 0.01);
  const decode::TouchVerdict pair = check.Check(Shifts(m, {{20, 20, 2.0}, {80, 70, 1.5}}), 50, 45, true, false, 6);
  EXPECT_TRUE(pair.multiple);
  EXPECT_EQ(pair.found, 2);
  const Shipped& s = Get();
  decode::PipelineConfig config;
  config.baseline = decode::BaselineFor(s.model, 1000.0);
  config.multi_window_nodes = 21;
  EXPECT_THROW((decode::Pipeline<float>(s.model, s.scene.patches[s.patch].spec, config)), InputError);
  config.multi_window_nodes = -1;
  EXPECT_THROW((decode::Pipeline<float>(s.model, s.scene.patches[s.patch].spec, config)), InputError);
  config.multi_window_nodes = 3;
  EXPECT_NO_THROW((decode::Pipeline<float>(s.model, s.scene.patches[s.patch].spec, config)));
}

// A found pair's forces carry an sd; Amplitudes follows the forces at the pair's places frame by frame.
TEST(TouchCheck, APairsForcesHaveAnSdAndFollowTheFrame) {
  const decode::TouchCheck check(SyntheticMap(0.05));
  const decode::ResponseModel& m = check.model();
  decode::TouchVerdict two = check.Check(Shifts(m, {{20, 20, 2.0}, {80, 70, 1.5}}), 50, 45);
  ASSERT_EQ(two.found, 2);
  for (const decode::Touch& t : two.touch) {
    EXPECT_TRUE(std::isfinite(t.force_sd_n));
    EXPECT_GT(t.force_sd_n, 0.0);
    EXPECT_LT(t.force_sd_n, 0.1) << "noise-free shifts on a strong response: a few hundredths of a newton";
    EXPECT_GT(t.gain_pm_per_n, 50.0);
  }
  const bool swapped = two.touch[0].y_mm > two.touch[1].y_mm;
  // The same places, the forces halved and doubled: re-solved without a search.
  decode::ShiftsPm later = Shifts(m, {{20, 20, 1.0}, {80, 70, 3.0}});
  check.Amplitudes(later, two);
  EXPECT_NEAR(two.touch[swapped ? 1 : 0].force_n, 1.0, 0.1);
  EXPECT_NEAR(two.touch[swapped ? 0 : 1].force_n, 3.0, 0.15);
  // One touch lifted: its force goes to 0, never negative.
  check.Amplitudes(Shifts(m, {{80, 70, 3.0}}), two);
  EXPECT_NEAR(two.touch[swapped ? 1 : 0].force_n, 0.0, 0.1);
  EXPECT_GE(two.touch[swapped ? 1 : 0].force_n, 0.0);
  // Noise on every grating: the sd grows with it.
  decode::ShiftsPm noisy = Shifts(m, {{20, 20, 2.0}, {80, 70, 1.5}});
  for (std::size_t i = 0; i < 16; ++i) noisy[i] += (i % 2 ? 8.0f : -8.0f);
  decode::TouchVerdict quiet = check.Check(Shifts(m, {{20, 20, 2.0}, {80, 70, 1.5}}), 50, 45);
  decode::TouchVerdict loud = quiet;
  check.Amplitudes(noisy, loud);
  EXPECT_GT(loud.touch[0].force_sd_n, 2 * quiet.touch[0].force_sd_n);
}

TEST(TouchCheck, MissingPeaksAndNoSignalAreNoMisfitAndNoNaN) {
  const decode::TouchCheck check(SyntheticMap(0.05));
  decode::ShiftsPm s = Shifts(check.model(), {{40, 40, 2.0}});
  s[3] = std::nanf("");
  s[7] = std::nanf("");
  const decode::TouchVerdict v = check.Check(s, 40, 40);
  EXPECT_FALSE(v.multiple);
  EXPECT_TRUE(std::isfinite(v.misfit));
  const decode::TouchVerdict zero = check.Check(decode::ShiftsPm{}, 40, 40);
  EXPECT_FALSE(zero.multiple);
  decode::ShiftsPm dark{};
  for (float& x : dark) x = std::nanf("");
  EXPECT_FALSE(check.Check(dark, 40, 40).multiple);
}

TEST(TouchCheck, AMalformedMapIsRefusedWithItsReason) {
  v1::ResponseMap m = SyntheticMap(0.05);
  m.mutable_g_pm_per_n()->RemoveLast();
  EXPECT_THROW({ decode::TouchCheck c(m); }, InputError);
  m = SyntheticMap(0.05);
  m.set_g_pm_per_n(5, std::nanf(""));
  EXPECT_THROW({ decode::TouchCheck c(m); }, InputError);
  m = SyntheticMap(1.5);
  EXPECT_THROW({ decode::TouchCheck c(m); }, InputError);
  m = SyntheticMap(0.05);
  m.set_dy_mm(0);
  EXPECT_THROW({ decode::TouchCheck c(m); }, InputError);
  m = SyntheticMap(0.05);
  m.set_dr_deg(0.01);  // a step too fine to be a place
  EXPECT_THROW({ decode::TouchCheck c(m); }, InputError);
  // Too many nodes for a flagged frame's fit to stay inside a 1 kHz period (the review: 300 x 300 took 1.2 ms).
  m = SyntheticMap(0.05);
  m.set_ny(200);
  m.set_nr(200);
  m.mutable_g_pm_per_n()->Resize(200 * 200 * 16, 1.0f);
  EXPECT_THROW({ decode::TouchCheck c(m); }, InputError);
}

// A map that does not lie on the patch would flag every frame and place it there: the pipeline refuses it.
TEST(TwoTouches, AResponseMapOffThePatchIsRefused) {
  const Shipped& s = Get();
  v1::DecoderModel moved = s.model;
  moved.mutable_response()->set_y0_mm(1000.0);
  decode::PipelineConfig config;
  config.baseline = decode::BaselineFor(moved, 1000.0);
  EXPECT_THROW((decode::Pipeline<float>(moved, s.scene.patches[s.patch].spec, config)), InputError);
  EXPECT_NO_THROW((decode::Pipeline<float>(s.model, s.scene.patches[s.patch].spec, config)));
}

}  // namespace
}  // namespace ruffini::testing
