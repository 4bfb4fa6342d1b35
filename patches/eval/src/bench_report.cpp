#include "ruffini/eval/bench_report.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "ruffini/error.h"
#include "ruffini/plot/svg.h"

namespace ruffini::eval {
namespace {

std::string Us(const LatencyUs& l, double v) {
  if (l.frames == 0) return "-";
  char b[32];
  std::snprintf(b, sizeof b, "%.2f", v);
  return b;
}

std::string Label(const BenchRow& r) { return r.weights.empty() ? r.configuration : r.configuration + " (" + r.weights + ")"; }

}  // namespace

std::string BenchTable(const BenchResult& result) {
  std::ostringstream md;
  md << "| # | decoder configuration | ungated p50 (us) | ungated p99 (us) | gated p50 (us) | gated p99 (us) | mean (us) "
        "| gated / timed frames | force error median (mN) | location error median (mm) | above-gate frames not located |\n";
  md << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (std::size_t k = 0; k < result.rows.size(); ++k) {
    const BenchRow& r = result.rows[k];
    const FrameLatency& l = r.latency;
    char tail[160];
    std::snprintf(tail, sizeof tail, " | %zu / %zu | %.1f | %.2f | %zu |\n", l.gated.frames, l.all.frames,
                  r.force_error_median_mn, r.location_error_median_mm, r.above_gate_not_located);
    md << "| " << k + 1 << " | " << Label(r) << " | " << Us(l.ungated, l.ungated.p50_us) << " | " << Us(l.ungated, l.ungated.p99_us)
       << " | " << Us(l.gated, l.gated.p50_us) << " | " << Us(l.gated, l.gated.p99_us) << " | " << Us(l.all, l.all.mean_us) << tail;
  }
  return md.str();
}

std::string BenchRatios(const BenchResult& result) {
  std::ostringstream md;
  auto one = [&](const char* kind, double ratio, std::size_t eigen, std::size_t best, std::size_t frames) {
    char b[512];
    if (frames == 0) {
      std::snprintf(b, sizeof b, "%s: no such frames timed", kind);
    } else {
      std::snprintf(b, sizeof b, "%s p50 %.1fx (row %zu, %s, vs row %zu, %s)", kind, ratio, eigen + 1,
                    result.rows[eigen].configuration.c_str(), best + 1, result.rows[best].configuration.c_str());
    }
    return std::string(b);
  };
  for (const auto& q : result.ratios) {
    const auto& eigen = result.rows[q.eigen_row].latency;
    md << "- Eigen vs best libtorch (" << q.weights << "), same weights, same run: "
       << one("gated", q.gated, q.eigen_row, q.best_gated_row, eigen.gated.frames) << "; "
       << one("ungated", q.ungated, q.eigen_row, q.best_ungated_row, eigen.ungated.frames) << "\n";
  }
  return md.str();
}

void WriteBench(const BenchResult& result, const std::string& dir, const std::string& command) {
  std::filesystem::create_directories(dir);
  const std::filesystem::path d(dir);
  std::ofstream out((d / "bench.md").string());
  out << "# Speed / accuracy of the decoders\n\nReproduce: `" << command << "`\n\n"
      << "One thread, per frame from raw wavelengths to the decoded frame, " << result.frames
      << " test frames timed per configuration after " << result.warmup_frames
      << " untimed warm-up frames (steady clock around each frame's step). \"shipped pipeline\" rows time "
         "decode::Pipeline::Process, the decoder service's whole per-frame path (plausibility checks, baseline frozen "
         "by the decoder's gate, the networks, creep compensation, calibrated uncertainty), run over the whole stream "
         "in order from its first frame (frames between test indentations processed untimed), never reset; gated: "
         "the output's in_contact. The other rows time the baseline update and the decoder alone, each test "
         "indentation started from the baseline tracker's state at that point of the stream; gated: the decoder "
         "located. libtorch runs with one intra-op and one inter-op thread, under "
         "c10::InferenceMode; \"TorchScript frozen\" is the same nets as TorchScript, torch::jit::freeze and "
         "optimize_for_inference. Errors are over the whole test set (the models' held-out indentations); the shipped "
         "pipeline's from one continuous pass over the stream (invalid frames count as 0 N). Location "
         "error is over the above-gate frames a decoder located; the last column counts those it did not. The "
         "inversion decoder returns at once on untouched frames (every shift under 3 pm).\n\n"
      << BenchTable(result);
  if (!result.ratios.empty()) out << "\nLatency ratio (libtorch p50 / Eigen p50; Eigen: the shipped pipeline row, decode::Pipeline<float>; the libtorch "
                                    "rows time the baseline and the nets only, without the pipeline's checks and uncertainty):\n\n" << BenchRatios(result);
  out << "\n![Pareto](pareto.svg)\n";
  if (!out) throw InputError((d / "bench.md").string() + ": cannot write");
  plot::Figure fig("Speed vs location accuracy (test set)", "gated p50 latency per frame (us)", "location error median (mm)", 760, 480);
  fig.SetLogX(true);
  plot::Series pts{"configurations", {}, {}, "#1f77b4", plot::Series::Style::kPoints};
  for (std::size_t k = 0; k < result.rows.size(); ++k) {
    const auto& r = result.rows[k];
    if (r.latency.gated.frames == 0) continue;
    pts.x.push_back(r.latency.gated.p50_us);
    pts.y.push_back(r.location_error_median_mm);
    fig.AddMarker({r.latency.gated.p50_us, r.location_error_median_mm, std::to_string(k + 1)});
  }
  fig.Add(pts);
  fig.Save((d / "pareto.svg").string());
}

}  // namespace ruffini::eval
