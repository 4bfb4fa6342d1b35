// Review 7 (docs/reviews/faint-refusal.md): the field models' faint refusal (commit 9433d2a,
// Preprocessing.faint_refuse_below_n; BaselineTracker::Gate::kHold) against the flag-only decoder on the same
// frames. Streams: the twin's strain (the scene's probe, viscoelastic cover and temperature history, 0.3 pm
// noise) for a force schedule at one place, optionally with per-grating offsets added to the peaks (a baseline
// error, as the sim's scenario `offsets` add them), decoded by decode::Pipeline as the decoder service runs
// it, once as the model says (refusing) and once with faint_refuse = false (flag only).
// A STOP is the first frame the aggregator would stop on under the field scene's rule (1.5 N, sd_k 0): a valid
// contact above 1.5 N, an over-range contact, or an invalid frame (a FAULT: stale baseline and the rest).
// Tests named DISABLED_ are findings (they fail); run with --gtest_also_run_disabled_tests. The TABLE=1
// environment variable prints the sweeps' rows.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"
#include "ruffini/twin/viscoelastic.h"

namespace ruffini::eval {
namespace {

constexpr double kRate = 100.0;
constexpr double kThreshold = 1.5;  // the field scenes' (and cobot's) stop threshold, sd_k 0

const twin::Scene& FieldScene() {
  static const twin::Scene s = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/forearm-field.yaml");
  return s;
}
const twin::Scene& GradientScene() {
  static const twin::Scene s = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/forearm-field-gradient.yaml");
  return s;
}
const v1::DecoderModel& FieldModel() {
  static const v1::DecoderModel m = decode::LoadModel(RUFFINI_SOURCE_DIR "/config/models/forearm-field.rmodel");
  return m;
}
const v1::DecoderModel& EmbeddedModel() {
  static const v1::DecoderModel m = decode::LoadModel(RUFFINI_SOURCE_DIR "/config/models/forearm-embedded.rmodel");
  return m;
}
bool Table() { return std::getenv("TABLE") != nullptr; }

using Offsets = std::array<double, patch::kGratings>;  // pm per grating
struct Touch {
  patch::SurfacePoint at;
  std::vector<double> force;  // per frame
};
// The twin's peaks for the touches (each with its own viscoelastic site), plus offsets(k) pm from frame k.
std::vector<Wavelengths> Synthesize(const twin::Scene& scene, const std::vector<Touch>& touches, std::size_t frames,
                                    const std::function<Offsets(std::size_t)>& offsets = {}, std::uint64_t seed = 5) {
  const twin::SkinTwin t(scene.Patch().spec, scene.EffectsOf(0), {scene.probe.radius_mm});
  twin::InterrogatorSim sim(t, seed);
  std::vector<twin::ViscoelasticSites> visco;
  for (const auto& touch : touches) {
    visco.emplace_back(scene.effects.viscoelastic ? &*scene.effects.viscoelastic : nullptr, 1.0 / kRate, scene.probe);
    visco.back().MoveTo(touch.at);
  }
  std::vector<Wavelengths> out(frames);
  std::vector<twin::Contact> contacts;
  for (std::size_t k = 0; k < frames; ++k) {
    contacts.clear();
    for (std::size_t j = 0; j < touches.size(); ++j) {
      const double f = k < touches[j].force.size() ? touches[j].force[k] : 0.0;
      for (const auto& c : visco[j].Step(f)) contacts.push_back(c);
    }
    twin::Shifts s;
    std::uint32_t flags = 0;
    t.StrainShiftsPm(contacts, s, flags);
    std::array<double, patch::kGratings> wl{};
    sim.Read(static_cast<double>(k) / kRate, s, wl, flags);
    const Offsets off = offsets ? offsets(k) : Offsets{};
    for (std::size_t i = 0; i < kGratings; ++i) out[k][i] = wl[i] + off[i] * 1e-3;
  }
  return out;
}

struct Decoded {
  std::vector<decode::PipelineOutput> out;
  std::size_t refused = 0, held_frames = 0;
};
Decoded DecodeAll(const v1::DecoderModel& m, const twin::Scene& scene, const std::vector<Wavelengths>& wl,
                  std::optional<bool> refuse) {
  decode::PipelineConfig cfg;
  cfg.faint_refuse = refuse;
  cfg.baseline = decode::BaselineFor(m, kRate);
  const decode::Pipeline<float> pipe(m, scene.Patch().spec, cfg);
  decode::Pipeline<float>::Data d(pipe);
  Decoded r;
  r.out.reserve(wl.size());
  for (const auto& w : wl) {
    r.out.push_back(pipe.Process(w, 0, d));
    const auto& o = r.out.back();
    r.refused += o.faint && !o.in_contact && o.valid;
  }
  return r;
}
bool Fault(const decode::PipelineOutput& o) { return !o.valid && !o.over_range && o.reason != decode::Reason::kCapturing; }
bool Stops(const decode::PipelineOutput& o) {
  return Fault(o) || o.over_range || (o.valid && o.in_contact && o.force_n > kThreshold);
}
// First frame from `from` that stops (npos: none); force_only: FAULTs do not count.
std::size_t FirstStop(const Decoded& d, std::size_t from, bool force_only = false) {
  for (std::size_t k = from; k < d.out.size(); ++k) {
    const auto& o = d.out[k];
    if (force_only ? (o.over_range || (o.valid && o.in_contact && o.force_n > kThreshold)) : Stops(o)) return k;
  }
  return std::string::npos;
}
std::size_t CountFault(const Decoded& d, std::size_t from, std::size_t to) {
  std::size_t n = 0;
  for (std::size_t k = from; k < to && k < d.out.size(); ++k) n += Fault(d.out[k]);
  return n;
}
float MaxReported(const Decoded& d, std::size_t from, std::size_t to) {
  float m = 0.0f;
  for (std::size_t k = from; k < to && k < d.out.size(); ++k) {
    const auto& o = d.out[k];
    if (o.valid && o.in_contact) m = std::max(m, o.force_n);
    if (o.over_range) m = std::max(m, o.force_n);
  }
  return m;
}
std::string Sec(std::size_t k, std::size_t ref) {
  if (k == std::string::npos) return "never";
  char b[32];
  std::snprintf(b, sizeof b, "%+.2f s", (static_cast<double>(k) - static_cast<double>(ref)) / kRate);
  return b;
}

// Weak sites (review field.md findings 1-2; field_test.cpp): the wrist edge on FBG 16, the validation corner,
// press 15 of seed 780, the edge misses of seeds 55 / 777 / 784, the elbow edge, the point between gratings.
std::vector<std::pair<std::string, patch::SurfacePoint>> WeakSites() {
  const twin::SkinTwin t(FieldScene().Patch().spec, FieldScene().effects, {5.5});
  const auto& a = t.spec().indented_area;
  const auto g16 = t.grating_centres()[15];
  // the indented area's point farthest from every grating centre
  const patch::Geometry geo(t.spec().surface_radius_mm);
  patch::SurfacePoint between{};
  double best = -1;
  for (double y = a.y_min_mm + 10; y <= a.y_max_mm - 10; y += 1.0) {
    for (double r = a.r_min_deg + 10; r <= a.r_max_deg - 10; r += 1.0) {
      double dmin = 1e9;
      for (const auto& c : t.grating_centres()) dmin = std::min(dmin, geo.SurfaceDistanceMm({y, r}, c));
      if (dmin > best) {
        best = dmin;
        between = {y, r};
      }
    }
  }
  return {{"wrist edge at FBG16", {a.y_max_mm - 0.2, g16.r_deg}},
          {"corner (133.1, 31.8)", {133.1, 31.8}},
          {"press 15 (134.8, 70.6)", {134.8, 70.6}},
          {"(134.4, 58.6)", {134.4, 58.6}},
          {"(133.2, 54.6)", {133.2, 54.6}},
          {"(17.4, 109.6)", {17.4, 109.6}},
          {"elbow edge", {a.y_min_mm + 0.2, 0.5 * (a.r_min_deg + a.r_max_deg)}},
          {"between gratings", between}};
}

// rest_s, a 1 s ramp to light_n, held hold_s, then a ramp at rate_n_per_s to top_n, held top_s, released 0.5 s.
struct Schedule {
  std::vector<double> force;
  std::size_t raise_from = 0, cross = std::string::npos, top_last = 0;
};
Schedule LightThenRaise(double rest_s, double light_n, double hold_s, double rate_n_per_s, double top_n, double top_s) {
  Schedule s;
  auto push = [&](double f) {
    if (s.cross == std::string::npos && f > kThreshold) s.cross = s.force.size();
    s.force.push_back(f);
  };
  for (int k = 0; k < static_cast<int>(rest_s * kRate); ++k) push(0.0);
  if (light_n > 0) {
    for (int k = 1; k <= 100; ++k) push(light_n * k / 100);
    for (long k = 0; k < static_cast<long>(hold_s * kRate); ++k) push(light_n);
  }
  s.raise_from = s.force.size();
  const int ramp = std::max(1, static_cast<int>(std::lround((top_n - light_n) / rate_n_per_s * kRate)));
  for (int k = 1; k <= ramp; ++k) push(light_n + (top_n - light_n) * k / ramp);
  for (int k = 0; k < static_cast<int>(top_s * kRate); ++k) push(top_n);
  s.top_last = s.force.size();
  for (int k = 49; k >= 0; --k) push(top_n * k / 50);
  for (int k = 0; k < 300; ++k) push(0.0);
  return s;
}

// Q1. From a held light press (none, 0.5, 0.9 N held 60 s) at each weak site, a ramp at 0.15 or 10 N/s to
// 1.5x the threshold: the decoded STOP, refusing and flag only, on the same frames. Holds: the refusal
// never delays it (the frames at or above 1 N are decoded alike; below the threshold neither stops).
TEST(FaintRefusalReview, ARampFromAHeldLightPressStopsAsFlagOnlyDoes) {
  int cases = 0, later = 0, missed_both = 0;
  for (const auto& [name, at] : WeakSites()) {
    for (const double light : {0.0, 0.5, 0.9}) {
      for (const double rate : {0.15, 10.0}) {
        const Schedule s = LightThenRaise(10, light, 60, rate, 2.25, 10);
        const auto wl = Synthesize(FieldScene(), {{at, s.force}}, s.force.size());
        const Decoded on = DecodeAll(FieldModel(), FieldScene(), wl, std::nullopt);
        const Decoded off = DecodeAll(FieldModel(), FieldScene(), wl, false);
        const std::size_t a = FirstStop(on, 1000), b = FirstStop(off, 1000);
        ++cases;
        later += a > b;
        missed_both += a == std::string::npos && b == std::string::npos;
        if (Table() || a != b) {
          std::printf("%-24s light %.1f N, %5.2f N/s: STOP refusing %s, flag only %s after the true crossing; max %.2f / %.2f N; "
                      "%zu refused\n", name.c_str(), light, rate, Sec(a, s.cross).c_str(), Sec(b, s.cross).c_str(),
                      MaxReported(on, s.raise_from, s.top_last), MaxReported(off, s.raise_from, s.top_last), on.refused);
        }
        EXPECT_LE(a, b) << name << " light " << light << " rate " << rate;
      }
    }
  }
  std::printf("%d cases, %d later refusing, %d with no STOP either way\n", cases, later, missed_both);
}


// Q1, more shapes: a press whose force hovers around 1 N (1.0 +- 0.3 N, 2 s period, 30 s) before the ramp,
// and two touches (a light touch held at the wrist edge, a second press ramping elsewhere).
TEST(FaintRefusalReview, AHoveringPressAndASecondTouchStopAsFlagOnlyDoes) {
  int cases = 0, later = 0;
  const auto sites = WeakSites();
  for (const auto& [name, at] : sites) {
    for (const double rate : {0.15, 10.0}) {
      Schedule s = LightThenRaise(10, 0.0, 0, rate, 2.25, 10);
      // hover: replace the rest after 10 s by 30 s around 1 N, then the ramp from 1 N
      std::vector<double> f(1000, 0.0);
      for (int k = 0; k < 3000; ++k) f.push_back(1.0 + 0.3 * std::sin(2 * M_PI * k / 200.0));
      const std::size_t raise = f.size();
      const int ramp = static_cast<int>(std::lround(1.25 / rate * kRate));
      std::size_t cross = std::string::npos;
      for (int k = 1; k <= ramp; ++k) {
        f.push_back(1.0 + 1.25 * k / ramp);
        if (cross == std::string::npos && f.back() > kThreshold) cross = f.size() - 1;
      }
      for (int k = 0; k < 1000; ++k) f.push_back(2.25);
      const std::size_t top = f.size();
      for (int k = 0; k < 300; ++k) f.push_back(0.0);
      // the hover itself peaks at 1.3 N: below the threshold; the crossing is the ramp's
      const auto wl = Synthesize(FieldScene(), {{at, f}}, f.size());
      const Decoded on = DecodeAll(FieldModel(), FieldScene(), wl, std::nullopt);
      const Decoded off = DecodeAll(FieldModel(), FieldScene(), wl, false);
      const std::size_t a = FirstStop(on, 1000), b = FirstStop(off, 1000);
      ++cases;
      later += a > b;
      if (Table() || a != b) {
        std::printf("hover %-24s %5.2f N/s: STOP refusing %s, flag only %s (after the ramp's crossing); max %.2f / %.2f N; %zu refused\n",
                    name.c_str(), rate, Sec(a, cross).c_str(), Sec(b, cross).c_str(), MaxReported(on, raise, top),
                    MaxReported(off, raise, top), on.refused);
      }
      EXPECT_LE(a, b) << "hover " << name << " " << rate;
    }
  }
  // two touches: 0.5 N held at the wrist edge from 10 s; the second ramps from 40 s at the other sites
  const patch::SurfacePoint first = sites[0].second;
  for (std::size_t j = 1; j < sites.size(); ++j) {
    for (const double rate : {0.15, 10.0}) {
      const Schedule s2 = LightThenRaise(40, 0.0, 0, rate, 2.25, 10);
      std::vector<double> f1(s2.force.size(), 0.0);
      for (std::size_t k = 1000; k + 400 < f1.size(); ++k) f1[k] = std::min(0.5, 0.5 * static_cast<double>(k - 1000) / 100.0);
      const auto wl = Synthesize(FieldScene(), {{first, f1}, {sites[j].second, s2.force}}, s2.force.size());
      const Decoded on = DecodeAll(FieldModel(), FieldScene(), wl, std::nullopt);
      const Decoded off = DecodeAll(FieldModel(), FieldScene(), wl, false);
      const std::size_t a = FirstStop(on, 1000), b = FirstStop(off, 1000);
      ++cases;
      later += a > b;
      if (Table() || a != b) {
        std::printf("two touches, second at %-24s %5.2f N/s: STOP refusing %s, flag only %s; %zu refused\n",
                    sites[j].first.c_str(), rate, Sec(a, s2.cross).c_str(), Sec(b, s2.cross).c_str(), on.refused);
      }
      EXPECT_LE(a, b) << "two touches " << sites[j].first << " " << rate;
    }
  }
  std::printf("%d cases, %d later refusing\n", cases, later);
}

// Q2. A baseline error e (per-grating offsets, |e| <= 1.2 pm) appears at 20 s with nothing touching; at 60 s
// a press of 1.5x the threshold (2.25 N, 1 s ramp, 5 s hold) at a weak site. Where the error reads as a light
// faint contact, the refusing decoder holds the baseline with its stale clock paused (kHold): the error stays
// in every later frame, without a FAULT, for as long as it reads so. Printed per site: the press's largest
// reported force with the error held against the same press with none, and the cases where the press that
// stops without the error does not stop with it.
struct HeldCase {
  std::string site;
  Offsets e{};
  float with_error = 0, without = 0;
  double refused_share = 0;
};
std::vector<Offsets> Patterns(std::uint64_t seed, int random_count) {
  std::vector<Offsets> out;
  for (std::size_t g = 0; g < kGratings; ++g) {
    for (const double v : {-1.2, -0.8, -0.5}) {
      Offsets e{};
      e[g] = v;
      out.push_back(e);
    }
  }
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<std::size_t> pick(0, kGratings - 1);
  std::uniform_real_distribution<double> amp(0.4, 1.2);
  for (int n = 0; n < random_count; ++n) {
    Offsets e{};
    const std::size_t opener = pick(rng);  // a negative offset: reads as a light press
    e[opener] = -amp(rng);
    for (int k = 0; k < 2; ++k) e[pick(rng)] = (rng() & 1 ? 1.0 : -1.0) * amp(rng);
    out.push_back(e);
  }
  return out;
}
std::vector<HeldCase> HeldErrorSweep(const twin::Scene& scene, const v1::DecoderModel& m, int random_count,
                                     std::size_t* held_patterns) {
  const auto sites = WeakSites();
  decode::PipelineConfig cfg;
  cfg.baseline = decode::BaselineFor(m, kRate);
  const decode::Pipeline<float> pipe(m, scene.Patch().spec, cfg);
  constexpr std::size_t kOn = 2000, kPress = 6000;
  std::vector<double> press;
  for (int k = 1; k <= 100; ++k) press.push_back(2.25 * k / 100);
  for (int k = 0; k < 500; ++k) press.push_back(2.25);
  for (int k = 49; k >= 0; --k) press.push_back(2.25 * k / 50);
  for (int k = 0; k < 200; ++k) press.push_back(0.0);
  // the press without any error, per site
  std::vector<float> reference;
  for (const auto& [name, at] : sites) {
    std::vector<double> f(kPress, 0.0);
    f.insert(f.end(), press.begin(), press.end());
    const auto wl = Synthesize(scene, {{at, f}}, f.size());
    decode::Pipeline<float>::Data d(pipe);
    float mx = 0;
    for (std::size_t k = 0; k < wl.size(); ++k) {
      const auto o = pipe.Process(wl[k], 0, d);
      if (k >= kPress && ((o.valid && o.in_contact) || o.over_range)) mx = std::max(mx, o.force_n);
    }
    reference.push_back(mx);
  }
  std::vector<HeldCase> cases;
  *held_patterns = 0;
  for (const Offsets& e : Patterns(17, random_count)) {
    const auto rest = Synthesize(scene, {}, kPress, [&](std::size_t k) { return k >= kOn ? e : Offsets{}; }, 9);
    decode::Pipeline<float>::Data d(pipe);
    std::size_t refused = 0, fault = 0;
    for (std::size_t k = 0; k < rest.size(); ++k) {
      const auto o = pipe.Process(rest[k], 0, d);
      if (k >= kOn + 1000) {
        refused += o.valid && o.faint && !o.in_contact;
        fault += Fault(o);
      }
    }
    const double share = static_cast<double>(refused) / static_cast<double>(kPress - kOn - 1000);
    if (share < 0.8 || fault > 0 || d.baseline().state() != decode::BaselineTracker::State::kFrozen) continue;
    ++*held_patterns;
    for (std::size_t j = 0; j < sites.size(); ++j) {
      std::vector<double> f(kPress, 0.0);
      f.insert(f.end(), press.begin(), press.end());
      const auto wl = Synthesize(scene, {{sites[j].second, f}}, f.size(), [&](std::size_t) { return e; }, 11);
      decode::Pipeline<float>::Data dj = d;  // the held state
      float mx = 0;
      for (std::size_t k = kPress; k < wl.size(); ++k) {
        const auto o = pipe.Process(wl[k], 0, dj);
        if ((o.valid && o.in_contact) || o.over_range) mx = std::max(mx, o.force_n);
      }
      cases.push_back({sites[j].first, e, mx, reference[j], share});
    }
  }
  return cases;
}
std::string Pm(const Offsets& e) {
  std::string s;
  char b[32];
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (e[i] == 0) continue;
    std::snprintf(b, sizeof b, "%sFBG%zu %+.2f", s.empty() ? "" : ", ", i + 1, e[i]);
    s += b;
  }
  return s;
}
void ReportHeld(const std::vector<HeldCase>& cases, std::size_t held, int* lost, float* worst_drop) {
  *lost = 0;
  *worst_drop = 0;
  for (const auto& c : cases) {
    const bool l = c.without > kThreshold && !(c.with_error > kThreshold);
    *lost += l;
    *worst_drop = std::max(*worst_drop, c.without - c.with_error);
    if (Table() || l) {
      std::printf("%-24s error {%s} held (%.0f %% refused): 2.25 N read %.2f N (without the error %.2f N)%s\n", c.site.c_str(),
                  Pm(c.e).c_str(), 100 * c.refused_share, c.with_error, c.without, l ? "  STOP LOST" : "");
    }
  }
  std::printf("%zu error patterns held without a FAULT; %zu presses; %d stops lost; largest drop %.2f N\n", held,
              cases.size(), *lost, *worst_drop);
}

// The property: a baseline error the decoder holds without its stale clock must not turn a press that stops
// into one that does not (flag only, the same error FAULTs the patch after max_frozen_s: a STOP).
// After the fix (the stale clock runs while faint frames are refused) no error is held past max_frozen_s
// (ABaselineErrorThatHidesAStopDoesNotOutlastMaxFrozenWithoutAFault passes), but this sweep presses 40 s after
// the error, inside max_frozen_s: it still loses 128 of 680 stops; flag only must lose the same ones by
// construction, not measured separately (the same frozen baseline in both modes; refusal changes only what
// frames below 1 N report).
// An open finding of the decoder, not of the refusal: a sub-pm baseline error at the weak sites.
TEST(FaintRefusalReview, DISABLED_ABaselineErrorHeldWithoutAStaleClockNeverLosesAStop) {
  std::size_t held = 0;
  const auto cases = HeldErrorSweep(FieldScene(), FieldModel(), 60, &held);
  int lost = 0;
  float drop = 0;
  ReportHeld(cases, held, &lost, &drop);
  EXPECT_EQ(lost, 0);
}

// The embedded model on the gradient scene (40 pm/C, a field across the patch), the same sweep. Holds: none of
// its patterns is held without a FAULT (the thermal-field follower and the field move the shifts).
TEST(FaintRefusalReview, ABaselineErrorHeldWithoutAStaleClockNeverLosesAStopEmbedded) {
  std::size_t held = 0;
  const auto cases = HeldErrorSweep(GradientScene(), EmbeddedModel(), 30, &held);
  int lost = 0;
  float drop = 0;
  ReportHeld(cases, held, &lost, &drop);
  EXPECT_EQ(lost, 0);
}


// Q1 / Q2: a light press held long (HOLD_S, default 400 s: past max_frozen_s; the review ran 3600 s) at weak
// sites, then raised at 10 N/s to 2.25 N. Holds: refusing or flag only, the robot is held (STOP or FAULT) by
// the end of the raised press whenever the same raise after a 60 s hold stops. These light presses are mostly
// not faint (their shifts pass 1.25 pm), so both decoders go stale about 300 s into the hold (the review's
// latch, unchanged): the FAULT is the STOP.
TEST(FaintRefusalReview, ALongLightPressRaisedToAStopHoldsTheRobotRefusingOrNot) {
  const double hold_s = std::getenv("HOLD_S") ? std::atof(std::getenv("HOLD_S")) : 400.0;
  const auto sites = WeakSites();
  struct Run {
    const twin::Scene* scene;
    const v1::DecoderModel* model;
    const char* name;
  };
  for (const Run& run : {Run{&FieldScene(), &FieldModel(), "field"}, Run{&GradientScene(), &EmbeddedModel(), "gradient"}}) {
    for (const std::size_t j : {std::size_t{0}, std::size_t{2}, std::size_t{7}}) {
      for (const double light : {0.5, 0.9}) {
        bool held[2][2] = {};
        std::size_t faults[2] = {}, refused = 0;
        for (int longhold = 0; longhold < 2; ++longhold) {
          const Schedule s = LightThenRaise(10, light, longhold ? hold_s : 60.0, 10.0, 2.25, 10);
          const auto wl = Synthesize(*run.scene, {{sites[j].second, s.force}}, s.force.size());
          for (int refuse = 0; refuse < 2; ++refuse) {
            const Decoded d = DecodeAll(*run.model, *run.scene, wl, refuse ? std::nullopt : std::optional<bool>(false));
            held[longhold][refuse] = FirstStop(d, 1000) < s.top_last;
            if (longhold) faults[refuse] = CountFault(d, 1000, s.raise_from);
            if (refuse && longhold) refused = d.refused;
          }
        }
        std::printf("%s %-24s %.1f N held %.0f s, raised to 2.25 N: robot held refusing %d / flag only %d (after 60 s: %d / %d); "
                    "FAULT frames during the hold %zu / %zu; %zu frames refused\n",
                    run.name, sites[j].first.c_str(), light, hold_s, held[1][1], held[1][0], held[0][1], held[0][0],
                    faults[1], faults[0], refused);
        for (int refuse = 0; refuse < 2; ++refuse) {
          if (held[0][refuse]) {
            EXPECT_TRUE(held[1][refuse]) << run.name << " " << sites[j].first << " " << light << " refuse " << refuse;
          }
        }
      }
    }
  }
}

// The sweep's worst case, held long. Grating 15 sits 0.8 pm low from 20 s (a baseline error of the size a
// released edge press leaves, review field.md finding 1(a)); nothing touches for 30 min; then 2.25 N at the
// wrist edge on FBG 16, 1 s ramp, 5 s hold. Flag only, the error reads as a ~0.5 N contact, the baseline goes
// stale after max_frozen_s and the patch FAULTs (the robot stops, and stays stopped until a re-tare). Refusing,
// every frame of the error is refused, the baseline is held with its stale clock paused, nothing is reported
// for 30 min, and the press reads 0.6 N: no STOP. The property: a baseline error that hides a stop does not
// outlast max_frozen_s without a FAULT.
TEST(FaintRefusalReview, ABaselineErrorThatHidesAStopDoesNotOutlastMaxFrozenWithoutAFault) {
  const double quiet_s = std::getenv("HOLD_S") ? std::atof(std::getenv("HOLD_S")) : 1800.0;
  const auto sites = WeakSites();
  const patch::SurfacePoint at = sites[0].second;  // wrist edge at FBG 16
  const std::size_t on = 2000, press = on + static_cast<std::size_t>(quiet_s * kRate);
  std::vector<double> f(press, 0.0);
  for (int k = 1; k <= 100; ++k) f.push_back(2.25 * k / 100);
  for (int k = 0; k < 500; ++k) f.push_back(2.25);
  const std::size_t last = f.size();
  for (int k = 49; k >= 0; --k) f.push_back(2.25 * k / 50);
  for (int k = 0; k < 300; ++k) f.push_back(0.0);
  Offsets e{};
  e[14] = -0.8;
  const auto wl = Synthesize(FieldScene(), {{at, f}}, f.size(), [&](std::size_t k) { return k >= on ? e : Offsets{}; });
  const auto clean = Synthesize(FieldScene(), {{at, f}}, f.size());
  const Decoded ref = DecodeAll(FieldModel(), FieldScene(), clean, std::nullopt);
  const Decoded held = DecodeAll(FieldModel(), FieldScene(), wl, std::nullopt);
  const Decoded flag = DecodeAll(FieldModel(), FieldScene(), wl, false);
  const std::size_t first_fault_flag = [&] {
    for (std::size_t k = on; k < press; ++k) {
      if (Fault(flag.out[k])) return k;
    }
    return std::string::npos;
  }();
  std::size_t reported = 0;
  for (std::size_t k = on; k < press; ++k) reported += held.out[k].in_contact;
  std::printf("FBG15 -0.8 pm for %.0f s, then 2.25 N at the wrist edge: refusing %zu FAULT frames before the press, %zu "
              "of %zu frames reported in contact, %zu refused, press read %.2f N (STOP %s); flag only first FAULT %.1f s "
              "after the error, press read %.2f N; no error: press read %.2f N (STOP %s)\n",
              quiet_s, CountFault(held, on, press), reported, press - on, held.refused, MaxReported(held, press, last),
              FirstStop(held, press) != std::string::npos ? "yes" : "no",
              first_fault_flag == std::string::npos ? -1.0 : static_cast<double>(first_fault_flag - on) / kRate,
              MaxReported(flag, press, last), MaxReported(ref, press, last),
              FirstStop(ref, press) != std::string::npos ? "yes" : "no");
  ASSERT_NE(FirstStop(ref, press), std::string::npos) << "the press stops without the error: the test can tell";
  ASSERT_LT(first_fault_flag, on + static_cast<std::size_t>(400 * kRate)) << "flag only, the error FAULTs";
  const std::size_t limit = on + static_cast<std::size_t>((decode::BaselineFor(FieldModel(), kRate).max_frozen_s + 60) * kRate);
  std::size_t stop = std::string::npos;
  for (std::size_t k = on; k < last; ++k) {
    if (Stops(held.out[k])) {
      stop = k;
      break;
    }
  }
  EXPECT_LT(stop, limit) << "refusing: no STOP or FAULT within max_frozen_s + 60 s of the error, nor on the press";
}


// Holds: a slowly growing error. FBG 15 drifts from 0 to -0.8 or -1.2 pm over 20 min (0.001 pm/s: a grating's
// own slow drift), then stays; 2.25 N at the wrist edge at 30 min. The gate stays closed, the tracker follows
// the drift (tau 30 s: a lag of 0.03 pm), nothing is held, and the press stops in both modes. The dangerous
// error is a step (a released press's residue, finding 1), not a drift.
TEST(FaintRefusalReview, ASlowlyGrowingBaselineErrorIsTrackedAndThePressStops) {
  const auto sites = WeakSites();
  const patch::SurfacePoint at = sites[0].second;
  const std::size_t on = 2000, grow = 120000, press = 180000;
  std::vector<double> f(press, 0.0);
  for (int k = 1; k <= 100; ++k) f.push_back(2.25 * k / 100);
  for (int k = 0; k < 500; ++k) f.push_back(2.25);
  const std::size_t last = f.size();
  for (int k = 0; k < 300; ++k) f.push_back(0.0);
  for (const double final_pm : {-0.8, -1.2}) {
    const auto wl = Synthesize(FieldScene(), {{at, f}}, f.size(), [&](std::size_t k) {
      Offsets e{};
      if (k >= on) e[14] = final_pm * std::min(1.0, static_cast<double>(k - on) / static_cast<double>(grow));
      return e;
    });
    for (const bool refuse : {true, false}) {
      const Decoded d = DecodeAll(FieldModel(), FieldScene(), wl, refuse ? std::nullopt : std::optional<bool>(false));
      std::size_t refused = 0, contacts = 0;
      for (std::size_t k = on; k < press; ++k) {
        refused += d.out[k].valid && d.out[k].faint && !d.out[k].in_contact;
        contacts += d.out[k].in_contact;
      }
      std::printf("FBG15 drifting to %.1f pm over 1200 s, %s: %zu frames refused, %zu in contact, %zu FAULT frames before "
                  "the press; press read %.2f N\n",
                  final_pm, refuse ? "refusing" : "flag only", refused, contacts, CountFault(d, on, press),
                  MaxReported(d, press, last));
      EXPECT_LT(FirstStop(d, press), last) << final_pm << " refuse " << refuse;
    }
  }
}


// Q4: the scene check bounds a raising stop rule (sd_k > 0) with the largest sd of the model's Uncertainty
// table. A frame can report a larger sd only through the two-touch fit (RaiseForPair: the pair's sd), which
// needs a response map. Printed for the two refusing models on one validation hour (seed 801, flag only):
// whether they carry a map, and the faint contact frames below 1 N whose reported sd exceeds the table's
// largest (those a raising rule could stop on flag only, which the refusal drops). Holds when there are none.
TEST(FaintRefusalReview, NoFaintFrameBelowTheRefusalReportsAnSdAboveTheModelsTable) {
  struct Run {
    const twin::Scene* scene;
    const v1::DecoderModel* model;
    const char* name;
  };
  for (const Run& run : {Run{&FieldScene(), &FieldModel(), "forearm-field"}, Run{&GradientScene(), &EmbeddedModel(), "forearm-embedded"}}) {
    const auto& sd = run.model->uncertainty().force_sd_n();
    ASSERT_FALSE(sd.empty());
    const float table_max = *std::max_element(sd.begin(), sd.end());
    const twin::SkinTwin t(run.scene->Patch().spec, run.scene->EffectsOf(0), {run.scene->probe.radius_mm});
    twin::FieldProtocol fp;
    fp.duration_s = 3600.0;
    std::vector<Wavelengths> wl;
    twin::RunField(t, *run.scene, fp, 801, [&](std::span<const dataset::Frame> frames) {
      for (const auto& f : frames) {
        Wavelengths w{};
        std::copy_n(f.wavelength_nm.begin(), kGratings, w.begin());
        wl.push_back(w);
      }
    });
    const Decoded d = DecodeAll(*run.model, *run.scene, wl, false);
    std::size_t faint = 0, above = 0, multiple = 0;
    float largest = 0;
    for (const auto& o : d.out) {
      if (!(o.valid && o.in_contact && o.faint && o.force_n < 1.0f)) continue;
      ++faint;
      multiple += o.multiple;
      above += o.force_sd_n > table_max;
      largest = std::max(largest, o.force_sd_n);
    }
    std::printf("%s (response map %s): %zu faint contact frames below 1 N, %zu flagged multiple, %zu with an sd above the "
                "table's %.3f N (largest %.3f N)\n",
                run.name, run.model->has_response() ? "yes" : "no", faint, multiple, above, table_max, largest);
    EXPECT_EQ(above, 0u) << run.name;
  }
}

}  // namespace
}  // namespace ruffini::eval
