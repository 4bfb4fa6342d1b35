// Decoder speed on fixed inputs: the Eigen runtime of the paper's pipeline (float/double, window W, MLP
// width), independent of any trained model (a synthetic model of the same shapes), and the baseline tracker.
// `ruffini bench` measures trained models with their errors; this program isolates the arithmetic.
#include <benchmark/benchmark.h>

#include <cmath>

#include "../decode/synthetic_model.h"
#include "ruffini/decode/baseline.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/patch/spec_loader.h"

namespace {

using namespace ruffini;

const patch::PatchSpec& Spec() {
  static const patch::PatchSpec s = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  return s;
}

template <typename Scalar>
void BM_PaperPipeline(benchmark::State& state) {
  const auto m = decode::testing::SyntheticModel(Spec(), static_cast<int>(state.range(0)));
  decode::NetworkDecoder<Scalar> d(m);
  typename decode::NetworkDecoder<Scalar>::Data data(d);
  decode::ShiftsPm s;
  s.fill(0.0f);
  float k = 0;
  for (auto _ : state) {
    s[3] = 80.0f + (k += 0.01f);  // in contact: the gate is open, all nets run
    benchmark::DoNotOptimize(d.Decode(s, data));
  }
}
BENCHMARK(BM_PaperPipeline<float>)->Arg(1)->Arg(8)->Arg(32);
BENCHMARK(BM_PaperPipeline<double>)->Arg(1)->Arg(8)->Arg(32);

// The whole per-frame path (decode::Pipeline: checks, baseline, networks, uncertainty, the faint flag) with
// the shipped lab model, at rest (noise on the nominal peaks) and in a press of 80 pm on FBG 4. Arg 0: the
// faint rule off (PipelineConfig::faint_pm 0), 1: as shipped.
void BM_ShippedPipeline(benchmark::State& state, bool pressed) {
  static const auto m = decode::LoadModel(RUFFINI_SOURCE_DIR "/config/models/forearm.rmodel");
  decode::PipelineConfig cfg;
  cfg.baseline = decode::BaselineFor(m, 100.0);
  if (state.range(0) == 0) cfg.faint_pm = 0.0;
  const decode::Pipeline<float> p(m, Spec(), cfg);
  decode::Pipeline<float>::Data data(p);
  decode::Wavelengths wl;
  std::uint64_t k = 0;
  const auto frame = [&] {
    ++k;
    for (std::size_t i = 0; i < 16; ++i) {
      wl[i] = Spec().gratings[i].wavelength_nm + 3e-4 * std::sin(0.7 * static_cast<double>(k) + static_cast<double>(i));
    }
    if (pressed && k > 200) wl[3] += 0.08;
    return p.Process(wl, 0, data);
  };
  for (int f = 0; f < 300; ++f) frame();  // capture, then the press under way
  for (auto _ : state) benchmark::DoNotOptimize(frame());
}
BENCHMARK_CAPTURE(BM_ShippedPipeline, rest, false)->Arg(0)->Arg(1);
BENCHMARK_CAPTURE(BM_ShippedPipeline, pressed, true)->Arg(0)->Arg(1);

void BM_ForceOnly(benchmark::State& state) {
  const auto m = decode::testing::SyntheticModel(Spec(), static_cast<int>(state.range(0)));
  decode::NetworkDecoder<float> d(m);
  decode::NetworkDecoder<float>::Data data(d);
  decode::ShiftsPm s;
  s.fill(0.0f);  // below the gate: the force net alone
  for (auto _ : state) benchmark::DoNotOptimize(d.Decode(s, data));
}
BENCHMARK(BM_ForceOnly)->Arg(1)->Arg(8)->Arg(32);

void BM_Baseline(benchmark::State& state) {
  decode::BaselineTracker t;
  decode::Wavelengths wl;
  for (std::size_t i = 0; i < 16; ++i) wl[i] = 1530.0 + 2.3 * static_cast<double>(i);
  decode::ShiftsPm s;
  for (auto _ : state) benchmark::DoNotOptimize(t.Update(wl, s));
}
BENCHMARK(BM_Baseline);

}  // namespace

BENCHMARK_MAIN();
