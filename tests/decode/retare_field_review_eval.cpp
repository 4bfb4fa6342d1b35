// Review 6 probes of the field-separating re-tare judge (decode/retare.h, RetareConfig::separate_field), printed
// as text. Not a test: the findings are tests/decode/retare_field_review_test.cpp; this prints the counts of
// docs/reviews/retare-field.md.
//
//   retare_field_review_eval field|cobot grid|pairs|error|broad|missing|noise
//
// Every window is the twin's strain for a held press (StrainShiftsPm), plus a temperature field (pm at the grating
// centres), the common mode removed as Retare::Feed removes it (thermal_ratio x the median of the present peaks),
// judged by RetareJudge with the plain config and with SeparateField(spec) (the decoder service's). A "flip" is a
// window with a press of at least the level (0.75 N) on the cover that the plain judge refuses and the separating
// judge accepts. "in" counts flips outside the cobot scene's accepted uncovered edge bands (Y < 22.5, Y > 122.5,
// R < 19, R > 126.5 are the bands).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/decode/retare.h"
#include "ruffini/sim/scenario.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

namespace {

using namespace ruffini;
using decode::RetareConfig;
using decode::RetareJudge;
using decode::RetareOutcome;
using decode::ShiftsPm;
constexpr std::size_t kG = decode::kGratings;
constexpr double kLevel = 0.75;

struct Rig {
  twin::Scene scene;
  std::size_t patch = 0;
  v1::DecoderModel model;
  std::unique_ptr<sim::MountedScene> mounts;
  std::unique_ptr<twin::SkinTwin> skin;
  decode::BaselineConfig baseline;
  std::unique_ptr<RetareJudge> plain, sep;
  Rig(const std::string& path, const std::string& name) : scene(twin::LoadScene(path)) {
    while (scene.patches[patch].name != name) ++patch;
    model = decode::LoadModel(scene.patches[patch].model_path);
    mounts = sim::LoadMounts(scene);
    skin = std::make_unique<twin::SkinTwin>(scene.patches[patch].spec, sim::EffectsFor(scene, mounts.get(), patch),
                                            std::vector<double>{scene.probe.radius_mm});
    baseline = decode::BaselineFor(model, 100.0);
    plain = std::make_unique<RetareJudge>(model.response(), RetareConfig{kLevel});
    RetareConfig c{kLevel};
    c.SeparateField(spec());
    sep = std::make_unique<RetareJudge>(model.response(), c);
  }
  const patch::PatchSpec& spec() const { return scene.patches[patch].spec; }
  // The twin's strain for these contacts (pm), and its flags.
  std::array<double, kG> Press(const std::vector<twin::Contact>& c, std::uint32_t* flags = nullptr) const {
    twin::Shifts sh{};
    std::uint32_t f = 0;
    skin->StrainShiftsPm(c, sh, f);
    if (flags) *flags = f;
    return sh;
  }
  std::array<double, kG> Press(double y, double r, double f, std::uint32_t* flags = nullptr) const {
    return Press({twin::Contact{{y, r}, f, scene.probe}}, flags);
  }
  // As Retare::Feed hands it to the judge: common mode removed.
  ShiftsPm Window(const std::array<double, kG>& v) const {
    ShiftsPm s;
    for (std::size_t i = 0; i < kG; ++i) s[i] = static_cast<float>(v[i]);
    if (baseline.common_mode) {
      const float cm = decode::MedianOfPresent(s, baseline.min_common_mode_gratings);
      if (std::isfinite(cm)) {
        for (std::size_t i = 0; i < kG; ++i) s[i] -= baseline.thermal_ratio[i] * cm;
      }
    }
    return s;
  }
};

using FieldFn = std::function<double(double y_mm, double r_deg)>;
struct NamedField {
  std::string name;
  FieldFn f;
};

double Rad(double d) { return d * std::numbers::pi / 180.0; }

std::vector<NamedField> Fields(double arc_mm_per_deg) {
  std::vector<NamedField> v;
  v.push_back({"none", [](double, double) { return 0.0; }});
  for (const double r0 : {0.0, 72.5, 145.0, 250.0}) {
    v.push_back({"scene r0=" + std::to_string(static_cast<int>(r0)), [r0](double y, double r) {
                   return -120.0 * (y / 150.0 - 0.5) + 40.0 * std::cos(Rad(r - r0));
                 }});
  }
  v.push_back({"along 120", [](double y, double) { return -120.0 * (y / 150.0 - 0.5); }});
  v.push_back({"along -120", [](double y, double) { return 120.0 * (y / 150.0 - 0.5); }});
  for (const double r0 : {0.0, 145.0}) {
    v.push_back({"around 40 r0=" + std::to_string(static_cast<int>(r0)),
                 [r0](double, double r) { return 40.0 * std::cos(Rad(r - r0)); }});
  }
  v.push_back({"scene x10", [](double y, double r) { return -1200.0 * (y / 150.0 - 0.5) + 400.0 * std::cos(Rad(r)); }});
  for (const double b : {40.0, -40.0, 120.0, -120.0}) {
    v.push_back({"bend " + std::to_string(static_cast<int>(b)), [b](double y, double) {
                   const double u = y / 150.0 - 0.5;
                   return b * 4.0 * u * u;
                 }});
  }
  for (const double a : {40.0, -40.0}) {
    v.push_back({"cos2R " + std::to_string(static_cast<int>(a)), [a](double, double r) { return a * std::cos(2 * Rad(r)); }});
  }
  // A warm hand: a Gaussian hot spot (amplitude pm, sigma mm of surface), at three places.
  for (const double amp : {40.0, 120.0, -40.0}) {
    for (const double sig : {15.0, 30.0}) {
      for (const auto& [yc, rc] : std::vector<std::pair<double, double>>{{35.0, 50.0}, {75.0, 72.5}, {120.0, 110.0}}) {
        char name[96];
        std::snprintf(name, sizeof name, "spot %+.0f s%.0f @(%.0f,%.0f)", amp, sig, yc, rc);
        v.push_back({name, [=](double y, double r) {
                       const double dy = y - yc, da = (r - rc) * arc_mm_per_deg;
                       return amp * std::exp(-(dy * dy + da * da) / (2 * sig * sig));
                     }});
      }
    }
  }
  return v;
}

std::array<double, kG> FieldAt(const Rig& rig, const FieldFn& f) {
  std::array<double, kG> v{};
  // A grating sees the field with its own thermal sensitivity (the model's thermal_ratio, which the common-mode
  // removal assumes): a uniform warming is then removed exactly.
  for (std::size_t i = 0; i < kG; ++i) {
    v[i] = rig.baseline.thermal_ratio[i] * f(rig.spec().gratings[i].centre.y_mm, rig.spec().gratings[i].centre.r_deg);
  }
  return v;
}

bool InBands(double y, double r) { return y < 22.5 || y > 122.5 || r < 19.0 || r > 126.5; }

struct Tally {
  // seen: the plain judge refuses the press alone (no field, no error): the press the gratings see.
  // seen_flips: flips of a press the plain judge refuses alone (what the separation must not lose).
  int windows = 0, plain_refused = 0, flips = 0, flips_in = 0, seen = 0, seen_flips = 0, seen_flips_in = 0;
  double seen_worst_f = 0, seen_worst_y = 0, seen_worst_r = 0, seen_worst_alone = 0;
  bool list = false;
  double worst_f = 0, worst_y = 0, worst_r = 0, worst_read = 0;  // the heaviest flipped press
  double worst_in_f = 0, worst_in_y = 0, worst_in_r = 0, worst_in_read = 0;
  // alone: the press alone as the plain judge reads it (its force), or a negative number when not known.
  void Add(const Rig& rig, const ShiftsPm& s, double f, double y, double r, double alone = -1.0) {
    ++windows;
    const bool is_seen = alone >= kLevel;
    seen += is_seen ? 1 : 0;
    const auto a = rig.plain->Judge(s);
    if (a.outcome != RetareOutcome::kPressing) return;
    ++plain_refused;
    const auto b = rig.sep->Judge(s);
    if (b.outcome != RetareOutcome::kAccepted) return;
    ++flips;
    if (is_seen) {
      ++seen_flips;
      seen_flips_in += InBands(y, r) ? 0 : 1;
      if (f > seen_worst_f || (f == seen_worst_f && alone > seen_worst_alone)) {
        seen_worst_f = f, seen_worst_y = y, seen_worst_r = r, seen_worst_alone = alone;
      }
      if (list) std::printf("    seen flip %.2f N @(%.1f,%.1f)%s: plain alone %.2f, plain %.2f, separated %.2f\n", f, y, r,
                            InBands(y, r) ? "" : " IN", alone, a.force_n, b.force_n);
    }
    if (f > worst_f) worst_f = f, worst_y = y, worst_r = r, worst_read = b.force_n;
    if (!InBands(y, r)) {
      ++flips_in;
      if (f > worst_in_f) worst_in_f = f, worst_in_y = y, worst_in_r = r, worst_in_read = b.force_n;
    }
  }
  void Print(const char* label) const {
    std::printf("%-34s windows %6d plain-refused %6d flips %5d (in %4d)", label, windows, plain_refused, flips, flips_in);
    if (flips) std::printf("  worst %.2f N @(%.1f,%.1f) read %.2f", worst_f, worst_y, worst_r, worst_read);
    if (flips_in) std::printf("  worst-in %.2f N @(%.1f,%.1f) read %.2f", worst_in_f, worst_in_y, worst_in_r, worst_in_read);
    std::printf("\n%-34s   seen alone %6d seen-flips %5d (in %4d)", "", seen, seen_flips, seen_flips_in);
    if (seen_flips) std::printf("  worst %.2f N @(%.1f,%.1f) plain alone %.2f", seen_worst_f, seen_worst_y, seen_worst_r, seen_worst_alone);
    std::printf("\n");
  }
};

std::array<double, kG> Add(std::array<double, kG> a, const std::array<double, kG>& b, double k = 1.0) {
  for (std::size_t i = 0; i < kG; ++i) a[i] += k * b[i];
  return a;
}

const double kForces[] = {0.75, 1.0, 1.5, 2.0, 3.0, 5.0};

double Alone(const Rig& rig, const std::array<double, kG>& p) { return rig.plain->Judge(rig.Window(p)).force_n; }

struct Pressed {
  double f, y, r, alone;
  std::array<double, kG> p;
};
// The held presses of a grid (5 mm, 5 deg), those the twin does not take over range.
std::vector<Pressed> PressGrid(const Rig& rig, std::initializer_list<double> forces) {
  std::vector<Pressed> v;
  for (const double f : forces) {
    for (double y = 2.5; y < 150.0; y += 5.0) {
      for (double r = 2.5; r < 145.0; r += 5.0) {
        std::uint32_t flags = 0;
        const auto p = rig.Press(y, r, f, &flags);
        if (flags & (twin::kFlagSaturated | twin::kFlagPeakMissing)) continue;  // Feed refuses it as over range
        v.push_back({f, y, r, Alone(rig, p), p});
      }
    }
  }
  return v;
}

void Grid(const Rig& rig) {
  const double arc = rig.spec().surface_radius_mm * std::numbers::pi / 180.0;
  Tally all;
  std::vector<Tally> by_force(std::size(kForces));
  const auto grid = PressGrid(rig, {0.75, 1.0, 1.5, 2.0, 3.0, 5.0});
  for (const auto& nf : Fields(arc)) {
    if (std::getenv("ALONE")) break;
    if (const char* only = std::getenv("FIELDS"); only != nullptr && std::string(only).find(nf.name) == std::string::npos) continue;
    const auto field = FieldAt(rig, nf.f);
    Tally t;
    t.list = std::getenv("LIST") != nullptr && nf.name.find(std::getenv("LIST")) == 0;
    for (const Pressed& q : grid) {
      const std::size_t k = static_cast<std::size_t>(std::find(std::begin(kForces), std::end(kForces), q.f) - std::begin(kForces));
      const ShiftsPm s = rig.Window(Add(q.p, field));
      t.Add(rig, s, q.f, q.y, q.r, q.alone);
      by_force[k].Add(rig, s, q.f, q.y, q.r, q.alone);
      all.Add(rig, s, q.f, q.y, q.r, q.alone);
    }
    t.Print(nf.name.c_str());
  }
  for (std::size_t k = 0; k < std::size(kForces); ++k) {
    char l[32];
    std::snprintf(l, sizeof l, "force %.2f N (all fields)", kForces[k]);
    by_force[k].Print(l);
  }
  all.Print("ALL");
  // No press: the field alone (the reason for the change), to show what the separation buys.
  int field_accepted_plain = 0, field_accepted_sep = 0, fields = 0;
  for (const auto& nf : Fields(arc)) {
    const ShiftsPm s = rig.Window(FieldAt(rig, nf.f));
    ++fields;
    field_accepted_plain += rig.plain->Judge(s).outcome == RetareOutcome::kAccepted ? 1 : 0;
    const auto b = rig.sep->Judge(s);
    field_accepted_sep += b.outcome == RetareOutcome::kAccepted ? 1 : 0;
    std::printf("  field alone %-28s plain %7.2f N, separated %5.2f N\n", nf.name.c_str(), rig.plain->Judge(s).force_n, b.force_n);
  }
  std::printf("fields alone: %d, accepted plain %d, separated %d\n", fields, field_accepted_plain, field_accepted_sep);
}

void Pairs(const Rig& rig) {
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<double> uy(2.5, 147.5), ur(2.5, 142.5), uf(0.75, 3.0);
  const double arc = rig.spec().surface_radius_mm * std::numbers::pi / 180.0;
  const auto fields = Fields(arc);
  for (const int fi : {0, 1}) {
    const auto field = FieldAt(rig, fields[static_cast<std::size_t>(fi)].f);
    Tally t;
    for (int n = 0; n < 20000; ++n) {
      const double y1 = uy(rng), r1 = ur(rng), f1 = uf(rng), y2 = uy(rng), r2 = ur(rng), f2 = uf(rng);
      std::uint32_t flags = 0;
      const auto p = rig.Press({twin::Contact{{y1, r1}, f1, rig.scene.probe}, twin::Contact{{y2, r2}, f2, rig.scene.probe}}, &flags);
      if (flags & (twin::kFlagSaturated | twin::kFlagPeakMissing)) continue;
      // the heavier press names the place; "in" when either press is outside the bands
      const bool a_in = !InBands(y1, r1), b_in = !InBands(y2, r2);
      const double f = std::max(f1, f2);
      const double y = (a_in || !b_in) ? y1 : y2, r = (a_in || !b_in) ? r1 : r2;
      t.Add(rig, rig.Window(Add(p, field)), f, y, r, Alone(rig, p));
    }
    t.Print(("pairs, field " + fields[static_cast<std::size_t>(fi)].name).c_str());
  }
}

// A press plus one grating's baseline error (a released press the old baseline kept, a spliced peak).
void Error(const Rig& rig) {
  const double arc = rig.spec().surface_radius_mm * std::numbers::pi / 180.0;
  const auto grid = PressGrid(rig, {0.75, 1.0, 1.5, 2.0, 3.0});
  const auto fields = Fields(arc);
  for (const int fi : {0, 1}) {
    const auto field = FieldAt(rig, fields[static_cast<std::size_t>(fi)].f);
    for (const double e : {-3.0, 3.0, 10.0}) {
      Tally t;
      for (std::size_t g = 0; g < kG; ++g) {
        for (std::size_t n = g % 3; n < grid.size(); n += 3) {  // a third of the grid per grating
          const Pressed& q = grid[n];
          auto p = Add(q.p, field);
          p[g] += e;
          t.Add(rig, rig.Window(p), q.f, q.y, q.r, q.alone);
        }
      }
      char l[96];
      std::snprintf(l, sizeof l, "error %+.1f pm, field %s", e, fields[static_cast<std::size_t>(fi)].name.c_str());
      t.Print(l);
    }
  }
}

// A broad press: a palm, n x n probes 12 mm apart sharing the force.
void Broad(const Rig& rig) {
  const double arc = rig.spec().surface_radius_mm * std::numbers::pi / 180.0;
  const auto fields = Fields(arc);
  for (const int fi : {0, 1}) {
    const auto field = FieldAt(rig, fields[static_cast<std::size_t>(fi)].f);
    for (const int n : {2, 3, 4}) {
      Tally t;
      for (const double f : {1.0, 2.0, 4.0, 8.0}) {
        for (double y = 2.5; y < 150.0; y += 5.0) {
          for (double r = 2.5; r < 145.0; r += 5.0) {
            std::vector<twin::Contact> c;
            for (int i = 0; i < n; ++i) {
              for (int j = 0; j < n; ++j) {
                c.push_back({{y + 12.0 * (i - (n - 1) / 2.0), r + 12.0 * (j - (n - 1) / 2.0) / arc}, f / (n * n), rig.scene.probe});
              }
            }
            std::uint32_t flags = 0;
            const auto p = rig.Press(c, &flags);
            if (flags & (twin::kFlagSaturated | twin::kFlagPeakMissing)) continue;
            t.Add(rig, rig.Window(Add(p, field)), f, y, r, Alone(rig, p));
          }
        }
      }
      char l[96];
      std::snprintf(l, sizeof l, "palm %dx%d, field %s", n, n, fields[static_cast<std::size_t>(fi)].name.c_str());
      t.Print(l);
    }
  }
}

// Missing peaks: random subsets leaving `present` peaks.
void Missing(const Rig& rig) {
  std::mt19937_64 rng(9);
  const auto grid = PressGrid(rig, {0.75, 1.0, 1.5, 2.0, 3.0});
  const double arc = rig.spec().surface_radius_mm * std::numbers::pi / 180.0;
  const auto fields = Fields(arc);
  for (const int fi : {0, 1}) {
    const auto field = FieldAt(rig, fields[static_cast<std::size_t>(fi)].f);
    for (const int present : {7, 8, 9, 10, 11, 13}) {
      Tally t;
      for (const Pressed& q : grid) {
        auto p = Add(q.p, field);
        auto alone = q.p;
        std::array<std::size_t, kG> idx;
        for (std::size_t i = 0; i < kG; ++i) idx[i] = i;
        std::shuffle(idx.begin(), idx.end(), rng);
        for (std::size_t i = static_cast<std::size_t>(present); i < kG; ++i) p[idx[i]] = alone[idx[i]] = std::nan("");
        t.Add(rig, rig.Window(p), q.f, q.y, q.r, Alone(rig, alone));
      }
      char l[96];
      std::snprintf(l, sizeof l, "%d present, field %s", present, fields[static_cast<std::size_t>(fi)].name.c_str());
      t.Print(l);
    }
  }
}

// Noise on the window (sigma pm per grating: 0.03 a window's mean, 0.1 its head, 1 a drifting interrogator).
void Noise(const Rig& rig) {
  std::mt19937_64 rng(3);
  const auto grid = PressGrid(rig, {0.75, 1.0, 1.5});
  const double arc = rig.spec().surface_radius_mm * std::numbers::pi / 180.0;
  const auto fields = Fields(arc);
  for (const int fi : {0, 1}) {
    const auto field = FieldAt(rig, fields[static_cast<std::size_t>(fi)].f);
    for (const double sigma : {0.03, 0.1, 1.0}) {
      std::normal_distribution<double> nd(0.0, sigma);
      Tally t;
      for (const Pressed& q : grid) {
        auto p = Add(q.p, field);
        for (auto& v : p) v += nd(rng);
        t.Add(rig, rig.Window(p), q.f, q.y, q.r, q.alone);
      }
      char l[96];
      std::snprintf(l, sizeof l, "noise %.2f pm, field %s", sigma, fields[static_cast<std::size_t>(fi)].name.c_str());
      t.Print(l);
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s field|cobot grid|pairs|error|broad|missing|noise\n", argv[0]);
    return 2;
  }
  try {
    const std::string which = argv[1], mode = argv[2];
    const auto owned = which == "cobot"
                           ? std::make_unique<Rig>(RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml", "forearm_a")
                           : std::make_unique<Rig>(RUFFINI_SOURCE_DIR "/config/scenes/forearm-field-gradient.yaml", "forearm");
    const Rig& rig = *owned;
    if (mode == "ratios") {
      for (std::size_t i = 0; i < kG; ++i) {
        std::printf("%zu ratio %.4f twin %.3f pm/C\n", i, rig.baseline.thermal_ratio[i], rig.skin->temperature_pm_per_c()[i]);
      }
      std::printf("map %d x %d nodes, y0 %.1f dy %.1f r0 %.1f dr %.1f, stiffening %.4f\n", rig.model.response().ny(),
                  rig.model.response().nr(), rig.model.response().y0_mm(), rig.model.response().dy_mm(),
                  rig.model.response().r0_deg(), rig.model.response().dr_deg(), rig.model.response().stiffening());
    } else if (mode == "time") {
      // The judge's cost per call (Retare::Feed calls it three times on the window's last frame).
      const auto p = rig.Window(rig.Press(75.0, 72.5, 1.0));
      auto q = p;
      q[2] = q[9] = q[15] = std::nanf("");
      for (const ShiftsPm* s : {&p, static_cast<const ShiftsPm*>(&q)}) {
        for (const RetareJudge* j : {rig.plain.get(), rig.sep.get()}) {
          const int n = 200;
          double sink = 0;
          const auto t0 = std::chrono::steady_clock::now();
          for (int k = 0; k < n; ++k) sink += j->Judge(*s).force_n;
          const double us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count() / n;
          std::printf("%s, %s: %.0f us per Judge (%.3f)\n", s == &p ? "16 present" : "13 present",
                      j == rig.plain.get() ? "plain" : "separated", us, sink / n);
        }
      }
    } else if (mode == "grid") Grid(rig);
    else if (mode == "pairs") Pairs(rig);
    else if (mode == "error") Error(rig);
    else if (mode == "broad") Broad(rig);
    else if (mode == "missing") Missing(rig);
    else if (mode == "noise") Noise(rig);
    else throw std::runtime_error("unknown mode " + mode);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
