#include "ruffini/train/torch_decoder.h"

#include <ATen/Parallel.h>
#include <torch/script.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <sstream>

#include "nets.h"

namespace ruffini::train {
namespace {

using namespace detail;

// prefix + k + suffix, by appending (GCC 12's -Wrestrict false positive on "literal" + std::string).
std::string Name(const char* prefix, int k, const char* suffix = "") {
  std::string out = prefix;
  out += std::to_string(k);
  out += suffix;
  return out;
}

torch::Tensor FromModel(const v1::Tensor& src) {
  std::vector<std::int64_t> shape(src.shape().begin(), src.shape().end());
  return torch::from_blob(const_cast<float*>(src.values().data()), shape, torch::kFloat).clone();
}

// The force CNN as TorchScript: the same ops as ForceNetImpl::forward, weights as module parameters.
torch::jit::Module ScriptedForceNet(const v1::ForceNet& f) {
  torch::jit::Module m("RuffiniForceNet");
  std::ostringstream src;
  src << "def forward(self, x):\n";
  for (int k = 0; k < f.conv_size(); ++k) {
    m.register_parameter(Name("conv", k, "_w"), FromModel(f.conv(k).weight()), false);
    m.register_parameter(Name("conv", k, "_b"), FromModel(f.conv(k).bias()), false);
    src << "    x = torch.max_pool1d(torch.relu(torch.conv1d(torch.constant_pad_nd(x, [7, 8], 0.0), self.conv" << k
        << "_w, self.conv" << k << "_b)), 2)\n";
  }
  src << "    x = torch.flatten(x, 1)\n";
  for (int k = 0; k < f.dense_size(); ++k) {
    m.register_parameter(Name("dense", k, "_w"), FromModel(f.dense(k).weight()), false);
    m.register_parameter(Name("dense", k, "_b"), FromModel(f.dense(k).bias()), false);
    src << "    x = torch.linear(x, self.dense" << k << "_w, self.dense" << k << "_b)\n";
    if (f.dense(k).relu()) src << "    x = torch.relu(x)\n";
  }
  src << "    return x\n";
  m.define(src.str());
  return m;
}

// Every grid's MLP and softmax as one TorchScript module: x [grids, 16] (row g z-scored for grid g) ->
// the softmaxes concatenated, [1, sum of classes].
torch::jit::Module ScriptedLocationNets(const v1::DecoderModel& model) {
  torch::jit::Module m("RuffiniLocationNets");
  std::ostringstream src;
  src << "def forward(self, x):\n";
  std::string outs;
  for (int g = 0; g < model.location_size(); ++g) {
    const auto& ln = model.location(g);
    const std::string h = Name("h", g);
    src << "    " << h << " = x[" << g << ":" << g + 1 << "]\n";
    for (int k = 0; k < ln.dense_size(); ++k) {
      const std::string name = Name(Name("g", g, "_dense").c_str(), k, "_");
      m.register_parameter(name + 'w', FromModel(ln.dense(k).weight()), false);
      m.register_parameter(name + 'b', FromModel(ln.dense(k).bias()), false);
      src << "    " << h << " = torch.linear(" << h << ", self." << name << "w, self." << name << "b)\n";
      if (ln.dense(k).relu()) src << "    " << h << " = torch.relu(" << h << ")\n";
    }
    src << "    " << h << " = torch.softmax(" << h << ", 1)\n";
    if (!outs.empty()) outs += ", ";
    outs += h;
  }
  src << "    return torch.cat([" << outs << "], 1)\n";
  m.define(src.str());
  return m;
}

torch::jit::Module Freeze(torch::jit::Module m) {
  m.register_attribute("training", c10::BoolType::get(), false);
  m.eval();
  torch::jit::Module frozen = torch::jit::freeze(m);
  return torch::jit::optimize_for_inference(frozen);
}

}  // namespace

std::string VariantName(TorchVariant v) { return v == TorchVariant::kEager ? "libtorch eager" : "libtorch TorchScript frozen"; }

void UseOneTorchThread() {
  static std::once_flag once;
  std::call_once(once, [] {
    torch::set_num_threads(1);
    try {
      at::set_num_interop_threads(1);
    } catch (const c10::Error&) {
      // Already set, or inter-op work already started in this process: inter-op parallelism is unused by
      // batch-1 inference of these nets either way.
    }
  });
}

struct TorchNets::Impl {
  // Eager.
  ForceNet net{nullptr};
  std::vector<Mlp> mlps;
  // Frozen.
  std::unique_ptr<torch::jit::Module> force_script, location_script;
  // Both: input normalisation and scratch inputs.
  std::vector<Norm> mlp_norms;
  std::vector<float> unit_floor;  // 0: RAW input
  int window = 1;
  std::array<float, kG> mean{}, inv_std{};
  float scale = 1, offset = 0;
  torch::Tensor x, loc_x;  // [1, W, 16]; eager [1, 16], frozen [grids, 16]
};

TorchNets::TorchNets(const v1::DecoderModel& m, TorchVariant variant) : impl_(std::make_unique<Impl>()), variant_(variant) {
  const auto& f = m.force();
  impl_->window = static_cast<int>(f.window());
  for (int i = 0; i < kG; ++i) {
    impl_->mean[static_cast<std::size_t>(i)] = f.input().mean(i);
    impl_->inv_std[static_cast<std::size_t>(i)] = 1.0f / f.input().std(i);
  }
  impl_->scale = f.output_scale_n();
  impl_->offset = f.output_offset_n();
  impl_->x = torch::empty({1, impl_->window, kG});
  for (const auto& ln : m.location()) {
    Norm nm;
    for (int i = 0; i < kG; ++i) {
      nm.mean[static_cast<std::size_t>(i)] = ln.input().mean(i);
      nm.std[static_cast<std::size_t>(i)] = ln.input().std(i);
    }
    impl_->mlp_norms.push_back(nm);
    impl_->unit_floor.push_back(ln.input_kind() == v1::LocationNet::UNIT ? ln.unit_floor_pm() : 0.0f);
  }
  if (variant == TorchVariant::kFrozen) {
    impl_->force_script = std::make_unique<torch::jit::Module>(Freeze(ScriptedForceNet(f)));
    impl_->location_script = std::make_unique<torch::jit::Module>(Freeze(ScriptedLocationNets(m)));
    impl_->loc_x = torch::empty({static_cast<long>(m.location_size()), kG});
    return;
  }
  impl_->net = ForceNet(impl_->window);
  torch::NoGradGuard no_grad;
  auto load = [](torch::Tensor& t, const v1::Tensor& src) {
    t.copy_(torch::from_blob(const_cast<float*>(src.values().data()), t.sizes(), torch::kFloat));
  };
  for (int k = 0; k < 3; ++k) {
    load(impl_->net->convs[static_cast<std::size_t>(k)]->weight, f.conv(k).weight());
    load(impl_->net->convs[static_cast<std::size_t>(k)]->bias, f.conv(k).bias());
  }
  load(impl_->net->fc1->weight, f.dense(0).weight());
  load(impl_->net->fc1->bias, f.dense(0).bias());
  load(impl_->net->fc2->weight, f.dense(1).weight());
  load(impl_->net->fc2->bias, f.dense(1).bias());
  impl_->net->eval();
  for (const auto& ln : m.location()) {
    std::vector<int> widths;
    for (int k = 0; k < 3; ++k) widths.push_back(static_cast<int>(ln.dense(k).weight().shape(0)));
    Mlp mlp(widths, static_cast<int>(ln.grid().ny() * ln.grid().nr()), 0.0);
    int k = 0;
    for (auto* lin : {&mlp->l1, &mlp->l2, &mlp->l3, &mlp->out}) {
      load((*lin)->weight, ln.dense(k).weight());
      load((*lin)->bias, ln.dense(k).bias());
      ++k;
    }
    mlp->eval();
    impl_->mlps.push_back(mlp);
  }
  impl_->loc_x = torch::empty({1, kG});
}

TorchNets::~TorchNets() = default;

float TorchNets::Forward(const float* w) {
  c10::InferenceMode inference;
  float* d = impl_->x.data_ptr<float>();
  for (int t = 0; t < impl_->window; ++t) {
    for (int i = 0; i < kG; ++i) {
      const auto ui = static_cast<std::size_t>(i);
      d[t * kG + i] = (w[t * kG + i] - impl_->mean[ui]) * impl_->inv_std[ui];
    }
  }
  const torch::Tensor y = variant_ == TorchVariant::kEager ? impl_->net->forward(impl_->x)
                                                             : impl_->force_script->forward({impl_->x}).toTensor();
  return y.item<float>() * impl_->scale + impl_->offset;
}

void TorchNets::Locate(const float* s, std::vector<float>& out) {
  c10::InferenceMode inference;
  out.clear();
  // Each grid's z-scored input (unit input: the shifts over their norm first).
  auto fill = [&](std::size_t g, float* d) {
    float scale = 1.0f;
    if (impl_->unit_floor[g] > 0.0f) {
      double n2 = 0;
      for (std::size_t i = 0; i < static_cast<std::size_t>(kG); ++i) n2 += static_cast<double>(s[i]) * s[i];
      scale = 1.0f / std::max(static_cast<float>(std::sqrt(n2)), impl_->unit_floor[g]);
    }
    for (std::size_t i = 0; i < static_cast<std::size_t>(kG); ++i) {
      d[i] = (s[i] * scale - impl_->mlp_norms[g].mean[i]) / impl_->mlp_norms[g].std[i];
    }
  };
  if (variant_ == TorchVariant::kFrozen) {
    float* d = impl_->loc_x.data_ptr<float>();
    for (std::size_t g = 0; g < impl_->mlp_norms.size(); ++g) fill(g, d + g * static_cast<std::size_t>(kG));
    const auto p = impl_->location_script->forward({impl_->loc_x}).toTensor().contiguous();
    out.insert(out.end(), p.data_ptr<float>(), p.data_ptr<float>() + p.numel());
    return;
  }
  for (std::size_t g = 0; g < impl_->mlps.size(); ++g) {
    fill(g, impl_->loc_x.data_ptr<float>());
    const auto p = torch::softmax(impl_->mlps[g]->forward(impl_->loc_x), 1).contiguous();
    out.insert(out.end(), p.data_ptr<float>(), p.data_ptr<float>() + p.numel());
  }
}

TorchFrameDecoder::TorchFrameDecoder(const v1::DecoderModel& m, TorchVariant variant)
    : nets_(m, variant), window_(static_cast<int>(m.force().window())), mean_(kG),
      window_shift_pm_(static_cast<std::size_t>(window_) * kG), gate_on_n_(m.gating().on_n()), gate_off_n_(m.gating().off_n()) {
  std::vector<decode::GridSpec> grids;
  for (const auto& l : m.location()) {
    const auto& g = l.grid();
    grids.push_back({g.name(), g.y0_mm(), g.r0_deg(), g.cell_y_mm(), g.cell_r_deg(), static_cast<int>(g.ny()), static_cast<int>(g.nr())});
  }
  nip_ = std::make_unique<decode::Nip>(grids);
  for (int i = 0; i < kG; ++i) mean_[static_cast<std::size_t>(i)] = m.force().input().mean(i);
}

TorchFrameDecoder::~TorchFrameDecoder() = default;

void TorchFrameDecoder::Reset(const decode::ShiftsPm* fill) {
  gate_ = false;
  filled_ = 0;
  if (fill) {
    for (int t = 0; t < window_; ++t) Push(*fill);
    filled_ = window_ - 1;
  }
}

decode::DecodeOutput TorchFrameDecoder::Decode(const decode::ShiftsPm& s) {
  decode::DecodeOutput o;
  Push(s);
  if (filled_ < window_) return o;
  o.valid = true;
  o.force_n = nets_.Forward(window_shift_pm_.data());
  gate_ = gate_ ? o.force_n > gate_off_n_ : o.force_n > gate_on_n_;
  o.in_contact = gate_;
  if (!gate_) return o;
  nets_.Locate(window_shift_pm_.data() + (window_ - 1) * kG, probabilities_);
  double y = 0, r = 0;
  o.confidence = static_cast<float>(nip_->Locate(probabilities_, y, r));
  o.y_mm = static_cast<float>(y);
  o.r_deg = static_cast<float>(r);
  o.located = true;
  return o;
}

void TorchFrameDecoder::Push(const decode::ShiftsPm& s) {
  std::copy(window_shift_pm_.begin() + kG, window_shift_pm_.end(), window_shift_pm_.begin());  // oldest first
  for (std::size_t i = 0; i < static_cast<std::size_t>(kG); ++i) {
    window_shift_pm_[(static_cast<std::size_t>(window_) - 1) * kG + i] = std::isfinite(s[i]) ? s[i] : mean_[i];
  }
  filled_ = std::min(filled_ + 1, window_);
}

std::vector<eval::BenchDecoder> TorchBenchDecoders(const v1::DecoderModel& model) {
  UseOneTorchThread();
  std::vector<eval::BenchDecoder> out;
  for (TorchVariant v : {TorchVariant::kEager, TorchVariant::kFrozen}) {
    out.push_back({VariantName(v) + ", same weights", eval::Runtime::kLibtorch, std::make_unique<TorchFrameDecoder>(model, v)});
  }
  return out;
}

}  // namespace ruffini::train
