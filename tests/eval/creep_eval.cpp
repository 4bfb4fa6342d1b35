// Not a test: prints the figures of docs/experiments/creep-fit.md. For one model and one field recording
// (`ruffini simulate --protocol field`):
// - what FitCreep's regression sees: (decoded - applied force) on the applied force low-passed with tau 1 / 10 /
//   100 s, its unconstrained least-squares solution, and the same with a free scale term (the applied force
//   itself) beside the three;
// - the decoded force of the long presses (held 30 s or more) and after their release, decoded as one stream
//   through decode::Pipeline, for each creep compensation given (--creep g1,g2,g3; "model" = the file's,
//   "none" = cleared).
//
//   creep_eval --model M.rmodel [--twin-g 0.05,0.04,0.03] [--creep none|model|g1,g2,g3]... DATA.h5
#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/eval/calibrate.h"
#include "ruffini/eval/stream.h"
#include "ruffini/patch/spec_loader.h"
#include "ruffini/stats.h"

using namespace ruffini;

namespace {

constexpr std::array<double, 3> kTau = {1.0, 10.0, 100.0};
bool g_per_press = false;
std::array<double, 3> g_twin{};
const std::vector<std::array<double, 3>>* g_x = nullptr;

std::array<double, 3> ParseG(const std::string& s) {
  std::array<double, 3> g{};
  if (std::sscanf(s.c_str(), "%lf,%lf,%lf", &g[0], &g[1], &g[2]) != 3) {
    std::fprintf(stderr, "bad g list: %s\n", s.c_str());
    std::exit(2);
  }
  return g;
}

double Ref(const dataset::Dataset& d, std::size_t k) {
  return std::isfinite(d.true_force_n[k]) ? d.true_force_n[k] : d.force_n[k];
}

eval::StreamPredictions Decode(const v1::DecoderModel& m, const patch::PatchSpec& spec, const dataset::Dataset& d) {
  decode::PipelineConfig c;
  c.baseline = decode::BaselineFor(m, d.info.sample_rate_hz);
  c.z_limit = std::numeric_limits<double>::infinity();  // as FitCreep decodes
  v1::DecoderModel open = m;
  open.clear_input_range();
  const decode::Pipeline<float> pipe(open, spec, c);
  return eval::DecodeStream(pipe, d);
}

// Applied force low-passed with each tau (the twin's discretisation, as FitCreep).
std::vector<std::array<double, 3>> Filtered(const dataset::Dataset& d) {
  const double dt = 1.0 / d.info.sample_rate_hz;
  std::array<double, 3> a{}, x{};
  for (std::size_t j = 0; j < 3; ++j) a[j] = 1.0 - std::exp(-dt / kTau[j]);
  std::vector<std::array<double, 3>> out(d.size());
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double r = Ref(d, k);
    const double f = std::isfinite(r) ? std::max(0.0, r) : 0.0;
    for (std::size_t j = 0; j < 3; ++j) x[j] += a[j] * (f - x[j]);
    out[k] = x;
  }
  return out;
}

struct Press {
  std::size_t first, hold_first, hold_last, last, next;  // next: the next press's first frame (or the end)
  double peak;
};

std::vector<Press> Presses(const dataset::Dataset& d) {
  std::vector<Press> out;
  std::size_t k = 0;
  while (k < d.size()) {
    if (d.indentation[k] < 0) {
      ++k;
      continue;
    }
    const std::int32_t id = d.indentation[k];
    Press p{k, k, k, k, d.size(), 0.0};
    std::size_t e = k;
    while (e < d.size() && d.indentation[e] == id) {
      p.peak = std::max(p.peak, Ref(d, e));
      ++e;
    }
    p.last = e - 1;
    bool first = true;
    for (std::size_t i = k; i < e; ++i) {
      if (Ref(d, i) >= 0.98 * p.peak) {
        if (first) p.hold_first = i;
        first = false;
        p.hold_last = i;
      }
    }
    out.push_back(p);
    k = e;
  }
  for (std::size_t i = 0; i + 1 < out.size(); ++i) out[i].next = out[i + 1].first;
  return out;
}

double Mean(const eval::StreamPredictions& p, std::size_t a, std::size_t b) {  // valid frames in [a, b)
  double s = 0;
  std::size_t n = 0;
  for (std::size_t k = a; k < b && k < p.size(); ++k) {
    if (!p.valid[k]) continue;
    s += p.force_n[k];
    ++n;
  }
  return n ? s / static_cast<double>(n) : std::nan("");
}

void Regressions(const dataset::Dataset& d, const eval::StreamPredictions& p, const std::vector<std::array<double, 3>>& x,
                 const std::array<double, 3>& twin_g) {
  // Rows as FitCreep takes them: every valid frame with a finite reference. Columns x1, x10, x100 and F.
  Eigen::Matrix4d ata = Eigen::Matrix4d::Zero();
  Eigen::Vector4d atb = Eigen::Vector4d::Zero();
  Eigen::Matrix4d ata_in = Eigen::Matrix4d::Zero();
  Eigen::Vector4d atb_in = Eigen::Vector4d::Zero();
  double sse0 = 0, sse0_in = 0;
  std::size_t n = 0, n_in = 0;
  // The nets' reading against the twin's strain force F_eff = F + sum g x: a scale s.
  double fe_fe = 0, fe_p = 0;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double r = Ref(d, k);
    if (!p.valid[k] || !std::isfinite(r)) continue;
    const Eigen::Vector4d row(x[k][0], x[k][1], x[k][2], std::max(0.0, r));
    const double e = p.force_n[k] - r;
    ata += row * row.transpose();
    atb += row * e;
    sse0 += e * e;
    ++n;
    if (d.indentation[k] >= 0) {
      ata_in += row * row.transpose();
      atb_in += row * e;
      sse0_in += e * e;
      ++n_in;
    }
    const double fe = std::max(0.0, r) + twin_g[0] * x[k][0] + twin_g[1] * x[k][1] + twin_g[2] * x[k][2];
    if (d.indentation[k] >= 0) {
      fe_fe += fe * fe;
      fe_p += fe * p.force_n[k];
    }
  }
  const auto solve = [](const Eigen::Matrix4d& A, const Eigen::Vector4d& b, int cols, double sse, std::size_t rows,
                        const char* what) {
    const Eigen::VectorXd s = A.topLeftCorner(cols, cols).ldlt().solve(b.head(cols));
    const double sse1 = sse - s.dot(b.head(cols));
    std::printf("  %-46s g = %+.4f / %+.4f / %+.4f", what, s[0], s[1], s[2]);
    if (cols == 4) std::printf(", scale term %+.4f", s[3]);
    std::printf("  (rms residual %.1f -> %.1f mN over %zu frames)\n", 1e3 * std::sqrt(sse / static_cast<double>(rows)),
                1e3 * std::sqrt(std::max(0.0, sse1) / static_cast<double>(rows)), rows);
  };
  std::printf("regression of decoded - applied force (no compensation), unconstrained least squares:\n");
  solve(ata, atb, 3, sse0, n, "FitCreep's rows, x terms only:");
  solve(ata, atb, 4, sse0, n, "FitCreep's rows, x terms + scale:");
  solve(ata_in, atb_in, 3, sse0_in, n_in, "press frames only, x terms only:");
  solve(ata_in, atb_in, 4, sse0_in, n_in, "press frames only, x terms + scale:");
  std::printf("  correlation of the columns x1, x10, x100, F (FitCreep's rows):\n");
  for (int i = 0; i < 4; ++i) {
    std::printf("   ");
    for (int j = 0; j < 4; ++j) std::printf(" %.3f", ata(i, j) / std::sqrt(ata(i, i) * ata(j, j)));
    std::printf("\n");
  }
  std::printf("decoded force / the twin's strain force F + sum g x (g %.3f / %.3f / %.3f), press frames: %.4f\n",
              twin_g[0], twin_g[1], twin_g[2], fe_p / fe_fe);
}

void Presses(const dataset::Dataset& d, const std::vector<Press>& presses, const eval::StreamPredictions& p,
             const char* label) {
  const std::size_t rate = static_cast<std::size_t>(std::lround(d.info.sample_rate_hz));
  std::vector<double> start, end, drift, after1, after10, after30, low;
  std::vector<double> err_all;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double r = Ref(d, k);
    // Invalid frames count as 0 N (as the bench scores the shipped pipeline).
    if (std::isfinite(r) && r > 0.05) err_all.push_back(std::abs((p.valid[k] ? p.force_n[k] : 0.0) - r) * 1e3);
  }
  std::array<std::size_t, decode::kReasonCount> reasons{};
  double first_stale_s = -1;
  for (std::size_t k = 0; k < d.size(); ++k) {
    ++reasons[p.reason[k]];
    if (first_stale_s < 0 && p.reason[k] == static_cast<std::uint8_t>(decode::Reason::kBaselineStale)) {
      first_stale_s = static_cast<double>(k) / d.info.sample_rate_hz;
    }
  }
  std::printf("%-26s frames by reason:", label);
  for (std::size_t r = 0; r < reasons.size(); ++r) {
    if (reasons[r]) std::printf(" %s %zu", std::string(decode::ReasonName(static_cast<decode::Reason>(r))).c_str(), reasons[r]);
  }
  std::printf("; first stale frame at %.1f s\n", first_stale_s);
  int n = 0;
  for (const Press& q : presses) {
    const double hold_s = static_cast<double>(q.hold_last - q.hold_first) / d.info.sample_rate_hz;
    if (hold_s < 30.0 || q.peak < 0.3) continue;
    ++n;
    const double s = Mean(p, q.hold_first + rate / 2, q.hold_first + 3 * rate / 2) / q.peak - 1.0;
    const double e = Mean(p, q.hold_last - rate, q.hold_last) / q.peak - 1.0;
    start.push_back(100 * s);
    end.push_back(100 * e);
    drift.push_back(100 * (e - s));
    const std::size_t rel = q.last + 1;
    const auto window = [&](double a_s, double b_s, std::vector<double>& into) {
      const std::size_t a = rel + static_cast<std::size_t>(a_s * d.info.sample_rate_hz);
      const std::size_t b = rel + static_cast<std::size_t>(b_s * d.info.sample_rate_hz);
      if (b <= q.next) into.push_back(1e3 * Mean(p, a, b) / q.peak);  // mN per N of the press
    };
    window(1, 3, after1);
    window(8, 12, after10);
    window(25, 30, after30);
    double lo = 0;
    for (std::size_t k = rel; k < q.next; ++k) {
      if (p.valid[k]) lo = std::min(lo, static_cast<double>(p.force_n[k]));
    }
    low.push_back(1e3 * lo / q.peak);
  }
  if (g_per_press) {
    std::printf("  press  peak N  hold s   y mm   r deg   start/F  end/F   F_eff_end/F   after 1-3 s mN\n");
    for (const Press& q : presses) {
      const double hold_s = static_cast<double>(q.hold_last - q.hold_first) / d.info.sample_rate_hz;
      const double s = Mean(p, q.hold_first + rate / 2, q.hold_first + 3 * rate / 2) / q.peak;
      const double e = Mean(p, q.hold_last - rate, q.hold_last) / q.peak;
      const std::size_t rel = q.last + 1;
      const double a = rel + 3 * rate <= q.next ? 1e3 * Mean(p, rel + rate, rel + 3 * rate) : std::nan("");
      const auto& xe = g_x->at(q.hold_last);
      const double fe = 1.0 + (g_twin[0] * xe[0] + g_twin[1] * xe[1] + g_twin[2] * xe[2]) / q.peak;
      std::printf("  %5d  %6.3f  %6.1f  %6.1f  %6.1f   %6.3f  %6.3f   %6.3f   %+7.1f\n", d.indentation[q.first], q.peak,
                  hold_s, d.y_mm[q.hold_first], d.r_deg[q.hold_first], s, e, fe, a);
    }
  }
  const auto med = [](std::vector<double> v) { return v.empty() ? std::nan("") : stats::Median(v); };
  std::printf("%-26s median |error| pressed frames (invalid = 0 N) %.1f mN; %d long presses (held >= 30 s, >= 0.3 N), medians: "
              "error at hold start %+.1f %%, at hold end %+.1f %% (drift %+.1f %%); after release, mN per N of the press: "
              "1-3 s %+.1f (%zu), 8-12 s %+.1f (%zu), 25-30 s %+.1f (%zu), lowest before the next press %+.1f\n",
              label, med(err_all), n, med(start), med(end), med(drift), med(after1), after1.size(), med(after10),
              after10.size(), med(after30), after30.size(), med(low));
}

}  // namespace

int main(int argc, char** argv) {
  std::string model_path, data_path;
  std::array<double, 3> twin_g = {0.05, 0.04, 0.03};
  std::vector<std::string> creeps;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--model" && i + 1 < argc) {
      model_path = argv[++i];
    } else if (a == "--twin-g" && i + 1 < argc) {
      twin_g = ParseG(argv[++i]);
    } else if (a == "--per-press") {
      g_per_press = true;
    } else if (a == "--creep" && i + 1 < argc) {
      creeps.push_back(argv[++i]);
    } else {
      data_path = a;
    }
  }
  if (model_path.empty() || data_path.empty()) {
    std::fprintf(stderr, "usage: creep_eval --model M.rmodel [--twin-g g1,g2,g3] [--creep none|model|g1,g2,g3]... DATA.h5\n");
    return 2;
  }
  if (creeps.empty()) creeps = {"none", "model"};
  const v1::DecoderModel model = decode::LoadModel(model_path);
  const patch::PatchSpec spec = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  const dataset::Dataset d = dataset::ReadDataset(data_path);
  const auto x = Filtered(d);
  const auto presses = Presses(d);
  g_twin = twin_g;
  g_x = &x;
  std::printf("%s on %s: %zu presses\n", model_path.c_str(), data_path.c_str(), presses.size());
  if (model.has_creep()) {
    std::printf("the file's creep g:");
    for (int k = 0; k < model.creep().g_size(); ++k) std::printf(" %.4f", model.creep().g(k));
    std::printf("\n");
  }
  v1::DecoderModel bare = model;
  bare.clear_creep();
  const auto p0 = Decode(bare, spec, d);
  Regressions(d, p0, x, twin_g);
  const v1::CreepCompensation fit = eval::FitCreep(model, spec, d);
  std::printf("FitCreep: g = %.4f / %.4f / %.4f\n", fit.g(0), fit.g(1), fit.g(2));
  for (const std::string& c : creeps) {
    v1::DecoderModel m = model;
    if (c == "none") {
      m.clear_creep();
    } else if (c != "model") {
      const auto g = ParseG(c);
      m.clear_creep();
      for (std::size_t j = 0; j < 3; ++j) {
        m.mutable_creep()->add_g(static_cast<float>(g[j]));
        m.mutable_creep()->add_tau_s(static_cast<float>(kTau[j]));
      }
    }
    const auto p = c == "none" ? p0 : Decode(m, spec, d);
    Presses(d, presses, p, ("creep " + c + ":").c_str());
  }
  return 0;
}
