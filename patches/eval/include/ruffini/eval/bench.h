#pragma once
// The speed/accuracy bench of decoder configurations on one dataset's test set (what `ruffini bench` runs).
//
// Latency is per frame from raw wavelengths to the decoder's output: the timed step is FrameStep::Step, one
// thread, steady clock around each call, in stream order over the test indentations. Two kinds of step:
//
// - The shipped path (PipelineStep): decode::Pipeline<Scalar>::Process(wavelengths, flags, data), the one
//   per-frame call the decoder service runs (plausibility checks, common-mode-free baseline frozen by the
//   decoder's own gate, the networks, creep compensation, calibrated uncertainty). Its state (baseline,
//   freeze, window, contact confirmation, creep) is carried along the whole stream and never reset, as in
//   the service; the baseline depends on the pipeline's own gate, so no tracker state computed outside it
//   would be its state. The bench therefore runs it over the whole stream in order, from frame 0: every
//   frame between test indentations is processed untimed, and the frames of the test indentations are
//   timed. This is the simplest honest option: each timed frame sees exactly the state the live stream
//   would have given it, at the cost of replaying the untimed frames (a few seconds at most). Timing one
//   continuous stretch instead would mix in frames outside the test set. Gated frames: the output's
//   in_contact (the force gate open, location run).
// - The decoders alone (BaselineThenDecode): BaselineTracker::Update then a FrameDecoder. Each indentation
//   starts untimed from the baseline tracker's state at that point of the stream and a window filled with its
//   first frame (as RunDecoder does), so the shifts are exactly those the errors are computed from. Gated:
//   the decoder located (its gate was open).
//
// Warm-up frames (the first frames of the test indentations, reached as the timed pass would reach them) run
// first, untimed. Errors are over the whole test set: for the shipped path from one continuous pass of the
// pipeline (invalid frames count as 0 N, as in `ruffini evaluate`), for the others from RunDecoder.
// libtorch is not linked here: its configurations come in through BenchOptions::extra.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/baseline.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/eval/evaluation.h"
#include "ruffini/eval/prepared.h"
#include "ruffini/patch/spec.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::eval {

// What the bench times per frame: raw peak wavelengths (and the source's flags) in, one decoded frame out.
class FrameStep {
 public:
  virtual ~FrameStep() = default;
  // True: the step carries its own state along the stream (the shipped pipeline). The bench then calls
  // Restart() (a fresh stream) instead of Reset() and feeds it every frame of the stream in order, untimed
  // outside the test indentations.
  [[nodiscard]] virtual bool FollowsStream() const noexcept { return false; }
  virtual void Restart() {}
  // Untimed, at the start of a test indentation (steps that do not follow the stream): `baseline` is the
  // tracker as the stream left it just before the indentation's first frame; `fill` fills the decoder's window.
  virtual void Reset(const decode::BaselineTracker& baseline, const decode::ShiftsPm& fill) = 0;
  // Timed: one frame. Returns whether the frame was gated (the force gate open: location ran).
  virtual bool Step(const decode::Wavelengths& wavelength_nm, std::uint32_t source_flags) = 0;
};

// The decoders alone: BaselineTracker::Update on the raw wavelengths, then the decoder on the shifts (the
// source flags are not looked at). Gated: the decoder located.
class BaselineThenDecode final : public FrameStep {
 public:
  explicit BaselineThenDecode(FrameDecoder& decoder) : decoder_(decoder) {}
  void Reset(const decode::BaselineTracker& baseline, const decode::ShiftsPm& fill) override {
    tracker_ = baseline;
    decoder_.Reset(&fill);
  }
  bool Step(const decode::Wavelengths& wavelength_nm, std::uint32_t /*source_flags*/) override {
    tracker_.Update(wavelength_nm, shift_pm_);
    last_ = decoder_.Decode(shift_pm_);
    return last_.located;
  }
  [[nodiscard]] const decode::DecodeOutput& last() const noexcept { return last_; }

 private:
  FrameDecoder& decoder_;
  decode::BaselineTracker tracker_;
  decode::ShiftsPm shift_pm_{};
  decode::DecodeOutput last_{};
};

// The shipped per-frame path: decode::Pipeline<Scalar>::Process. Follows the stream (see the top of this
// file). Gated: the output's in_contact.
template <typename Scalar>
class PipelineStep final : public FrameStep {
 public:
  PipelineStep(const v1::DecoderModel& model, const patch::PatchSpec& spec, decode::PipelineConfig config)
      : pipeline_(model, spec, std::move(config)), data_(std::make_unique<typename decode::Pipeline<Scalar>::Data>(pipeline_)) {}
  [[nodiscard]] bool FollowsStream() const noexcept override { return true; }
  void Restart() override { data_ = std::make_unique<typename decode::Pipeline<Scalar>::Data>(pipeline_); }
  // Not used by the bench (the pipeline's state is its own): a fresh stream, like Restart().
  void Reset(const decode::BaselineTracker&, const decode::ShiftsPm&) override { Restart(); }
  bool Step(const decode::Wavelengths& wavelength_nm, std::uint32_t source_flags) override {
    last_ = pipeline_.Process(wavelength_nm, source_flags, *data_);
    return last_.in_contact;
  }
  [[nodiscard]] const decode::PipelineOutput& last() const noexcept { return last_; }
  [[nodiscard]] const decode::Pipeline<Scalar>& pipeline() const noexcept { return pipeline_; }
  [[nodiscard]] const typename decode::Pipeline<Scalar>::Data& data() const noexcept { return *data_; }

 private:
  decode::Pipeline<Scalar> pipeline_;
  std::unique_ptr<typename decode::Pipeline<Scalar>::Data> data_;
  decode::PipelineOutput last_{};
};

// The shipped pipeline's config for a model on a stream of this rate: the defaults the decoder service and
// `ruffini decode` use, baseline from decode::BaselineFor.
decode::PipelineConfig ShippedPipelineConfig(const v1::DecoderModel& model, double sample_rate_hz);

// The per-frame step the bench times for a decoder alone.
std::unique_ptr<FrameStep> MakeFrameStep(FrameDecoder& decoder);

// One test indentation as the bench replays it: frames [first, last) and the baseline tracker just before.
struct TestStretch {
  std::size_t first = 0, last = 0;
  decode::BaselineTracker baseline;
};
// The test indentations in stream order, with the tracker states PrepareFrames passed through (same config).
std::vector<TestStretch> TestStretches(const dataset::Dataset& data, const Prepared& prepared,
                                       const std::vector<std::int32_t>& test_ids,
                                       const decode::BaselineConfig& config = {});

struct LatencyUs {
  double p50_us = 0, p99_us = 0, mean_us = 0;
  std::size_t frames = 0;  // 0: no frame of this kind was timed (the times are then 0)
};
struct FrameLatency {
  LatencyUs all, gated, ungated;  // gated: the decoder located (gate open); ungated: force only
};
// Runs warmup_frames untimed, then times up to `frames` steps over the stretches (each starting with Reset;
// a step that follows the stream is restarted once per pass and fed the frames between stretches untimed).
FrameLatency MeasureFrameLatency(FrameStep& step, const dataset::Dataset& data, const Prepared& prepared,
                                 const std::vector<TestStretch>& stretches, std::size_t frames, std::size_t warmup_frames);

enum class Runtime : std::uint8_t { kEigen, kLibtorch, kInversion };

struct BenchDecoder {
  std::string configuration;  // e.g. "libtorch eager, same weights"
  Runtime runtime = Runtime::kEigen;
  std::unique_ptr<FrameDecoder> decoder;
};
// More configurations for a model (the libtorch anchors: train::TorchBenchDecoders).
using ExtraDecoders = std::function<std::vector<BenchDecoder>(const v1::DecoderModel&)>;

struct BenchOptions {
  std::size_t frames = 20000;        // timed per configuration
  std::size_t warmup_frames = 2000;  // run before timing, untimed (about two indentations: gated and ungated)
  ExtraDecoders extra;
  std::vector<int> inversion_iterations = {1, 3, 10};
};

struct BenchRow {
  std::string configuration;  // "paper pipeline, NIP union, float"
  std::string weights;        // "W=16, MLP 64-64-64"; empty for the inversion decoder
  Runtime runtime = Runtime::kEigen;
  FrameLatency latency;
  double force_error_median_mn = 0, location_error_median_mm = 0;
  std::size_t above_gate_not_located = 0;
};

// The shipped pipeline (decode::Pipeline<float>, Eigen runtime) against the fastest libtorch configuration on
// the same weights, in the same run: ratio = libtorch p50 / shipped p50 (> 1: the shipped path is faster),
// gated and ungated frames apart. The libtorch rows time the baseline and the nets only (no plausibility
// checks, no uncertainty): the comparison is tilted towards libtorch, never away from it.
struct BenchRatio {
  std::string weights;
  std::size_t eigen_row = 0;                          // index into rows
  std::size_t best_gated_row = 0, best_ungated_row = 0;  // the fastest libtorch row for each kind of frame
  double gated = 0, ungated = 0;
};

struct BenchResult {
  std::vector<BenchRow> rows;
  std::vector<BenchRatio> ratios;  // one per model with libtorch configurations
  std::size_t frames = 0, warmup_frames = 0;
};

using BenchProgress = std::function<void(const std::string& configuration)>;

// Every configuration of every model: the shipped pipeline (decode::Pipeline, float and double), the paper
// pipeline's decoder alone (float, double), each grid alone (float), the extra configurations; then the inversion decoder (response map fitted outside the first model's test set).
// The models must match `spec` (decode::CheckModelMatchesPatch) and have been trained on `data`.
BenchResult RunBench(const std::vector<v1::DecoderModel>& models, const dataset::Dataset& data,
                     const patch::PatchSpec& spec, const BenchOptions& options, const BenchProgress& progress = {});

// The models' weights in a row label: "W=16, MLP 64-64-64".
std::string WeightsTag(const v1::DecoderModel& model);

}  // namespace ruffini::eval
