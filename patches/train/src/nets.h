#pragma once
// The networks trained by ruffini::train, as libtorch modules (internal to the training library).
//
// ForceNet: the paper's CNN over a window of W frames; Mlp: one grid's location MLP (the layout exported
// and the one the eager libtorch decoder runs); MlpBank: the four grid MLPs trained as one module. FitNets:
// what one fit produces (the nets and the normalisations they were trained with).
#include <torch/torch.h>

#include "ruffini/frame.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

namespace ruffini::train::detail {

constexpr int kG = static_cast<int>(::ruffini::kGratings);

struct ForceNetImpl : torch::nn::Module {
  explicit ForceNetImpl(int window) {
    for (int k = 0; k < 3; ++k) {
      convs.push_back(register_module("conv" + std::to_string(k),
                                      torch::nn::Conv1d(torch::nn::Conv1dOptions(k == 0 ? window : 16, 16, 16))));
    }
    fc1 = register_module("fc1", torch::nn::Linear(32, 100));
    fc2 = register_module("fc2", torch::nn::Linear(100, 1));
  }
  torch::Tensor forward(torch::Tensor x) {  // [N, W, 16]
    // 'same' padding written out (7 zeros before, 8 after, as PyTorch's padding='same' does for kernel 16),
    // which the runtime mirrors with pad_left = 7.
    for (auto& c : convs) x = torch::max_pool1d(torch::relu(c->forward(torch::constant_pad_nd(x, {7, 8}))), 2);
    return fc2->forward(torch::relu(fc1->forward(x.flatten(1))));
  }
  std::vector<torch::nn::Conv1d> convs;
  torch::nn::Linear fc1{nullptr}, fc2{nullptr};
};
TORCH_MODULE(ForceNet);

struct MlpImpl : torch::nn::Module {
  MlpImpl(const std::vector<int>& w, int classes, double dropout) {
    l1 = register_module("l1", torch::nn::Linear(kG, w[0]));
    l2 = register_module("l2", torch::nn::Linear(w[0], w[1]));
    drop = register_module("drop", torch::nn::Dropout(dropout));
    l3 = register_module("l3", torch::nn::Linear(w[1], w[2]));
    out = register_module("out", torch::nn::Linear(w[2], classes));
  }
  torch::Tensor forward(torch::Tensor x) {
    x = torch::relu(l1->forward(x));
    x = drop->forward(torch::relu(l2->forward(x)));
    return out->forward(torch::relu(l3->forward(x)));
  }
  torch::nn::Linear l1{nullptr}, l2{nullptr}, l3{nullptr}, out{nullptr};
  torch::nn::Dropout drop{nullptr};
};
TORCH_MODULE(Mlp);

// The four grid MLPs trained as one module: every layer's weights stacked along a leading grid axis and
// applied with one batched matrix product, so a training step costs the framework overhead of one small
// MLP instead of four (the nets are tiny, and per-operation overhead, not arithmetic, dominated). The losses
// are summed, so each net's gradient is the one it would get alone. Output layers are padded to the largest
// grid; padded logits are pushed to -1e9 and never targeted. Exported as four separate nets.
struct MlpBankImpl : torch::nn::Module {
  MlpBankImpl(const std::vector<int>& w, const std::vector<int>& classes, double dropout_p, at::Generator generator)
      : dropout(dropout_p), gen(std::move(generator)) {
    const auto nets = static_cast<long>(classes.size());
    const long widest = *std::max_element(classes.begin(), classes.end());
    const std::array<long, 5> dims = {kG, w[0], w[1], w[2], widest};
    for (std::size_t k = 0; k < 4; ++k) {
      // PyTorch's Linear default: weights and biases uniform in +-1/sqrt(fan_in).
      const double bound = 1.0 / std::sqrt(static_cast<double>(dims[k]));
      const std::string index = std::to_string(k);  // (appending, not "w" + ...: GCC 12's -Wrestrict false positive)
      std::string w_name = "w", b_name = "b";
      w_name += index;
      b_name += index;
      weights.push_back(register_parameter(w_name, torch::empty({nets, dims[k], dims[k + 1]}).uniform_(-bound, bound, gen)));
      biases.push_back(register_parameter(b_name, torch::empty({nets, 1, dims[k + 1]}).uniform_(-bound, bound, gen)));
    }
    mask = torch::zeros({nets, 1, widest});
    for (long g = 0; g < nets; ++g) mask[g].narrow(1, classes[static_cast<std::size_t>(g)], widest - classes[static_cast<std::size_t>(g)]).fill_(-1e9);
    mask = register_buffer("mask", mask);
  }
  // x [N, 16] -> logits [nets, N, widest], padded entries at -1e9.
  torch::Tensor forward(const torch::Tensor& x) {
    auto h = x.unsqueeze(0).expand({weights[0].size(0), x.size(0), x.size(1)});
    for (std::size_t k = 0; k < 4; ++k) {
      h = torch::baddbmm(biases[k], h, weights[k]);
      if (k < 3) h = torch::relu(h);
      if (k == 1 && is_training() && dropout > 0) {  // the one dropout layer, after the second
        // Inverted dropout with this fit's own generator (fits run in parallel; the global one would make
        // the masks depend on thread timing).
        h = h * torch::empty_like(h).bernoulli_(1.0 - dropout, gen) / (1.0 - dropout);
      }
    }
    return h + mask;
  }
  std::vector<torch::Tensor> weights, biases;
  torch::Tensor mask;
  double dropout;
  at::Generator gen;
};
TORCH_MODULE(MlpBank);

struct Norm {
  std::array<float, kG> mean{}, std{};
};

// One fit: the force net, the location bank, their input normalisations and the force output scaling.
struct FitNets {
  ForceNet force{nullptr};
  MlpBank mlps{nullptr};
  Norm force_norm, loc_norm;
  float f_mean = 0, f_std = 1;
};

}  // namespace ruffini::train::detail
