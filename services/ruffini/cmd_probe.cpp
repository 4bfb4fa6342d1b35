// grating-probe: one grating off by a fraction of a picometre, nothing touching (issue 17, review field.md
// finding 3). A synthetic stream through decode::Pipeline, the code the decoder service runs: the spec's
// nominal peaks plus Gaussian noise, a baseline captured, then one grating offset; the force reported
// (force_n on valid frames in contact, else 0) 0.5-1.5 s into the offset is tabled per grating and offset.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "commands.h"
#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/decode/touches.h"
#include "ruffini/error.h"
#include "ruffini/patch/spec_loader.h"

namespace ruffini::cli {
namespace {

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(pos));
  const std::size_t hi = std::min(v.size() - 1, lo + 1);
  return v[lo] + (pos - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

std::string Fmt(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

struct Cell {
  double median = 0, p99 = 0, flagged = 0, p99_unflagged = 0;
};

}  // namespace

void RegisterProbeCommand(CLI::App& app) {
  struct Args {
    std::string model, report, data, patch_spec = RUFFINI_DEFAULT_PATCH;
    double rate_hz = 100.0, noise_pm = 0.3, settle_s = 4.0, hold_s = 10.0, from_s = 0.5, to_s = 1.5, limit_n = 0.1;
    int repeats = 5;
    unsigned seed = 1;
    std::vector<double> offsets{-2.0, -1.0, -0.5, 0.5, 1.0, 2.0};
    decode::PipelineConfig pc;
    std::string faint_refuse = "model";
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "grating-probe",
      "One grating off by a fraction of a pm, nothing touching: the force decode::Pipeline reports (median, p99, flagged "
      "share) per grating and offset, on a synthetic noisy stream -> REPORT/probe.md");
  cmd->add_option("--model", a->model, "Model file (.rmodel)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--report", a->report, "Report folder (probe.md)")->required();
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec")->capture_default_str();
  cmd->add_option("--rate-hz", a->rate_hz, "Stream rate")->check(CLI::Range(1.0, 10000.0))->capture_default_str();
  cmd->add_option("--noise-pm", a->noise_pm, "Per-grating Gaussian noise, pm")->check(CLI::Range(0.0, 100.0))->capture_default_str();
  cmd->add_option("--offsets", a->offsets, "Offsets, pm")->capture_default_str();
  cmd->add_option("--settle-s", a->settle_s, "Quiet time after the 1 s capture, before the offset")
      ->check(CLI::Range(0.0, 600.0))->capture_default_str();
  cmd->add_option("--hold-s", a->hold_s, "How long the offset is held")->check(CLI::Range(0.1, 600.0))->capture_default_str();
  cmd->add_option("--from-s", a->from_s, "Scored window start, s into the offset")->capture_default_str();
  cmd->add_option("--to-s", a->to_s, "Scored window end, s into the offset")->capture_default_str();
  cmd->add_option("--limit-n", a->limit_n, "A case passes when its unflagged reported force's p99 is at most this")
      ->capture_default_str();
  cmd->add_option("--repeats", a->repeats, "Noise draws per case (a fresh stream and baseline each)")
      ->check(CLI::Range(1, 1000))->capture_default_str();
  cmd->add_option("--seed", a->seed, "Noise seed")->capture_default_str();
  cmd->add_option("--faint-pm", a->pc.faint_pm, "PipelineConfig::faint_pm (0: off, the decoder before it)")
      ->check(CLI::Range(0.0, 100.0))->capture_default_str();
  cmd->add_option("--faint-refuse", a->faint_refuse, kFaintRefuseHelp)
      ->check(CLI::IsMember({"model", "on", "off"}))->capture_default_str();
  cmd->add_option("--faint-max-n", a->pc.faint_max_n, "With --faint-refuse on: faint frames below this force are no contact")
      ->check(CLI::Range(0.0, 1e3))->capture_default_str();
  cmd->add_option("--data", a->data,
                  "Also decode this recording (twin data with true forces) and table the share of its contact frames "
                  "flagged faint per true force")->check(CLI::ExistingFile);
  cmd->add_option("--faint-smooth-s", a->pc.faint_smooth_s, "The faint rule's smoothing of the shifts, s")
      ->check(CLI::Range(0.0, 10.0))->capture_default_str();
  cmd->callback([a]() {
    if (!(a->from_s >= 0 && a->to_s > a->from_s && a->to_s <= a->hold_s)) {
      throw InputError("grating-probe: need 0 <= --from-s < --to-s <= --hold-s");
    }
    const patch::PatchSpec spec = patch::LoadPatchSpec(a->patch_spec);
    const v1::DecoderModel m = decode::LoadModel(a->model);
    decode::CheckModelMatchesPatch(m, spec, a->model);
    decode::PipelineConfig cfg = a->pc;
    cfg.faint_refuse = ModelOnOff(a->faint_refuse);
    cfg.baseline = decode::BaselineFor(m, a->rate_hz);
    const decode::Pipeline<float> pipe(m, spec, cfg);
    cfg = pipe.config();  // the model's choices resolved
    const int capture = cfg.baseline.capture_frames;
    const int settle = static_cast<int>(std::lround(a->settle_s * a->rate_hz));
    const int hold = static_cast<int>(std::lround(a->hold_s * a->rate_hz));
    const int from = static_cast<int>(std::lround(a->from_s * a->rate_hz));
    const int to = static_cast<int>(std::lround(a->to_s * a->rate_hz));
    const std::size_t no = a->offsets.size();
    std::vector<std::vector<Cell>> cells(kGratings, std::vector<Cell>(no));
    std::mt19937_64 rng(a->seed);
    std::normal_distribution<double> noise(0.0, a->noise_pm * 1e-3);  // nm
    int rest_contact = 0, rest_frames = 0, rest_flagged = 0;
    for (std::size_t g = 0; g < kGratings; ++g) {
      for (std::size_t k = 0; k < no; ++k) {
        std::vector<double> force, unflagged;
        int flagged = 0;
        for (int rep = 0; rep < a->repeats; ++rep) {
          decode::Pipeline<float>::Data d(pipe);
          Wavelengths wl;
          for (int f = 0; f < capture + settle + hold; ++f) {
            for (std::size_t i = 0; i < kGratings; ++i) wl[i] = spec.gratings[i].wavelength_nm + noise(rng);
            const int t = f - capture - settle;
            if (t >= 0) wl[g] += a->offsets[k] * 1e-3;
            const decode::PipelineOutput o = pipe.Process(wl, 0, d);
            const double reported = o.in_contact ? o.force_n : 0.0;
            if (t < 0 && f >= capture) {
              ++rest_frames;
              rest_contact += o.in_contact ? 1 : 0;
              rest_flagged += o.faint ? 1 : 0;
            }
            if (t >= from && t < to) {
              force.push_back(reported);
              flagged += o.faint ? 1 : 0;
              unflagged.push_back(o.faint ? 0.0 : reported);
            }
          }
        }
        Cell& c = cells[g][k];
        c.median = Quantile(force, 0.5);
        c.p99 = Quantile(force, 0.99);
        c.flagged = force.empty() ? 0.0 : static_cast<double>(flagged) / static_cast<double>(force.size());
        c.p99_unflagged = Quantile(unflagged, 0.99);
      }
    }
    std::ostringstream md;
    md << "# One grating off, nothing touching (`ruffini grating-probe`)\n\n";
    md << "model `" << a->model << "`, " << a->rate_hz << " Hz, noise " << a->noise_pm << " pm, " << a->repeats
       << " streams per case (1 s capture, " << a->settle_s << " s quiet, offset held " << a->hold_s << " s), scored "
       << a->from_s << "-" << a->to_s << " s into the offset; faint rule "
       << (cfg.faint_pm > 0 ? "below " + Fmt(cfg.faint_pm) + " pm smoothed over " + Fmt(cfg.faint_smooth_s) + " s" +
                                  (cfg.faint_refuse.value_or(false) ? ", refused under " + Fmt(cfg.faint_max_n) + " N" : std::string(", flag only"))
                            : std::string("off"))
       << ". Reported force: force_n on frames in contact, else 0. Contact frames at rest before the offsets: "
       << rest_contact << " of " << rest_frames << " (flagged: " << rest_flagged << ").\n\n";
    md << "Median / p99 reported force (N), and the share of scored frames flagged `faint`:\n\n| FBG |";
    for (double o : a->offsets) md << ' ' << (o > 0 ? "+" : "") << o << " pm |";
    md << "\n|---|";
    for (std::size_t k = 0; k < no; ++k) md << "---|";
    md << '\n';
    char buf[96];
    for (std::size_t g = 0; g < kGratings; ++g) {
      md << "| " << g + 1 << " |";
      for (std::size_t k = 0; k < no; ++k) {
        const Cell& c = cells[g][k];
        std::snprintf(buf, sizeof buf, " %.2f / %.2f", c.median, c.p99);
        md << buf;
        if (c.flagged > 0) {
          std::snprintf(buf, sizeof buf, " (%.0f %%)", 100.0 * c.flagged);
          md << buf;
        }
        md << " |";
      }
      md << '\n';
    }
    int cases = 0, over = 0, fail = 0;
    double worst = 0.0;
    for (std::size_t g = 0; g < kGratings; ++g) {
      for (std::size_t k = 0; k < no; ++k) {
        const double o = std::abs(a->offsets[k]);
        if (!(std::abs(o - 0.5) < 1e-9 || std::abs(o - 1.0) < 1e-9)) continue;
        ++cases;
        over += cells[g][k].p99 > a->limit_n ? 1 : 0;
        fail += cells[g][k].p99_unflagged > a->limit_n ? 1 : 0;
        worst = std::max(worst, cells[g][k].p99_unflagged);
      }
    }
    std::snprintf(buf, sizeof buf, "%.2f", worst);
    md << "\n**Summary, offsets of +-0.5 and +-1 pm:** " << cases << " cases; reported p99 above " << a->limit_n
       << " N in " << over << "; above it counting flagged frames as 0 (the target: at most " << a->limit_n
       << " N, or flagged) in **" << fail << "** (largest " << buf << " N).\n";
    if (!a->data.empty()) {
      // The flag on a recording: per true-force bin, the contact frames and the share flagged faint (and, with
      // faint frames refused: those are counted as flagged and not in contact).
      const dataset::Dataset data = dataset::ReadDataset(a->data);
      if (data.info.patch_name != m.patch_name()) throw InputError(a->data + ": not a recording of the model's patch");
      decode::PipelineConfig rc = cfg;
      rc.baseline = decode::BaselineFor(m, data.info.sample_rate_hz);
      const decode::Pipeline<float> rp(m, spec, rc);
      decode::Pipeline<float>::Data rd(rp);
      const std::vector<double> edges{0.0, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 1.5, 2.0, 1e9};
      std::vector<long> frames(edges.size() - 1), contact(edges.size() - 1), flagged(edges.size() - 1);
      Wavelengths wl;
      for (std::size_t k = 0; k < data.size(); ++k) {
        for (std::size_t i = 0; i < kGratings; ++i) wl[i] = data.wavelength_nm[k][i];
        const decode::PipelineOutput o = rp.Process(wl, data.flags[k], rd);
        const double f = std::isfinite(data.true_force_n[k]) ? data.true_force_n[k] : data.force_n[k];
        if (!std::isfinite(f)) continue;
        std::size_t b = 0;
        while (b + 2 < edges.size() && f >= edges[b + 1]) ++b;
        ++frames[b];
        contact[b] += o.in_contact ? 1 : 0;
        flagged[b] += o.faint ? 1 : 0;
      }
      md << "\nThe flag on `" << a->data << "` (" << data.size()
         << " frames, decoded as one stream): per true force, the frames, the share reported in contact, and the share "
            "flagged `faint` among the frames in contact or flagged:\n\n| true force (N) | frames | in contact | flagged |\n"
            "|---|---|---|---|\n";
      for (std::size_t b = 0; b + 1 < edges.size(); ++b) {
        const long seen = contact[b] + (cfg.faint_refuse.value_or(false) ? flagged[b] : 0);
        std::snprintf(buf, sizeof buf, "| %.2f - %s | %ld | %.2f %% | %.2f %% |\n", edges[b],
                      b + 2 < edges.size() ? Fmt(edges[b + 1]).c_str() : "...", frames[b],
                      frames[b] ? 100.0 * static_cast<double>(contact[b]) / static_cast<double>(frames[b]) : 0.0,
                      seen ? 100.0 * static_cast<double>(flagged[b]) / static_cast<double>(seen) : 0.0);
        md << buf;
      }
    }
    if (m.has_response()) {
      // What the map says of a lone shift: the share a single touch (force >= 0) leaves unexplained of -1 / +1 pm
      // on one grating, and the most negative response any place of the map gives that grating.
      const decode::TouchCheck tc(m.response());
      const decode::ResponseModel& r = tc.model();
      md << "\nThe response map (" << r.ny << " x " << r.nr << " nodes, Y " << r.y0_mm << ".." << r.y0_mm + (r.ny - 1) * r.dy_mm
         << " mm, R " << r.r0_deg << ".." << r.r0_deg + (r.nr - 1) * r.dr_deg
         << " deg) on a lone shift: the share of its energy the best single touch leaves unexplained, and the grating's "
            "most negative and largest response over the map (pm/N):\n\n| FBG | -1 pm | +1 pm | min g | max g |\n|---|---|---|---|---|\n";
      for (std::size_t g = 0; g < kGratings; ++g) {
        decode::ShiftsPm lone{};
        lone[g] = -1.0f;
        const double neg = tc.Unexplained(lone);
        lone[g] = 1.0f;
        const double pos = tc.Unexplained(lone);
        double lo = 0, hi = 0;
        for (const auto& node : r.g) {
          lo = std::min(lo, static_cast<double>(node[g]));
          hi = std::max(hi, static_cast<double>(node[g]));
        }
        std::snprintf(buf, sizeof buf, "| %zu | %.2f | %.2f | %.1f | %.1f |\n", g + 1, neg, pos, lo, hi);
        md << buf;
      }
    }
    std::filesystem::create_directories(a->report);
    const std::string path = (std::filesystem::path(a->report) / "probe.md").string();
    std::ofstream(path) << md.str();
    std::fputs(md.str().c_str(), stdout);
    std::printf("wrote %s\n", path.c_str());
  });
}

}  // namespace ruffini::cli
