// The bench (eval::RunBench and its writer) on twin data with a hand-built model: the timed step replays the
// stream from raw wavelengths exactly, frames are split into gated and ungated, warm-up is not timed, the
// Eigen-vs-libtorch ratio names the fastest libtorch row, and the report has its columns. No timing goal here
// (speed goals live in benchmarks): only the bookkeeping around the clock.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "../decode/synthetic_model.h"
#include "ruffini/error.h"
#include "ruffini/eval/bench.h"
#include "ruffini/eval/bench_report.h"
#include "ruffini/eval/stream.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/scene.h"

namespace ruffini::eval {
namespace {

struct Fixture {
  twin::Scene scene = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/forearm.yaml");
  dataset::Dataset data;
  Prepared prepared;
  v1::DecoderModel model;
  std::vector<std::int32_t> test;
  Fixture() {
    const twin::SkinTwin t(scene.Patch().spec, scene.effects, {scene.probe.radius_mm});
    data.info = twin::TwinDatasetInfo(t, scene, "paper", 4, 100.0);
    twin::PaperProtocol p;
    p.indentations = 40;
    twin::RunPaper(t, scene, p, 4, [&](std::span<const dataset::Frame> f) {
      for (const auto& x : f) data.Append(x);
    });
    prepared = PrepareFrames(data);
    model = decode::testing::SyntheticModel(scene.Patch().spec, 4);
    for (std::size_t i = 0; i < prepared.ids.size(); i += 5) test.push_back(prepared.ids[i]);  // 8 of 40
    for (auto id : test) model.add_test_indentations(static_cast<std::uint32_t>(id));
    // The synthetic model's std is 1 pm: without a known input range the shipped pipeline would find every
    // press out of range. (The decoders alone do not look at it.)
    auto* range = model.mutable_input_range();
    for (int i = 0; i < 16; ++i) {
      range->add_min_shift_pm(-3000.0f);
      range->add_max_shift_pm(3000.0f);
    }
    range->set_margin_pm(100.0f);
  }
};

const Fixture& F() {
  static const Fixture f;
  return f;
}

// Records what the decoder is fed (and decodes it with the runtime).
class Recording final : public FrameDecoder {
 public:
  explicit Recording(const v1::DecoderModel& m) : inner_(m) {}
  void Reset(const decode::ShiftsPm* fill) override {
    ++resets;
    inner_.Reset(fill);
  }
  decode::DecodeOutput Decode(const decode::ShiftsPm& s) override {
    seen.push_back(s);
    return inner_.Decode(s);
  }
  std::vector<decode::ShiftsPm> seen;
  int resets = 0;

 private:
  NetworkFrameDecoder<float> inner_;
};

bool SameBits(const decode::ShiftsPm& a, const decode::ShiftsPm& b) { return std::memcmp(a.data(), b.data(), sizeof a) == 0; }

// From the stretch's tracker state, the baseline update inside the timed step gives the very shifts the
// errors are computed from (PrepareFrames), frame for frame, bit for bit.
TEST(BenchTest, TimedStepReplaysThePreparedShifts) {
  const auto stretches = TestStretches(F().data, F().prepared, F().test);
  ASSERT_EQ(stretches.size(), F().test.size());
  Recording rec(F().model);
  BaselineThenDecode step(rec);
  std::size_t frames = 0;
  for (const auto& s : stretches) {
    ASSERT_LT(s.first, s.last);
    step.Reset(s.baseline, F().prepared.shift_pm[s.first]);
    rec.seen.clear();
    for (std::size_t k = s.first; k < s.last; ++k) (void)step.Step(F().data.wavelength_nm[k], F().data.flags[k]);
    ASSERT_EQ(rec.seen.size(), s.last - s.first);
    for (std::size_t k = s.first; k < s.last; ++k, ++frames) {
      ASSERT_TRUE(SameBits(rec.seen[k - s.first], F().prepared.shift_pm[k])) << "frame " << k;
    }
  }
  EXPECT_GT(frames, 1000u);
  // A stretch started from a fresh tracker (no baseline yet) would not reproduce them.
  Recording fresh(F().model);
  BaselineThenDecode wrong(fresh);
  wrong.Reset(decode::BaselineTracker(BaselineConfigFor(F().data)), F().prepared.shift_pm[stretches[0].first]);
  (void)wrong.Step(F().data.wavelength_nm[stretches[0].first], 0);
  EXPECT_FALSE(SameBits(fresh.seen[0], F().prepared.shift_pm[stretches[0].first]));
}

// Counts calls: warm-up runs first, untimed, and each stretch starts with a reset.
class CountingStep final : public FrameStep {
 public:
  void Reset(const decode::BaselineTracker&, const decode::ShiftsPm&) override { ++resets; }
  bool Step(const decode::Wavelengths&, std::uint32_t) override {
    return (steps++ % 4) == 0;  // one frame in four "gated"
  }
  std::size_t steps = 0, resets = 0;
};

TEST(BenchTest, WarmupIsRunButNotTimed) {
  const auto stretches = TestStretches(F().data, F().prepared, F().test);
  CountingStep step;
  const FrameLatency l = MeasureFrameLatency(step, F().data, F().prepared, stretches, 1500, 300);
  EXPECT_EQ(step.steps, 1800u);
  EXPECT_EQ(l.all.frames, 1500u);
  EXPECT_EQ(l.gated.frames + l.ungated.frames, 1500u);
  EXPECT_EQ(l.gated.frames, 375u);  // steps 300..1799: every fourth
  EXPECT_GE(step.resets, 2u);
  EXPECT_LE(l.all.p50_us, l.all.p99_us);
}

// The shipped pipeline follows the stream: restarted once per pass, fed every frame from the first in order
// (untimed between test stretches), so each timed frame gets exactly the output one continuous pass gives it
// (DecodeStream); gated frames are those in contact.
class RecordingPipeline final : public FrameStep {
 public:
  RecordingPipeline(const v1::DecoderModel& m, const patch::PatchSpec& spec, double rate)
      : inner_(m, spec, ShippedPipelineConfig(m, rate)) {}
  [[nodiscard]] bool FollowsStream() const noexcept override { return true; }
  void Restart() override {
    inner_.Restart();
    out.clear();
    ++restarts;
  }
  void Reset(const decode::BaselineTracker&, const decode::ShiftsPm&) override { ADD_FAILURE() << "Reset on a stream step"; }
  bool Step(const decode::Wavelengths& wl, std::uint32_t flags) override {
    const bool g = inner_.Step(wl, flags);
    out.push_back(inner_.last());
    return g;
  }
  std::vector<decode::PipelineOutput> out;
  int restarts = 0;

 private:
  PipelineStep<float> inner_;
};

TEST(BenchTest, PipelineStepFollowsTheStream) {
  const auto& spec = F().scene.Patch().spec;
  const auto stretches = TestStretches(F().data, F().prepared, F().test);
  RecordingPipeline step(F().model, spec, F().data.info.sample_rate_hz);
  const std::size_t frames = 3000;
  const FrameLatency l = MeasureFrameLatency(step, F().data, F().prepared, stretches, frames, 300);
  EXPECT_EQ(step.restarts, 2);
  EXPECT_EQ(l.all.frames, frames);
  // The frames the timed pass timed, in order; the last of them is the last frame the step saw.
  std::vector<std::size_t> timed;
  for (const auto& s : stretches) {
    for (std::size_t k = s.first; k < s.last && timed.size() < frames; ++k) timed.push_back(k);
  }
  ASSERT_EQ(step.out.size(), timed.back() + 1);
  const decode::Pipeline<float> pipe(F().model, spec, ShippedPipelineConfig(F().model, F().data.info.sample_rate_hz));
  const StreamPredictions ref = DecodeStream(pipe, F().data);
  for (std::size_t k = 0; k < step.out.size(); ++k) {
    ASSERT_EQ(step.out[k].force_n, ref.force_n[k]) << "frame " << k;
    ASSERT_EQ(step.out[k].in_contact, ref.in_contact[k] != 0) << "frame " << k;
    ASSERT_EQ(static_cast<int>(step.out[k].reason), static_cast<int>(ref.reason[k])) << "frame " << k;
  }
  std::size_t contact = 0;
  for (std::size_t k : timed) contact += ref.in_contact[k];
  EXPECT_EQ(l.gated.frames, contact);
  EXPECT_GT(contact, 0u) << stretches.size() << " stretches, first " << stretches[0].first << "-" << stretches[0].last
                         << ", reason at the first timed frame " << decode::ReasonName(step.out[timed[0]].reason)
                         << ", valid timed " << std::count_if(timed.begin(), timed.end(), [&](std::size_t k) { return ref.valid[k] != 0; });
  EXPECT_LT(contact, frames);
}

TEST(BenchTest, RunBenchRowsRatiosAndReport) {
  BenchOptions o;
  o.frames = 2000;
  o.warmup_frames = 200;
  o.inversion_iterations = {1};
  // Two stand-ins for libtorch on the same weights: their rows, and the ratio to the faster one.
  o.extra = [](const v1::DecoderModel& m) {
    std::vector<BenchDecoder> v;
    v.push_back({"stand-in double", Runtime::kLibtorch, std::make_unique<NetworkFrameDecoder<double>>(m)});
    v.push_back({"stand-in float", Runtime::kLibtorch, std::make_unique<NetworkFrameDecoder<float>>(m)});
    return v;
  };
  const BenchResult r = RunBench({F().model}, F().data, F().scene.Patch().spec, o);
  ASSERT_EQ(r.rows.size(), 2u + 2u + 4u + 2u + 1u);
  EXPECT_EQ(r.rows[0].configuration, "shipped pipeline (decode::Pipeline), float");
  EXPECT_EQ(r.rows[1].configuration, "shipped pipeline (decode::Pipeline), double");
  EXPECT_EQ(r.rows[2].configuration, "paper pipeline, NIP union, float");
  EXPECT_EQ(r.rows[0].runtime, Runtime::kEigen);
  EXPECT_EQ(r.rows[0].weights, WeightsTag(F().model));
  EXPECT_EQ(r.rows[0].weights.substr(0, 9), "W=4, MLP ");
  EXPECT_EQ(r.rows[8].runtime, Runtime::kLibtorch);
  EXPECT_EQ(r.rows.back().runtime, Runtime::kInversion);
  EXPECT_TRUE(r.rows.back().weights.empty());
  for (const auto& row : r.rows) {
    EXPECT_EQ(row.latency.all.frames, 2000u) << row.configuration;
    EXPECT_EQ(row.latency.gated.frames + row.latency.ungated.frames, 2000u) << row.configuration;
    EXPECT_LE(row.latency.gated.p50_us, row.latency.gated.p99_us);
    EXPECT_LE(row.latency.ungated.p50_us, row.latency.ungated.p99_us);
  }
  // The twin's indentations start and end untouched: both kinds of frames are timed.
  EXPECT_GT(r.rows[0].latency.gated.frames, 0u);
  EXPECT_GT(r.rows[0].latency.ungated.frames, 0u);
  // Same weights, same errors.
  EXPECT_NEAR(r.rows[8].force_error_median_mn, r.rows[2].force_error_median_mn, 1e-3);
  EXPECT_NEAR(r.rows[9].location_error_median_mm, r.rows[2].location_error_median_mm, 1e-3);
  // The shipped pipeline is scored too (its own continuous pass).
  EXPECT_GT(r.rows[0].force_error_median_mn, 0.0);
  EXPECT_GT(r.rows[1].latency.gated.frames, 0u);
  ASSERT_EQ(r.ratios.size(), 1u);
  const BenchRatio& q = r.ratios[0];
  EXPECT_EQ(q.eigen_row, 0u);  // the shipped pipeline, float
  const double g8 = r.rows[8].latency.gated.p50_us, g9 = r.rows[9].latency.gated.p50_us;
  EXPECT_EQ(q.best_gated_row, g9 < g8 ? 9u : 8u);
  EXPECT_DOUBLE_EQ(q.gated, r.rows[q.best_gated_row].latency.gated.p50_us / r.rows[0].latency.gated.p50_us);
  EXPECT_DOUBLE_EQ(q.ungated, r.rows[q.best_ungated_row].latency.ungated.p50_us / r.rows[0].latency.ungated.p50_us);

  const auto dir = std::filesystem::temp_directory_path() / "ruffini_bench_test";
  std::filesystem::remove_all(dir);
  WriteBench(r, dir.string(), "ruffini bench --model m.rmodel --data d.h5");
  std::ifstream in(dir / "bench.md");
  std::stringstream md;
  md << in.rdbuf();
  for (const char* must : {"Reproduce: `ruffini bench --model m.rmodel --data d.h5`", "| ungated p50 (us) | ungated p99 (us) | gated p50 (us) | gated p99 (us) |",
                           "| 9 | stand-in double (W=4", "| 11 | inversion, LM 1 iteration |",
                           "| 1 | shipped pipeline (decode::Pipeline), float (W=4", "Eigen vs best libtorch (W=4", "(row 1, shipped pipeline (decode::Pipeline), float, vs row ", "![Pareto](pareto.svg)"}) {
    EXPECT_NE(md.str().find(must), std::string::npos) << must;
  }
  EXPECT_TRUE(std::filesystem::exists(dir / "pareto.svg"));
  std::filesystem::remove_all(dir);
}

TEST(BenchTest, RejectsForeignPreparedFramesAndNoModel) {
  Prepared other = F().prepared;
  other.shift_pm.pop_back();
  other.force_n.pop_back();
  EXPECT_THROW(TestStretches(F().data, other, F().test), InputError);
  EXPECT_THROW(RunBench({}, F().data, F().scene.Patch().spec, {}), InputError);
}

}  // namespace
}  // namespace ruffini::eval
