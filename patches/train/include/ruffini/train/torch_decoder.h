#pragma once
// libtorch inference of a model's nets, batch 1: the anchors `ruffini bench` compares the Eigen runtime with
// (training library only; the runtime never links libtorch). Two variants of the same weights:
//   eager   torch::nn modules, as trained;
//   frozen  a torch::jit::Module per net family whose forward is TorchScript source, the weights registered
//           as parameters, then torch::jit::freeze (weights folded into the graph as constants, frozen-graph
//           optimisations) and torch::jit::optimize_for_inference: the strongest libtorch path in C++.
// Both run under c10::InferenceMode. Inputs are z-scored in C++ (as the Eigen runtime does); only the nets run
// in libtorch. Not real-time safe: libtorch allocates per call.
#include <memory>
#include <string>
#include <vector>

#include "ruffini/decode/grids.h"
#include "ruffini/eval/bench.h"
#include "ruffini/eval/evaluation.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::train {

enum class TorchVariant { kEager, kFrozen };
[[nodiscard]] std::string VariantName(TorchVariant v);

// One intra-op and one inter-op libtorch thread for this process (a fair comparison with the single-threaded
// Eigen runtime). Call early, before any libtorch work; later calls do nothing.
void UseOneTorchThread();

// A model's force net and location nets in libtorch.
class TorchNets {
 public:
  explicit TorchNets(const v1::DecoderModel& model, TorchVariant variant = TorchVariant::kEager);
  ~TorchNets();
  TorchNets(const TorchNets&) = delete;
  TorchNets& operator=(const TorchNets&) = delete;
  // Force (N) for one window: W x 16 shifts (pm), oldest first, no NaN.
  float Forward(const float* window_shift_pm);
  // Every location net's softmax for one frame of shifts (pm), concatenated in the model's order.
  void Locate(const float* shift_pm, std::vector<float>& probabilities);
  [[nodiscard]] TorchVariant variant() const noexcept { return variant_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  TorchVariant variant_;
};

// The decoder around TorchNets: the same window (missing peaks at the force net's training mean), gate
// (hysteresis) and NIP union as the Eigen runtime's paper pipeline, the nets run by libtorch.
class TorchFrameDecoder final : public eval::FrameDecoder {
 public:
  explicit TorchFrameDecoder(const v1::DecoderModel& model, TorchVariant variant = TorchVariant::kEager);
  ~TorchFrameDecoder() override;
  void Reset(const decode::ShiftsPm* fill) override;
  decode::DecodeOutput Decode(const decode::ShiftsPm& shift_pm) override;

 private:
  void Push(const decode::ShiftsPm& shift_pm);
  TorchNets nets_;
  int window_;
  std::vector<float> mean_, window_shift_pm_, probabilities_;
  float gate_on_n_, gate_off_n_;
  bool gate_ = false;
  int filled_ = 0;
  std::unique_ptr<decode::Nip> nip_;
};

// The bench's libtorch configurations of one model: eager and frozen TorchScript. Calls UseOneTorchThread().
std::vector<eval::BenchDecoder> TorchBenchDecoders(const v1::DecoderModel& model);

}  // namespace ruffini::train
