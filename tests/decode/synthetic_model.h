#pragma once
// A hand-built model whose outputs are known functions of the input, for testing the runtime without
// training: the CNN passes grating values through (one tap per layer), so
//   force_n = 0.001 * (max(shift[0..7], 0) + max(shift[8..15], 0))     (shifts in pm, mean 0, std 1)
// and every location net maps the shifts to logits through `logit_gain` (large = huge logits).
#include "ruffini/decode/grids.h"
#include "ruffini/patch/spec.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::decode::testing {

inline void Fill(v1::Tensor* t, std::initializer_list<std::uint32_t> shape, float value = 0.0f) {
  std::size_t n = 1;
  for (auto d : shape) {
    t->add_shape(d);
    n *= d;
  }
  for (std::size_t k = 0; k < n; ++k) t->add_values(value);
}

inline v1::DecoderModel SyntheticModel(const patch::PatchSpec& spec, int window = 1, float logit_gain = 1.0f,
                                       float std_value = 1.0f) {
  v1::DecoderModel m;
  m.set_format_version(1);
  m.set_patch_name(spec.name);
  m.set_patch_fingerprint(spec.Fingerprint());
  m.set_surface_radius_mm(spec.surface_radius_mm);
  auto* f = m.mutable_force();
  f->set_window(static_cast<std::uint32_t>(window));
  for (int i = 0; i < 16; ++i) {
    f->mutable_input()->add_mean(0.0f);
    f->mutable_input()->add_std(std_value);
  }
  std::uint32_t in = static_cast<std::uint32_t>(window);
  for (int k = 0; k < 3; ++k) {
    auto* c = f->add_conv();
    Fill(c->mutable_weight(), {16, in, 16});
    // Output channel 0 copies input channel (window - 1 for the first layer: the newest frame), tap 7 = same position.
    const std::uint32_t src = k == 0 ? in - 1 : 0;
    c->mutable_weight()->set_values(static_cast<int>((0 * in + src) * 16 + 7), 1.0f);
    Fill(c->mutable_bias(), {16});
    c->set_pad_left(7);
    c->set_pool(2);
    in = 16;
  }
  auto* d1 = f->add_dense();  // flatten [16 ch x 2]: entries 0 and 1 are channel 0
  Fill(d1->mutable_weight(), {100, 32});
  d1->mutable_weight()->set_values(0, 1.0f);
  d1->mutable_weight()->set_values(1, 1.0f);
  Fill(d1->mutable_bias(), {100});
  d1->set_relu(true);
  auto* d2 = f->add_dense();
  Fill(d2->mutable_weight(), {1, 100});
  d2->mutable_weight()->set_values(0, 1.0f);
  Fill(d2->mutable_bias(), {1});
  f->set_output_scale_n(0.001f);
  f->set_output_offset_n(0.0f);
  for (const auto& g : PaperGrids(spec.indented_area)) {
    auto* l = m.add_location();
    auto* gr = l->mutable_grid();
    gr->set_name(g.name);
    gr->set_y0_mm(g.y0_mm);
    gr->set_r0_deg(g.r0_deg);
    gr->set_cell_y_mm(g.cell_y_mm);
    gr->set_cell_r_deg(g.cell_r_deg);
    gr->set_ny(static_cast<std::uint32_t>(g.ny));
    gr->set_nr(static_cast<std::uint32_t>(g.nr));
    for (int i = 0; i < 16; ++i) {
      l->mutable_input()->add_mean(0.0f);
      l->mutable_input()->add_std(std_value);
    }
    const auto classes = static_cast<std::uint32_t>(g.classes());
    std::uint32_t w_in = 16;
    for (std::uint32_t out : {8u, 8u, 8u, classes}) {
      auto* d = l->add_dense();
      Fill(d->mutable_weight(), {out, w_in});
      for (std::uint32_t r = 0; r < out; ++r) {
        // A fixed, input-dependent pattern: row r reads input (r % w_in) with a sign that alternates.
        d->mutable_weight()->set_values(static_cast<int>(r * w_in + r % w_in), (r % 2 ? -1.0f : 1.0f) * logit_gain);
      }
      Fill(d->mutable_bias(), {out});
      d->set_relu(out != classes);
      w_in = out;
    }
  }
  m.mutable_gating()->set_on_n(0.05f);
  m.mutable_gating()->set_off_n(0.04f);
  return m;
}

}  // namespace ruffini::decode::testing
