#pragma once
// The speed/accuracy bench of decoder configurations on one dataset's test set (what `ruffini bench` runs).
//
// Latency is per frame from raw wavelengths to the decoder's output: the timed step is FrameStep::Step (today
// the baseline update, then the decoder), one thread, steady clock around each call, in stream order over the
// test indentations. Each indentation starts untimed from the baseline tracker's state at that point of the
// stream and a window filled with its first frame (as RunDecoder does), so the shifts are exactly those the
// errors are computed from. Warm-up frames run first, untimed. Frames are split by what the decoder did:
// gated (the gate was open: location ran) and ungated (force only). Errors are over the whole test set.
// libtorch is not linked here: its configurations come in through BenchOptions::extra.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/baseline.h"
#include "ruffini/eval/evaluation.h"
#include "ruffini/eval/prepared.h"
#include "ruffini/patch/spec.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::eval {

// What the bench times per frame: raw peak wavelengths in, one decoded frame out. The one place to swap in a
// fuller per-frame pipeline.
class FrameStep {
 public:
  virtual ~FrameStep() = default;
  // Untimed, at the start of a test indentation: `baseline` is the tracker as the stream left it just before
  // the indentation's first frame; `fill` fills the decoder's window.
  virtual void Reset(const decode::BaselineTracker& baseline, const decode::ShiftsPm& fill) = 0;
  // Timed: one frame.
  virtual decode::DecodeOutput Step(const decode::Wavelengths& wavelength_nm) = 0;
};

// Today's per-frame step: BaselineTracker::Update on the raw wavelengths, then the decoder on the shifts.
class BaselineThenDecode final : public FrameStep {
 public:
  explicit BaselineThenDecode(FrameDecoder& decoder) : decoder_(decoder) {}
  void Reset(const decode::BaselineTracker& baseline, const decode::ShiftsPm& fill) override {
    tracker_ = baseline;
    decoder_.Reset(&fill);
  }
  decode::DecodeOutput Step(const decode::Wavelengths& wavelength_nm) override {
    tracker_.Update(wavelength_nm, shift_pm_);
    return decoder_.Decode(shift_pm_);
  }

 private:
  FrameDecoder& decoder_;
  decode::BaselineTracker tracker_;
  decode::ShiftsPm shift_pm_{};
};

// The per-frame step the bench times for a decoder.
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
// Runs warmup_frames untimed, then times up to `frames` steps over the stretches (each starting with Reset).
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

// Eigen runtime (paper pipeline, float) against the fastest libtorch configuration on the same weights, in
// the same run: ratio = libtorch p50 / Eigen p50 (> 1: Eigen is faster), gated and ungated frames apart.
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

// Every configuration of every model: the paper pipeline (float, double), each grid alone (float), the
// extra configurations; then the inversion decoder (response map fitted outside the first model's test set).
// The models must match `spec` (decode::CheckModelMatchesPatch) and have been trained on `data`.
BenchResult RunBench(const std::vector<v1::DecoderModel>& models, const dataset::Dataset& data,
                     const patch::PatchSpec& spec, const BenchOptions& options, const BenchProgress& progress = {});

// The models' weights in a row label: "W=16, MLP 64-64-64".
std::string WeightsTag(const v1::DecoderModel& model);

}  // namespace ruffini::eval
