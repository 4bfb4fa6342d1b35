// eval::ScoreStops on constructed streams, where every press, episode and delay is known.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "ruffini/decode/pipeline.h"
#include "ruffini/error.h"
#include "ruffini/eval/stop_score.h"
#include "ruffini/patch/spec_loader.h"

namespace ruffini::eval {
namespace {

constexpr double kRate = 100.0;

const patch::PatchSpec& Spec() {
  static const patch::PatchSpec s = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  return s;
}

// A stream of `seconds` at 100 Hz: nothing pressed, the decoder valid, untouched and tracking, after 1 s of
// start-up capture.
struct Stream {
  dataset::Dataset d;
  StreamPredictions p;
  explicit Stream(double seconds) {
    const auto n = static_cast<std::size_t>(seconds * kRate);
    d.info.sample_rate_hz = kRate;
    for (std::size_t k = 0; k < n; ++k) {
      dataset::Frame f;
      f.t_s = static_cast<double>(k) / kRate;
      f.serial = k;
      f.y_mm = f.r_deg = std::numeric_limits<float>::quiet_NaN();
      d.Append(f);
    }
    p.force_n.assign(n, 0.0f);
    p.force_sd_n.assign(n, 0.05f);
    p.y_mm.assign(n, 70.0f);
    p.r_deg.assign(n, 70.0f);
    p.confidence.assign(n, 1.0f);
    p.common_mode_pm.assign(n, 0.0f);
    p.pos_cov_mm2.assign(3 * n, 1.0f);
    p.valid.assign(n, 1);
    p.located.assign(n, 0);
    p.in_contact.assign(n, 0);
    p.reason.assign(n, static_cast<std::uint8_t>(decode::Reason::kOk));
    p.baseline_frozen.assign(n, 0);
    p.over_range.assign(n, 0);
    for (std::size_t k = 0; k < 100 && k < n; ++k) {
      p.valid[k] = 0;
      p.reason[k] = static_cast<std::uint8_t>(decode::Reason::kCapturing);
    }
  }
  static std::size_t K(double t) { return static_cast<std::size_t>(std::llround(t * kRate)); }
  // A true press `id` from t0 to t1 (s), ramping linearly to `peak` over the first half and back.
  void Press(std::int32_t id, double t0, double t1, float peak, float y = 60.0f, float r = 70.0f) {
    const std::size_t a = K(t0), b = K(t1);
    for (std::size_t k = a; k <= b; ++k) {
      const double u = static_cast<double>(k - a) / static_cast<double>(b - a);
      d.true_force_n[k] = peak * static_cast<float>(u < 0.5 ? 2 * u : 2 * (1 - u));
      d.force_n[k] = d.true_force_n[k];
      d.indentation[k] = id;
      d.y_mm[k] = y;
      d.r_deg[k] = r;
    }
  }
  // The decoder reports force f in contact from t0 to t1 (the gate open), located at the true place.
  void Report(double t0, double t1, float f) {
    for (std::size_t k = K(t0); k <= K(t1); ++k) {
      p.force_n[k] = f;
      p.in_contact[k] = 1;
      p.located[k] = 1;
    }
  }
  void Invalid(double t0, double t1, decode::Reason why) {
    for (std::size_t k = K(t0); k <= K(t1); ++k) {
      p.valid[k] = 0;
      p.in_contact[k] = 0;
      p.force_n[k] = 0;
      p.reason[k] = static_cast<std::uint8_t>(why);
    }
  }
  StopScore Score(const StopRuleModel& rule = {}) const { return ScoreStops(d, p, Spec(), rule); }
};

TEST(StopScore, AQuietStreamHasNoEpisodeAndItsHoursExcludeTheCapture) {
  const Stream s(101.0);
  const StopScore r = s.Score();
  EXPECT_EQ(r.frames, 10000u);
  EXPECT_NEAR(r.hours, 100.0 / 3600.0, 1e-9);
  EXPECT_TRUE(r.episodes.empty());
  EXPECT_EQ(r.spurious(), 0);
  EXPECT_EQ(r.quiet_frames, 10000u);
  EXPECT_EQ(r.false_contact_frames, 0u);
}

TEST(StopScore, AHardPressReadWellStopsWithTheDelayFromTheTrueCrossing) {
  Stream s(30.0);
  s.Press(0, 10.0, 12.0, 3.0f);  // 0 -> 3 N over 1 s: crosses 1.5 N at 10.5 s (strictly above: 10.51)
  s.Report(10.2, 12.0, 0.0f);
  for (std::size_t k = Stream::K(10.2); k <= Stream::K(12.0); ++k) s.p.force_n[k] = s.d.true_force_n[Stream::K(static_cast<double>(k) / kRate - 0.05)];  // 50 ms late
  const StopScore r = s.Score();
  ASSERT_EQ(r.due, 1);
  EXPECT_EQ(r.due_missed(), 0);
  ASSERT_EQ(r.due_presses.size(), 1u);
  EXPECT_TRUE(r.due_presses[0].stopped);
  EXPECT_FALSE(r.due_presses[0].fault_only);
  EXPECT_NEAR(r.due_presses[0].delay_ms, 50.0, 10.0 + 1e-6);
  ASSERT_EQ(r.episodes.size(), 1u);
  EXPECT_EQ(r.episodes[0].cause, EpisodeCause::kDuePress);
  EXPECT_EQ(r.spurious(), 0);
}

TEST(StopScore, AHardPressReadLightIsMissedAndOneReadEarlyHasANegativeDelay) {
  Stream s(60.0);
  s.Press(0, 10.0, 12.0, 3.0f);
  s.Report(10.2, 12.0, 1.2f);  // read below the threshold throughout: missed
  s.Press(1, 30.0, 32.0, 2.0f);
  s.Report(30.2, 32.0, 1.6f);  // read above from 30.2 s; truly above 1.5 N only from 30.75 s
  const StopScore r = s.Score();
  ASSERT_EQ(r.due, 2);
  EXPECT_EQ(r.due_missed(), 1);
  EXPECT_FALSE(r.due_presses[0].stopped);
  EXPECT_FLOAT_EQ(r.due_presses[0].reported_max_n, 1.2f);
  EXPECT_TRUE(r.due_presses[1].stopped);
  EXPECT_LT(r.due_presses[1].delay_ms, -400.0);
  EXPECT_EQ(r.spurious(), 0);
}

TEST(StopScore, ALightPressReadAboveTheThresholdIsOneSpuriousStopHoweverOftenItCrosses) {
  Stream s(60.0);
  s.Press(0, 10.0, 30.0, 1.2f);  // 0.8 x threshold: light
  s.Report(12.0, 28.0, 1.2f);  // below the release level (90 % of 1.5 N): each crossing's cause ends
  for (double t = 14.0; t < 26.0; t += 3.0) s.Report(t, t + 0.5, 1.6f);  // crosses four times, 2.5 s apart
  const StopScore r = s.Score();
  EXPECT_EQ(r.light, 1);
  EXPECT_EQ(r.CountEpisodes(EpisodeCause::kLightPress), 4);  // the operator could reset in between
  EXPECT_EQ(r.light_stopped, 1);
  EXPECT_EQ(r.spurious(), 1);
}

TEST(StopScore, TheReleaseHysteresisKeepsOneCauseAndCausesWithinTheLatchAreOneEpisode) {
  Stream s(60.0);
  s.Press(0, 10.0, 30.0, 1.4f);  // 0.93 x threshold: the grey band, neither due nor light
  s.Report(12.0, 28.0, 1.6f);
  s.Report(15.0, 15.5, 1.4f);  // below the threshold, above 90 % of it: the cause holds
  s.Report(20.0, 20.5, 1.0f);  // below the release level for 0.5 s: ends, and comes back within 1 s
  const StopScore r = s.Score();
  EXPECT_EQ(r.grey, 1);
  ASSERT_EQ(r.episodes.size(), 1u);
  EXPECT_EQ(r.episodes[0].cause, EpisodeCause::kGreyPress);
  EXPECT_EQ(r.spurious(), 0);
  StopRuleModel no_latch;
  no_latch.operator_latch_s = 0.2;
  EXPECT_EQ(s.Score(no_latch).episodes.size(), 2u);
}

TEST(StopScore, DoubtsAndOverRangeStopEvenWhenTheForceIsLow) {
  Stream s(60.0);
  s.Report(10.0, 10.05, -0.2f);  // in contact, below -50 mN: a doubt, in a rest
  s.Report(20.0, 20.1, 0.3f);
  s.p.y_mm[Stream::K(20.05)] = 170.0f;  // placed 20 mm beyond the patch's 150 mm
  s.p.over_range[Stream::K(40.0)] = 1;   // over range: a contact of at least 2.5 N
  s.p.valid[Stream::K(40.0)] = 0;
  s.p.in_contact[Stream::K(40.0)] = 1;
  s.p.force_n[Stream::K(40.0)] = 2.5f;
  s.p.reason[Stream::K(40.0)] = static_cast<std::uint8_t>(decode::Reason::kOutOfRange);
  s.Report(50.0, 50.1, -0.04f);  // within the tolerance: 0 N, no stop
  const StopScore r = s.Score();
  ASSERT_EQ(r.episodes.size(), 3u);
  EXPECT_EQ(r.episodes[0].kind, EpisodeKind::kNegativeForce);
  EXPECT_EQ(r.episodes[1].kind, EpisodeKind::kBeyondPatch);
  EXPECT_EQ(r.episodes[2].kind, EpisodeKind::kOverRange);
  EXPECT_EQ(r.CountEpisodes(EpisodeCause::kRest), 3);
  EXPECT_EQ(r.spurious(), 3);
  EXPECT_GT(r.false_contact_frames, 0u);  // in contact with nothing pressing
}

TEST(StopScore, AStaleBaselineIsAFaultAndItsTimeWithoutACauseIsStuck) {
  Stream s(400.0);
  s.Invalid(100.0, 250.0, decode::Reason::kBaselineStale);
  s.Press(0, 150.0, 152.0, 2.0f);  // a due press during the fault: stopped, by the FAULT only
  const StopScore r = s.Score();
  ASSERT_EQ(r.episodes.size(), 1u);
  EXPECT_EQ(r.episodes[0].kind, EpisodeKind::kFault);
  EXPECT_EQ(r.episodes[0].cause, EpisodeCause::kRest);
  EXPECT_NEAR(r.fault_s, 150.01, 0.02);
  EXPECT_LT(r.fault_no_cause_s, r.fault_s);  // the press's frames above 1.5 N are a present cause
  EXPECT_GT(r.longest_fault_no_cause_s, 60.0);
  EXPECT_TRUE(r.stuck(StopRuleModel{}));
  ASSERT_EQ(r.due_presses.size(), 1u);
  EXPECT_TRUE(r.due_presses[0].stopped);
  EXPECT_TRUE(r.due_presses[0].fault_only);
}

TEST(StopScore, TwoRejectedFramesAreNoFaultThreeAre) {
  Stream s(60.0);
  s.Invalid(10.0, 10.01, decode::Reason::kTooManyMissing);  // 2 frames
  EXPECT_TRUE(s.Score().episodes.empty());
  s.Invalid(10.0, 10.02, decode::Reason::kTooManyMissing);  // 3 frames
  const StopScore r = s.Score();
  ASSERT_EQ(r.episodes.size(), 1u);
  EXPECT_EQ(r.episodes[0].kind, EpisodeKind::kFault);
  EXPECT_NEAR(r.fault_s, 0.01, 1e-9);
}

TEST(StopScore, TheSdRuleJudgesForcePlusKSd) {
  Stream s(60.0);
  s.Press(0, 10.0, 30.0, 1.2f);
  s.Report(12.0, 28.0, 1.45f);  // sd 0.05: +1 sd is 1.50 (not above), +2 sd 1.55 (above)
  StopRuleModel plus1, plus2;
  plus1.sd_k = 1.0;
  plus2.sd_k = 2.0;
  EXPECT_EQ(s.Score().spurious(), 0);
  EXPECT_EQ(s.Score(plus2).spurious(), 1);
  EXPECT_LE(s.Score(plus1).spurious(), 1);  // at the threshold in float arithmetic: either way, never more
}

TEST(StopScore, BadInputIsAClearError) {
  Stream s(20.0);
  StreamPredictions short_p = s.p;
  short_p.force_n.pop_back();
  EXPECT_THROW(ScoreStops(s.d, short_p, Spec(), {}), InputError);
  Stream no_truth(20.0);
  for (auto& f : no_truth.d.true_force_n) f = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(no_truth.Score(), InputError);
  StopRuleModel bad;
  bad.threshold_n = 0;
  EXPECT_THROW(s.Score(bad), InputError);
}

}  // namespace
}  // namespace ruffini::eval
