// Decoder speed on fixed inputs: the Eigen runtime of the paper's pipeline (float/double, window W, MLP
// width), independent of any trained model (a synthetic model of the same shapes), and the baseline tracker.
// `ruffini bench` measures trained models with their errors; this program isolates the arithmetic.
#include <benchmark/benchmark.h>

#include "../decode/synthetic_model.h"
#include "ruffini/decode/baseline.h"
#include "ruffini/decode/network_decoder.h"
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
