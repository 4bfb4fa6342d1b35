#include "ruffini/eval/bench.h"

#include <algorithm>
#include <chrono>
#include <limits>
#include <optional>
#include <set>
#include <type_traits>

#include "ruffini/decode/pipeline.h"
#include "ruffini/error.h"
#include "ruffini/eval/stream.h"
#include "ruffini/stats.h"

namespace ruffini::eval {
namespace {

static_assert(std::is_same_v<std::remove_cvref_t<decltype(dataset::Dataset{}.wavelength_nm[0])>, decode::Wavelengths>,
              "the bench feeds the dataset's wavelengths to the baseline tracker as they are");

LatencyUs Summarise(std::vector<double>& ns) {
  LatencyUs l;
  l.frames = ns.size();
  if (ns.empty()) return l;
  double sum = 0;
  for (double v : ns) sum += v;
  l.mean_us = sum / static_cast<double>(ns.size()) * 1e-3;
  l.p50_us = stats::Quantile(ns, 0.5) * 1e-3;
  l.p99_us = stats::Quantile(ns, 0.99) * 1e-3;
  return l;
}

// The shipped pipeline's predictions as Evaluate takes them: one continuous pass over the stream (as the
// decoder service runs it), test frames marked; invalid frames carry NaN (Evaluate scores them as 0 N).
template <typename Scalar>
Predictions PipelinePredictions(const v1::DecoderModel& m, const patch::PatchSpec& spec, const dataset::Dataset& data,
                                const std::vector<std::int32_t>& test) {
  PipelineStep<Scalar> step(m, spec, ShippedPipelineConfig(m, data.info.sample_rate_hz));
  const std::vector<std::uint8_t> mask = MaskOfIndentations(data, test);
  const std::size_t n = data.size();
  Predictions pred;
  pred.force_n.assign(n, std::numeric_limits<float>::quiet_NaN());
  pred.y_mm.assign(n, 0.0f);
  pred.r_deg.assign(n, 0.0f);
  pred.valid.assign(n, 0);
  pred.located.assign(n, 0);
  pred.test = mask;
  for (std::size_t k = 0; k < n; ++k) {
    (void)step.Step(data.wavelength_nm[k], data.flags[k]);
    const decode::PipelineOutput& o = step.last();
    pred.valid[k] = o.valid ? 1 : 0;
    pred.located[k] = o.located ? 1 : 0;
    if (o.valid) pred.force_n[k] = o.force_n;
    pred.y_mm[k] = o.y_mm;
    pred.r_deg[k] = o.r_deg;
  }
  return pred;
}

}  // namespace

std::unique_ptr<FrameStep> MakeFrameStep(FrameDecoder& decoder) { return std::make_unique<BaselineThenDecode>(decoder); }

std::vector<TestStretch> TestStretches(const dataset::Dataset& data, const Prepared& p,
                                       const std::vector<std::int32_t>& test_ids, const decode::BaselineConfig& config) {
  if (data.size() != p.size()) throw InputError("bench: the prepared frames do not belong to the dataset");
  const std::set<std::int32_t> test(test_ids.begin(), test_ids.end());
  std::vector<TestStretch> out;
  decode::BaselineTracker tracker(BaselineConfigFor(data, config));
  decode::ShiftsPm scratch{};
  for (std::size_t i = 0; i < p.ids.size(); ++i) {
    if (!test.count(p.ids[i])) continue;
    out.push_back({p.ranges[i].first, p.ranges[i].second, decode::BaselineTracker{}});
  }
  std::sort(out.begin(), out.end(), [](const TestStretch& a, const TestStretch& b) { return a.first < b.first; });
  std::size_t k = 0;
  for (auto& s : out) {
    for (; k < s.first; ++k) tracker.Update(data.wavelength_nm[k], scratch);
    s.baseline = tracker;
  }
  return out;
}

FrameLatency MeasureFrameLatency(FrameStep& step, const dataset::Dataset& data, const Prepared& p,
                                 const std::vector<TestStretch>& stretches, std::size_t frames, std::size_t warmup_frames) {
  if (data.flags.size() != data.size()) throw InputError("bench: the dataset has no flags per frame");
  const bool stream = step.FollowsStream();
  std::size_t cursor = 0;  // stream steps: the next frame of the stream they have not seen
  // Start of a test stretch, untimed: a step that follows the stream processes every frame up to it.
  auto start = [&](const TestStretch& s) {
    if (!stream) {
      step.Reset(s.baseline, p.shift_pm[s.first]);
      return;
    }
    for (; cursor < s.first; ++cursor) (void)step.Step(data.wavelength_nm[cursor], data.flags[cursor]);
  };
  // Warm-up: the first stretches, untimed (caches, lazy initialisation, a JIT's profiling runs).
  if (stream) step.Restart();
  std::size_t warm = 0;
  for (const auto& s : stretches) {
    if (warm >= warmup_frames) break;
    start(s);
    for (std::size_t k = s.first; k < s.last && warm < warmup_frames; ++k, ++warm) {
      (void)step.Step(data.wavelength_nm[k], data.flags[k]);
      cursor = k + 1;
    }
  }
  if (stream) {  // the timed pass starts the stream again
    step.Restart();
    cursor = 0;
  }
  std::vector<double> all, gated, ungated;
  all.reserve(frames);
  gated.reserve(frames);
  ungated.reserve(frames);
  for (const auto& s : stretches) {
    if (all.size() >= frames) break;
    start(s);
    for (std::size_t k = s.first; k < s.last && all.size() < frames; ++k) {
      const decode::Wavelengths& wl = data.wavelength_nm[k];
      const std::uint32_t flags = data.flags[k];
      const auto t0 = std::chrono::steady_clock::now();
      const bool is_gated = step.Step(wl, flags);  // a virtual call that updates state: never elided
      const auto t1 = std::chrono::steady_clock::now();
      cursor = k + 1;
      const double ns = std::chrono::duration<double, std::nano>(t1 - t0).count();
      all.push_back(ns);
      (is_gated ? gated : ungated).push_back(ns);
    }
  }
  return {Summarise(all), Summarise(gated), Summarise(ungated)};
}

decode::PipelineConfig ShippedPipelineConfig(const v1::DecoderModel& model, double sample_rate_hz) {
  decode::PipelineConfig c;
  c.baseline = decode::BaselineFor(model, sample_rate_hz);
  return c;
}

std::string WeightsTag(const v1::DecoderModel& m) {
  std::string widths;
  for (auto w : m.training().mlp_widths()) {
    if (!widths.empty()) widths += '-';  // (appending: GCC 12's -Wrestrict false positive on "-" + string)
    widths += std::to_string(w);
  }
  return "W=" + std::to_string(m.force().window()) + ", MLP " + widths;
}

BenchResult RunBench(const std::vector<v1::DecoderModel>& models, const dataset::Dataset& data,
                     const patch::PatchSpec& spec, const BenchOptions& o, const BenchProgress& progress) {
  if (models.empty()) throw InputError("bench: no model");
  // Shifts as each model was trained to see them (common mode removed or not): prepared per model.
  Prepared p;
  Prepared first_p;
  BenchResult result;
  result.frames = o.frames;
  result.warmup_frames = o.warmup_frames;
  auto add = [&](const std::string& configuration, const std::string& weights, Runtime runtime, FrameStep& step,
                 const std::vector<TestStretch>& stretches, const Predictions& pred) {
    BenchRow r;
    r.configuration = configuration;
    r.weights = weights;
    r.runtime = runtime;
    r.latency = MeasureFrameLatency(step, data, p, stretches, o.frames, o.warmup_frames);
    const Evaluation ev = Evaluate(p, pred, spec);
    r.force_error_median_mn = ev.force_error_mn.median;
    r.location_error_median_mm = ev.location_error_mm.median;
    r.above_gate_not_located = ev.location_missed;
    result.rows.push_back(std::move(r));
  };
  auto run = [&](const std::string& configuration, const std::string& weights, Runtime runtime, FrameDecoder& dec,
                 const std::vector<std::int32_t>& test, const std::vector<TestStretch>& stretches) {
    if (progress) progress(configuration + (weights.empty() ? "" : " (" + weights + ")"));
    const std::unique_ptr<FrameStep> step = MakeFrameStep(dec);
    add(configuration, weights, runtime, *step, stretches, RunDecoder(dec, p, test, {}, /*test_only=*/true));
  };
  auto run_shipped = [&]<typename Scalar>(const std::string& configuration, const std::string& weights,
                                          const v1::DecoderModel& m, const std::vector<std::int32_t>& test,
                                          const std::vector<TestStretch>& stretches, Scalar) {
    if (progress) progress(configuration + " (" + weights + ")");
    PipelineStep<Scalar> step(m, spec, ShippedPipelineConfig(m, data.info.sample_rate_hz));
    add(configuration, weights, Runtime::kEigen, step, stretches, PipelinePredictions<Scalar>(m, spec, data, test));
  };
  std::vector<std::int32_t> first_test;
  std::vector<TestStretch> first_stretches;
  for (const auto& m : models) {
    const decode::BaselineConfig baseline = decode::BaselineFor(m, data.info.sample_rate_hz);
    p = PrepareFrames(data, baseline);
    const std::vector<std::int32_t> test(m.test_indentations().begin(), m.test_indentations().end());
    const std::vector<TestStretch> stretches = TestStretches(data, p, test, baseline);
    if (first_test.empty()) {
      first_test = test;
      first_stretches = stretches;
      first_p = p;
    }
    const std::string tag = WeightsTag(m);
    const std::size_t eigen_row = result.rows.size();  // the shipped pipeline, float: the Eigen side of the ratio
    run_shipped("shipped pipeline (decode::Pipeline), float", tag, m, test, stretches, float{});
    run_shipped("shipped pipeline (decode::Pipeline), double", tag, m, test, stretches, double{});
    {
      NetworkFrameDecoder<float> dec(m);
      run("paper pipeline, NIP union, float", tag, Runtime::kEigen, dec, test, stretches);
    }
    {
      NetworkFrameDecoder<double> dec(m);
      run("paper pipeline, NIP union, double", tag, Runtime::kEigen, dec, test, stretches);
    }
    for (int g = 0; g < m.location_size(); ++g) {
      decode::DecoderOptions opt;
      opt.grids = {g};
      NetworkFrameDecoder<float> dec(m, opt);
      run("single grid " + m.location(g).grid().name() + ", float", tag, Runtime::kEigen, dec, test, stretches);
    }
    if (o.extra) {
      std::optional<BenchRatio> ratio;
      for (auto& extra : o.extra(m)) {
        run(extra.configuration, tag, extra.runtime, *extra.decoder, test, stretches);
        if (extra.runtime != Runtime::kLibtorch) continue;
        const std::size_t k = result.rows.size() - 1;
        const auto& rows = result.rows;
        if (!ratio) ratio = BenchRatio{tag, eigen_row, k, k, 0, 0};
        if (rows[k].latency.gated.p50_us < rows[ratio->best_gated_row].latency.gated.p50_us) ratio->best_gated_row = k;
        if (rows[k].latency.ungated.p50_us < rows[ratio->best_ungated_row].latency.ungated.p50_us) ratio->best_ungated_row = k;
      }
      if (ratio) {
        const auto& rows = result.rows;
        const auto& eigen = rows[eigen_row].latency;
        ratio->gated = eigen.gated.frames ? rows[ratio->best_gated_row].latency.gated.p50_us / eigen.gated.p50_us : 0.0;
        ratio->ungated = eigen.ungated.frames ? rows[ratio->best_ungated_row].latency.ungated.p50_us / eigen.ungated.p50_us : 0.0;
        result.ratios.push_back(*ratio);
      }
    }
  }
  if (!o.inversion_iterations.empty()) {
    p = first_p;
    const decode::ResponseModel response = FitResponse(p, spec, first_test);
    for (int it : o.inversion_iterations) {
      decode::InversionOptions io;
      io.iterations = it;
      const decode::InversionDecoder inv(response, io);
      InversionFrameDecoder dec(inv);
      run("inversion, LM " + std::to_string(it) + " iteration" + (it > 1 ? "s" : ""), "", Runtime::kInversion, dec,
          first_test, first_stretches);
    }
  }
  return result;
}

}  // namespace ruffini::eval
