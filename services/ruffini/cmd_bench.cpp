// ruffini bench: the speed/accuracy trade of every decoder configuration on one dataset's test set.
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>

#include "commands.h"
#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/inversion.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/error.h"
#include "ruffini/eval/evaluation.h"
#include "ruffini/patch/spec_loader.h"
#include "ruffini/plot/svg.h"
#ifdef RUFFINI_HAVE_TORCH
#include "ruffini/train/trainer.h"
#endif

namespace ruffini::cli {
namespace {

#ifdef RUFFINI_HAVE_TORCH
// libtorch eager inference of the same weights, batch 1, with the same window, gate and NIP.
class TorchFrameDecoder final : public eval::FrameDecoder {
 public:
  explicit TorchFrameDecoder(const v1::DecoderModel& m)
      : net_(m), window_(static_cast<int>(m.force().window())), mean_(16), buf_(static_cast<std::size_t>(window_) * 16),
        on_(m.gating().on_n()), off_(m.gating().off_n()) {
    std::vector<decode::GridSpec> grids;
    for (const auto& l : m.location()) {
      const auto& g = l.grid();
      grids.push_back({g.name(), g.y0_mm(), g.r0_deg(), g.cell_y_mm(), g.cell_r_deg(), static_cast<int>(g.ny()), static_cast<int>(g.nr())});
    }
    nip_ = std::make_unique<decode::Nip>(grids);
    for (int i = 0; i < 16; ++i) mean_[static_cast<std::size_t>(i)] = m.force().input().mean(i);
  }
  void Reset(const decode::ShiftsPm* fill) override {
    gate_ = false;
    filled_ = 0;
    if (fill) {
      for (int t = 0; t < window_; ++t) Push(*fill);
      filled_ = window_ - 1;
    }
  }
  decode::DecodeOutput Decode(const decode::ShiftsPm& s) override {
    decode::DecodeOutput o;
    Push(s);
    if (filled_ < window_) return o;
    o.valid = true;
    o.force_n = net_.Forward(buf_.data());
    gate_ = gate_ ? o.force_n > off_ : o.force_n > on_;
    o.in_contact = gate_;
    if (!gate_) return o;
    net_.Locate(buf_.data() + (window_ - 1) * 16, probs_);
    double y = 0, r = 0;
    o.confidence = static_cast<float>(nip_->Locate(probs_, y, r));
    o.y_mm = static_cast<float>(y);
    o.r_deg = static_cast<float>(r);
    o.located = true;
    return o;
  }

 private:
  void Push(const decode::ShiftsPm& s) {
    std::copy(buf_.begin() + 16, buf_.end(), buf_.begin());  // oldest first
    for (std::size_t i = 0; i < 16; ++i) buf_[(static_cast<std::size_t>(window_) - 1) * 16 + i] = std::isfinite(s[i]) ? s[i] : mean_[i];
    filled_ = std::min(filled_ + 1, window_);
  }
  train::TorchForceNet net_;
  int window_;
  std::vector<float> mean_, buf_, probs_;
  float on_, off_;
  bool gate_ = false;
  int filled_ = 0;
  std::unique_ptr<decode::Nip> nip_;
};
#endif

struct Row {
  std::string config;
  eval::Latency latency;
  double force_mn = 0, location_mm = 0;
  std::size_t missed = 0;
};

void RegisterBench(CLI::App& app) {
  struct Args {
    std::vector<std::string> models;
    std::string data, out = "bench", patch_spec = RUFFINI_DEFAULT_PATCH;
    std::size_t frames = 20000;
    bool no_torch = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("bench", "Per-frame latency (p50/p99, one thread) and test error of every decoder configuration");
  cmd->add_option("--model", a->models, "Model file(s); give several to compare windows or widths")->required()->check(CLI::ExistingFile);
  cmd->add_option("--data", a->data, "Dataset the models were trained on (its held-out indentations are the test set)")
      ->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", a->out, "Folder for bench.md and pareto.svg")->capture_default_str();
  cmd->add_option("--frames", a->frames, "Frames timed per configuration")->check(CLI::Range(100, 10000000))->capture_default_str();
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec")->capture_default_str();
  cmd->add_flag("--no-torch", a->no_torch, "Skip the libtorch eager configuration");
  cmd->callback([a]() {
    const patch::PatchSpec spec = patch::LoadPatchSpec(a->patch_spec);
    const dataset::Dataset d = dataset::ReadDataset(a->data);
    const eval::Prepared p = eval::PrepareFrames(d);
    std::vector<Row> rows;
    std::vector<std::int32_t> first_test;
    auto run = [&](const std::string& name, eval::FrameDecoder& dec, const std::vector<std::int32_t>& test) {
      spdlog::info("bench: {}", name);
      Row r;
      r.config = name;
      r.latency = eval::MeasureLatency(dec, p, test, a->frames);
      const auto ev = eval::Evaluate(p, eval::RunDecoder(dec, p, test, {}, /*test_only=*/true), spec);
      r.force_mn = ev.force_error_mn.median;
      r.location_mm = ev.location_error_mm.median;
      r.missed = ev.location_missed;
      rows.push_back(r);
    };
    for (const auto& path : a->models) {
      const v1::DecoderModel m = decode::LoadModel(path);
      decode::CheckModelMatchesPatch(m, spec, path);
      const std::vector<std::int32_t> test(m.test_indentations().begin(), m.test_indentations().end());
      if (first_test.empty()) first_test = test;
      std::string widths;
      for (auto w : m.training().mlp_widths()) widths += (widths.empty() ? "" : "-") + std::to_string(w);
      const std::string tag = "W=" + std::to_string(m.force().window()) + ", MLP " + widths;
      {
        eval::NetworkFrameDecoder<float> dec(m);
        run("paper pipeline, NIP union, float (" + tag + ")", dec, test);
      }
      {
        eval::NetworkFrameDecoder<double> dec(m);
        run("paper pipeline, NIP union, double (" + tag + ")", dec, test);
      }
      for (int g = 0; g < m.location_size(); ++g) {
        decode::DecoderOptions o;
        o.grids = {g};
        eval::NetworkFrameDecoder<float> dec(m, o);
        run("single grid " + m.location(g).grid().name() + ", float (" + tag + ")", dec, test);
      }
#ifdef RUFFINI_HAVE_TORCH
      if (!a->no_torch) {
        TorchFrameDecoder dec(m);
        run("libtorch eager, same weights (" + tag + ")", dec, test);
      }
#endif
    }
    const decode::ResponseModel response = eval::FitResponse(p, spec, first_test);
    for (int it : {1, 3, 10}) {
      decode::InversionOptions o;
      o.iterations = it;
      const decode::InversionDecoder inv(response, o);
      eval::InversionFrameDecoder dec(inv);
      run("inversion, LM " + std::to_string(it) + " iteration" + (it > 1 ? "s" : ""), dec, first_test);
    }
    std::ostringstream md;
    md << "| # | decoder configuration | p50 (us) | p99 (us) | mean (us) | force error median (mN) | location error median (mm) | above-gate frames not located |\n";
    md << "|---|---|---|---|---|---|---|---|\n";
    for (std::size_t k = 0; k < rows.size(); ++k) {
      const Row& r = rows[k];
      char buf[512];
      std::snprintf(buf, sizeof buf, "| %zu | %s | %.2f | %.2f | %.2f | %.1f | %.2f | %zu |\n", k + 1, r.config.c_str(), r.latency.p50_us,
                    r.latency.p99_us, r.latency.mean_us, r.force_mn, r.location_mm, r.missed);
      md << buf;
    }
    std::fputs(md.str().c_str(), stdout);
    std::filesystem::create_directories(a->out);
    const auto dir = std::filesystem::path(a->out);
    std::ofstream out((dir / "bench.md").string());
    std::string command = "ruffini bench";
    for (const auto& mp : a->models) command += " --model " + mp;
    command += " --data " + a->data + " --out " + a->out + " --frames " + std::to_string(a->frames);
    out << "# Speed / accuracy of the decoders\n\nReproduce: `" << command << "`\n\nSingle thread, per frame, " << a->frames
        << " test frames timed per configuration (steady clock around each Decode call); errors over the whole test set "
           "(the models' held-out indentations). Location error is over the above-gate frames a decoder located; the last "
           "column counts those it did not. The inversion decoder returns at once on untouched frames (every shift under "
           "3 pm), so its p50 is that of an idle frame: compare its mean and p99.\n\n" << md.str()
        << "\n![Pareto](pareto.svg)\n";
    if (!out) throw InputError((dir / "bench.md").string() + ": cannot write");
    plot::Figure fig("Speed vs location accuracy (test set)", "p50 latency per frame (us)", "location error median (mm)", 760, 480);
    fig.SetLogX(true);
    plot::Series pts{"configurations", {}, {}, "#1f77b4", plot::Series::Style::kPoints};
    for (std::size_t k = 0; k < rows.size(); ++k) {
      pts.x.push_back(rows[k].latency.p50_us);
      pts.y.push_back(rows[k].location_mm);
      fig.AddMarker({rows[k].latency.p50_us, rows[k].location_mm, std::to_string(k + 1)});
    }
    fig.Add(pts);
    fig.Save((dir / "pareto.svg").string());
    std::printf("\nwrote %s and %s (markers number the table's rows)\n", (dir / "bench.md").string().c_str(), (dir / "pareto.svg").string().c_str());
  });
}

}  // namespace

void RegisterBenchCommand(CLI::App& app) { RegisterBench(app); }

}  // namespace ruffini::cli
