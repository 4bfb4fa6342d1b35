// Not a test: prints the tables of docs/experiments/retare.md. Field hours (`ruffini simulate --protocol
// field`) decoded as one stream through decode::Pipeline, as `ruffini evaluate` does, twice: as shipped
// (a stale baseline stays stale), and with an operator who asks for a re-tare (decode::Retare) when the
// patch goes `baseline_stale` and again every --every-s while it stays stale. Counted per hour: the time
// stale (the decoder's FAULT), the part of it with no press at or above the threshold (no present cause),
// the re-tares by outcome, those refused while something pressed, and those accepted while something
// pressed (what a re-tare absorbed: its largest true force).
//
//   retare_eval --model M.rmodel [--level-n 0.75] [--every-s 10] [--threshold-n 1.5] [--dry-run] [--separate-field] DATA.h5...
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/decode/retare.h"
#include "ruffini/patch/spec_loader.h"

using namespace ruffini;

namespace {

// --separate-field: the judge separates a first-order temperature field from a touch (RetareConfig).
bool g_separate_field = false;
const patch::PatchSpec* g_spec = nullptr;

struct Run {
  double hours = 0, stale_s = 0, stale_no_cause_s = 0, longest_stale_s = 0;
  int stale_episodes = 0;
  int requests = 0;
  std::array<int, decode::kRetareOutcomeCount> outcomes{};
  int refused_pressing_while_pressed = 0;   // kPressing with a true press (> 20 mN) in the window
  int refused_pressing_nothing = 0;         // kPressing with nothing pressing (a refusal the map caused)
  int accepted_while_pressed = 0;           // accepted with a true press (> 20 mN) in the window
  double accepted_max_true_n = 0;           // the largest true force an accepted window held
  double accepted_max_judged_n = 0;         // the largest force the judge found in an accepted window
  double refused_min_true_n = 1e9;          // the lightest true press (window max) a kPressing refusal saw
};

Run Decode(const v1::DecoderModel& m, const patch::PatchSpec& spec, const dataset::Dataset& d, bool operator_on,
           double level_n, double every_s, double threshold_n, double min_shift_pm) {
  decode::PipelineConfig cfg;
  cfg.baseline = decode::BaselineFor(m, d.info.sample_rate_hz);
  const decode::Pipeline<float> pipe(m, spec, cfg);
  decode::Pipeline<float>::Data data(pipe);
  decode::RetareConfig rc;
  rc.min_force_n = level_n;
  rc.min_shift_pm = min_shift_pm;
  if (g_separate_field) rc.SeparateField(*g_spec);
  decode::Retare retare(m.has_response() ? &m.response() : nullptr, cfg.baseline, rc);
  const double dt = 1.0 / d.info.sample_rate_hz;
  Run r;
  r.hours = static_cast<double>(d.size()) * dt / 3600.0;
  double run_s = 0, last_request_s = -1e9, window_max_true = 0;
  bool was_stale = false;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double t = static_cast<double>(k) * dt;
    Wavelengths wl;
    for (std::size_t i = 0; i < kGratings; ++i) wl[i] = d.wavelength_nm[k][i];
    const decode::PipelineOutput o = pipe.Process(wl, d.flags[k], data);
    const bool stale = o.reason == decode::Reason::kBaselineStale;
    const float truth = d.true_force_n[k];
    if (stale) {
      r.stale_s += dt;
      if (!(truth > threshold_n)) r.stale_no_cause_s += dt;
      run_s += dt;
      r.longest_stale_s = std::max(r.longest_stale_s, run_s);
      if (!was_stale) ++r.stale_episodes;
    } else {
      run_s = 0;
    }
    was_stale = stale;
    if (!operator_on) continue;
    if (retare.active()) {
      window_max_true = std::max(window_max_true, static_cast<double>(truth));
      const auto res = retare.Feed(wl, o, data.baseline());
      if (!res) continue;
      ++r.outcomes[static_cast<std::size_t>(res->outcome)];
      const bool pressed = window_max_true > 0.02;
      if (std::getenv("RETARE_VERBOSE") != nullptr) {
        std::fprintf(stderr, "t %.1f %s judged %.2f N at (%.1f, %.1f) motion %.2f pm true max %.2f N\n", t,
                     std::string(decode::RetareOutcomeName(res->outcome)).c_str(), res->force_n, res->y_mm, res->r_deg,
                     res->motion_pm, window_max_true);
      }
      if (res->outcome == decode::RetareOutcome::kAccepted) {
        pipe.Retare(retare.baseline_nm(), data);
        if (pressed) ++r.accepted_while_pressed;
        r.accepted_max_true_n = std::max(r.accepted_max_true_n, window_max_true);
        r.accepted_max_judged_n = std::max(r.accepted_max_judged_n, res->force_n);
      } else if (res->outcome == decode::RetareOutcome::kPressing) {
        if (pressed) {
          ++r.refused_pressing_while_pressed;
          r.refused_min_true_n = std::min(r.refused_min_true_n, window_max_true);
        } else {
          ++r.refused_pressing_nothing;
        }
      }
    } else if (stale && t - last_request_s >= every_s) {
      last_request_s = t;
      ++r.requests;
      retare.Start();
      window_max_true = truth;
    }
  }
  return r;
}

// Dry run: a re-tare judged (never applied) every every_s through the whole hour, whatever the state, against
// the true force in its window: what the rule would absorb if asked at any moment.
struct Dry {
  int windows = 0;
  int pressed_at_level = 0, pressed_at_level_accepted = 0;   // true force >= level somewhere in the window
  int light = 0, light_accepted = 0;                          // 20 mN < true max < level
  int untouched = 0, untouched_refused = 0;                   // true max <= 20 mN
  int moving = 0;
  double accepted_max_true_n = 0;                             // the largest true force in an accepted window
};

Dry DryRun(const v1::DecoderModel& m, const patch::PatchSpec& spec, const dataset::Dataset& d, double level_n,
           double every_s, double min_shift_pm) {
  decode::PipelineConfig cfg;
  cfg.baseline = decode::BaselineFor(m, d.info.sample_rate_hz);
  const decode::Pipeline<float> pipe(m, spec, cfg);
  decode::Pipeline<float>::Data data(pipe);
  decode::RetareConfig rc;
  rc.min_force_n = level_n;
  rc.min_shift_pm = min_shift_pm;
  if (g_separate_field) rc.SeparateField(*g_spec);
  decode::Retare retare(m.has_response() ? &m.response() : nullptr, cfg.baseline, rc);
  const double dt = 1.0 / d.info.sample_rate_hz;
  Dry r;
  double next_s = every_s, window_max_true = 0;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double t = static_cast<double>(k) * dt;
    Wavelengths wl;
    for (std::size_t i = 0; i < kGratings; ++i) wl[i] = d.wavelength_nm[k][i];
    const decode::PipelineOutput o = pipe.Process(wl, d.flags[k], data);
    const float truth = d.true_force_n[k];
    if (retare.active()) {
      window_max_true = std::max(window_max_true, static_cast<double>(truth));
      const auto res = retare.Feed(wl, o, data.baseline());
      if (!res) continue;
      if (res->outcome == decode::RetareOutcome::kMoving) {
        ++r.moving;
        continue;
      }
      if (res->outcome != decode::RetareOutcome::kAccepted && res->outcome != decode::RetareOutcome::kPressing) continue;
      const bool accepted = res->outcome == decode::RetareOutcome::kAccepted;
      ++r.windows;
      if (window_max_true >= level_n) {
        ++r.pressed_at_level;
        r.pressed_at_level_accepted += accepted ? 1 : 0;
        if (accepted && std::getenv("RETARE_VERBOSE") != nullptr) {
          const std::size_t k0 = k + 1 - static_cast<std::size_t>(res->frames);
          std::fprintf(stderr, "dry t %.1f accepted with a press: true %.2f..%.2f N (max %.2f) at (%.1f, %.1f); judged %.2f\n",
                       t, d.true_force_n[k0], truth, window_max_true, d.y_mm[k], d.r_deg[k], res->force_n);
        }
      } else if (window_max_true > 0.02) {
        ++r.light;
        r.light_accepted += accepted ? 1 : 0;
      } else {
        ++r.untouched;
        r.untouched_refused += accepted ? 0 : 1;
      }
      if (accepted) r.accepted_max_true_n = std::max(r.accepted_max_true_n, window_max_true);
    } else if (t >= next_s && data.baseline().state() != decode::BaselineTracker::State::kCapturing) {
      next_s = t + every_s;
      retare.Start();
      window_max_true = truth;
    }
  }
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  std::string model_path;
  double level_n = 0.75, every_s = 10.0, threshold_n = 1.5, min_shift_pm = decode::RetareConfig{}.min_shift_pm;
  std::vector<std::string> files;
  bool dry = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--model") model_path = next();
    else if (a == "--level-n") level_n = std::stod(next());
    else if (a == "--every-s") every_s = std::stod(next());
    else if (a == "--threshold-n") threshold_n = std::stod(next());
    else if (a == "--min-shift-pm") min_shift_pm = std::stod(next());
    else if (a == "--dry-run") dry = true;
    else if (a == "--separate-field") g_separate_field = true;
    else files.push_back(a);
  }
  if (model_path.empty() || files.empty()) {
    std::fprintf(stderr, "usage: retare_eval --model M.rmodel [--level-n N] [--every-s S] [--threshold-n N] [--min-shift-pm P] [--dry-run] [--separate-field] DATA.h5...\n");
    return 2;
  }
  const v1::DecoderModel m = decode::LoadModel(model_path);
  const patch::PatchSpec spec = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  g_spec = &spec;
  std::printf("model %s (response map: %s), level %.2f N, min shift %.2f pm, operator every %.0f s while stale, "
              "threshold %.2f N\n\n",
              model_path.c_str(), m.has_response() ? "yes" : "no", level_n, min_shift_pm, every_s, threshold_n);
  if (dry) {
    std::printf("dry run: a re-tare judged every %.0f s through each hour (never applied); windows by the true force in them\n\n", every_s);
    std::printf("| data | windows judged | true >= level: refused / all | light (20 mN..level): accepted / all | "
                "untouched: refused / all | moving | largest true force accepted N |\n|---|---|---|---|---|---|---|\n");
    for (const auto& f : files) {
      const dataset::Dataset d = dataset::ReadDataset(f);
      const Dry r = DryRun(m, spec, d, level_n, every_s, min_shift_pm);
      std::printf("| %s | %d | %d / %d | %d / %d | %d / %d | %d | %.2f |\n", f.substr(f.rfind('/') + 1).c_str(), r.windows,
                  r.pressed_at_level - r.pressed_at_level_accepted, r.pressed_at_level, r.light_accepted, r.light,
                  r.untouched_refused, r.untouched, r.moving, r.accepted_max_true_n);
      std::fflush(stdout);
    }
    return 0;
  }
  std::printf("| data | hours | stale min (no cause) shipped | longest stale s | stale min (no cause) with re-tare | "
              "longest stale s | requests | accepted | pressing (pressed / nothing) | moving | invalid | "
              "accepted while pressed (max true N) | max judged N accepted | lightest press refused N |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  Run ta, tb;
  for (const auto& f : files) {
    const dataset::Dataset d = dataset::ReadDataset(f);
    const Run a = Decode(m, spec, d, false, level_n, every_s, threshold_n, min_shift_pm);
    const Run b = Decode(m, spec, d, true, level_n, every_s, threshold_n, min_shift_pm);
    using O = decode::RetareOutcome;
    auto n = [&](O o) { return b.outcomes[static_cast<std::size_t>(o)]; };
    std::printf("| %s | %.2f | %.1f (%.1f) | %.0f | %.1f (%.1f) | %.0f | %d | %d | %d (%d / %d) | %d | %d | %d (%.2f) | %.2f | %s |\n",
                f.substr(f.rfind('/') + 1).c_str(), a.hours, a.stale_s / 60, a.stale_no_cause_s / 60, a.longest_stale_s,
                b.stale_s / 60, b.stale_no_cause_s / 60, b.longest_stale_s, b.requests, n(O::kAccepted), n(O::kPressing),
                b.refused_pressing_while_pressed, b.refused_pressing_nothing, n(O::kMoving), n(O::kInvalidFrames),
                b.accepted_while_pressed, b.accepted_max_true_n, b.accepted_max_judged_n,
                b.refused_min_true_n < 1e8 ? std::to_string(b.refused_min_true_n).substr(0, 4).c_str() : "-");
    std::fflush(stdout);
  }
  return 0;
}
