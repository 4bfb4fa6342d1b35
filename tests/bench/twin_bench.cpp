// Twin speed: per-frame cost of the forward model and the interrogator, and the paper protocol end to end
// (frames generated per second, with and without writing HDF5). Run: build/release/bin/twin_bench
#include <benchmark/benchmark.h>

#include <filesystem>

#include "ruffini/dataset/dataset.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

namespace {

using namespace ruffini;

const twin::Scene& DefaultScene() {
  static const twin::Scene s = twin::LoadScene(std::string(RUFFINI_SOURCE_DIR) + "/config/scenes/forearm.yaml");
  return s;
}
const twin::SkinTwin& DefaultTwin() {
  static const twin::SkinTwin t(DefaultScene().patches[0].spec, DefaultScene().effects, {5.5});
  return t;
}

void BM_StrainShifts(benchmark::State& state) {
  const auto& t = DefaultTwin();
  twin::Contact c{{70.0, 70.0}, 1.2, DefaultScene().probe};
  twin::Shifts s;
  std::uint32_t flags = 0;
  for (auto _ : state) {
    c.at.y_mm = c.at.y_mm > 130 ? 20.0 : c.at.y_mm + 0.37;
    t.StrainShiftsPm(std::span<const twin::Contact>(&c, 1), s, flags);
    benchmark::DoNotOptimize(s);
  }
}
BENCHMARK(BM_StrainShifts);

void BM_InterrogatorRead(benchmark::State& state) {
  twin::InterrogatorSim sim(DefaultTwin(), 1);
  twin::Shifts s{};
  std::array<double, 16> wl;
  std::uint32_t flags = 0;
  double t = 0;
  for (auto _ : state) {
    sim.Read(t += 0.01, s, wl, flags);
    benchmark::DoNotOptimize(wl);
  }
}
BENCHMARK(BM_InterrogatorRead);

// The paper protocol, frames to a sink that drops them: the twin's generation rate.
void BM_PaperProtocolFrames(benchmark::State& state) {
  twin::PaperProtocol p;
  p.indentations = static_cast<int>(state.range(0));
  std::uint64_t frames = 0;
  for (auto _ : state) {
    const auto run = twin::RunPaper(DefaultTwin(), DefaultScene(), p, 1, [](std::span<const dataset::Frame>) {});
    frames += run.frames;
  }
  state.counters["frames_per_s"] = benchmark::Counter(static_cast<double>(frames), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_PaperProtocolFrames)->Arg(270)->Unit(benchmark::kMillisecond);

// The same, written to an HDF5 dataset (uncompressed, and shuffle+deflate level 1).
void BM_PaperProtocolToHdf5(benchmark::State& state) {
  twin::PaperProtocol p;
  p.indentations = 270;
  const auto path = std::filesystem::temp_directory_path() / "ruffini_bench.h5";
  std::uint64_t frames = 0;
  double bytes_per_frame = 0;
  for (auto _ : state) {
    dataset::DatasetWriter w(path.string(), twin::TwinDatasetInfo(DefaultTwin(), DefaultScene(), "paper", 1, 100.0),
                             static_cast<int>(state.range(0)));
    const auto run = twin::RunPaper(DefaultTwin(), DefaultScene(), p, 1,
                                    [&](std::span<const dataset::Frame> f) { w.Append(f); });
    w.Close();
    frames += run.frames;
    bytes_per_frame = static_cast<double>(std::filesystem::file_size(path)) / static_cast<double>(run.frames);
  }
  std::filesystem::remove(path);
  state.counters["frames_per_s"] = benchmark::Counter(static_cast<double>(frames), benchmark::Counter::kIsRate);
  state.counters["bytes_per_frame"] = bytes_per_frame;
}
BENCHMARK(BM_PaperProtocolToHdf5)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
