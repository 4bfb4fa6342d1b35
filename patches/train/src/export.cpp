#include "export.h"

#include <cstdint>

namespace ruffini::train::detail {
namespace {

void Put(v1::Tensor* t, const torch::Tensor& x) {
  const auto c = x.detach().contiguous().to(torch::kFloat);
  for (auto d : c.sizes()) t->add_shape(static_cast<std::uint32_t>(d));
  t->mutable_values()->Add(c.data_ptr<float>(), c.data_ptr<float>() + c.numel());
}

void PutNorm(v1::Normalization* out, const Norm& nm) {
  for (int i = 0; i < kG; ++i) {
    out->add_mean(nm.mean[static_cast<std::size_t>(i)]);
    out->add_std(nm.std[static_cast<std::size_t>(i)]);
  }
}

}  // namespace

void ExportNets(const FitNets& n, const std::array<decode::GridSpec, 4>& grids, const TrainOptions& o,
                v1::DecoderModel& m) {
  auto* fn = m.mutable_force();
  fn->set_window(static_cast<std::uint32_t>(o.window));
  PutNorm(fn->mutable_input(), n.force_norm);
  for (const auto& c : n.force->convs) {
    auto* l = fn->add_conv();
    Put(l->mutable_weight(), c->weight);
    Put(l->mutable_bias(), c->bias);
    l->set_pad_left(7);  // PyTorch 'same' for kernel 16: 15 zeros, 7 before and 8 after
    l->set_pool(2);
  }
  for (const auto* lin : {&n.force->fc1, &n.force->fc2}) {
    auto* d = fn->add_dense();
    Put(d->mutable_weight(), (*lin)->weight);
    Put(d->mutable_bias(), (*lin)->bias);
    d->set_relu(lin == &n.force->fc1);
  }
  fn->set_output_scale_n(n.f_std);
  fn->set_output_offset_n(n.f_mean);
  for (std::size_t g = 0; g < grids.size(); ++g) {
    auto* ln = m.add_location();
    auto* gr = ln->mutable_grid();
    gr->set_name(grids[g].name);
    gr->set_y0_mm(grids[g].y0_mm);
    gr->set_r0_deg(grids[g].r0_deg);
    gr->set_cell_y_mm(grids[g].cell_y_mm);
    gr->set_cell_r_deg(grids[g].cell_r_deg);
    gr->set_ny(static_cast<std::uint32_t>(grids[g].ny));
    gr->set_nr(static_cast<std::uint32_t>(grids[g].nr));
    PutNorm(ln->mutable_input(), n.loc_norm);
    if (o.location_input == "unit") {
      ln->set_input_kind(v1::LocationNet::UNIT);
      ln->set_unit_floor_pm(static_cast<float>(o.unit_floor_pm));
    }
    for (std::size_t k = 0; k < 4; ++k) {
      // Stacked [in, out] -> a Linear's [out, in]; the output layer loses its padding.
      auto w = n.mlps->weights[k][static_cast<long>(g)].t();
      auto b = n.mlps->biases[k][static_cast<long>(g)][0];
      if (k == 3) {
        w = w.narrow(0, 0, grids[g].classes());
        b = b.narrow(0, 0, grids[g].classes());
      }
      auto* d = ln->add_dense();
      Put(d->mutable_weight(), w);
      Put(d->mutable_bias(), b);
      d->set_relu(k < 3);
    }
  }
  m.mutable_gating()->set_on_n(static_cast<float>(o.gate_n));
  m.mutable_gating()->set_off_n(static_cast<float>(0.8 * o.gate_n));
}

void AddGoldenVector(std::span<const float> window_shift_pm, float force_n, std::span<const float> probabilities,
                     const decode::Nip& nip, v1::DecoderModel& m) {
  auto* gv = m.add_golden();
  gv->mutable_window_shift_pm()->Add(window_shift_pm.begin(), window_shift_pm.end());
  gv->set_force_n(force_n);
  gv->mutable_probabilities()->Add(probabilities.begin(), probabilities.end());
  double y = 0, r = 0;
  nip.Locate(probabilities, y, r);
  gv->set_y_mm(y);
  gv->set_r_deg(r);
}

}  // namespace ruffini::train::detail
