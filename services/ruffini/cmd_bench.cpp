// ruffini bench: the speed/accuracy trade of every decoder configuration on one dataset's test set.
// Options -> eval::RunBench (libtorch anchors from ruffini::train when built) -> table, bench.md, pareto.svg.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>
#include <memory>

#include "commands.h"
#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/eval/bench.h"
#include "ruffini/eval/bench_report.h"
#include "ruffini/patch/spec_loader.h"
#ifdef RUFFINI_HAVE_TORCH
#include "ruffini/train/torch_decoder.h"
#endif

namespace ruffini::cli {
namespace {

void RegisterBench(CLI::App& app) {
  struct Args {
    std::vector<std::string> models;
    std::string data, out = "bench", patch_spec = RUFFINI_DEFAULT_PATCH;
    std::size_t frames = 20000, warmup = 2000;
    bool no_torch = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("bench", "Per-frame latency (p50/p99 gated and ungated, one thread) and test error of every decoder configuration");
  cmd->add_option("--model", a->models, "Model file(s); give several to compare windows or widths")->required()->check(CLI::ExistingFile);
  cmd->add_option("--data", a->data, "Dataset the models were trained on (its held-out indentations are the test set)")
      ->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", a->out, "Folder for bench.md and pareto.svg")->capture_default_str();
  cmd->add_option("--frames", a->frames, "Frames timed per configuration")->check(CLI::Range(100, 10000000))->capture_default_str();
  cmd->add_option("--warmup", a->warmup, "Untimed frames run before timing each configuration")->check(CLI::Range(0, 1000000))->capture_default_str();
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec")->capture_default_str();
  cmd->add_flag("--no-torch", a->no_torch, "Skip the libtorch configurations");
  cmd->callback([a]() {
    eval::BenchOptions o;
    o.frames = a->frames;
    o.warmup_frames = a->warmup;
#ifdef RUFFINI_HAVE_TORCH
    if (!a->no_torch) {
      train::UseOneTorchThread();  // before any libtorch work
      o.extra = train::TorchBenchDecoders;
    }
#else
    spdlog::warn("bench: built without libtorch: no libtorch configurations");
#endif
    const patch::PatchSpec spec = patch::LoadPatchSpec(a->patch_spec);
    const dataset::Dataset d = dataset::ReadDataset(a->data);
    std::vector<v1::DecoderModel> models;
    for (const auto& path : a->models) {
      models.push_back(decode::LoadModel(path));
      decode::CheckModelMatchesPatch(models.back(), spec, path);
    }
    const eval::BenchResult r = eval::RunBench(models, d, spec, o, [](const std::string& c) { spdlog::info("bench: {}", c); });
    std::fputs(eval::BenchTable(r).c_str(), stdout);
    std::fputs(("\n" + eval::BenchRatios(r)).c_str(), stdout);
    std::string command = "ruffini bench";
    for (const auto& mp : a->models) command += " --model " + mp;
    command += " --data " + a->data + " --out " + a->out + " --frames " + std::to_string(a->frames);
    if (a->warmup != 2000) command += " --warmup " + std::to_string(a->warmup);
    if (a->no_torch) command += " --no-torch";
    eval::WriteBench(r, a->out, command);
    const auto dir = std::filesystem::path(a->out);
    std::printf("\nwrote %s and %s (markers number the table's rows)\n", (dir / "bench.md").string().c_str(),
                (dir / "pareto.svg").string().c_str());
  });
}

}  // namespace

void RegisterBenchCommand(CLI::App& app) { RegisterBench(app); }

}  // namespace ruffini::cli
