#include "ruffini/decode/network_decoder.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "ruffini/error.h"

namespace ruffini::decode {
namespace {
// Inputs are z-scored with the training statistics. A z-score beyond +-kMaxZ lies far outside anything the
// nets were trained on (a channel that never moved in training has std 1e-3 pm); clamping keeps every
// activation finite in float instead of letting it overflow to inf and NaN.
constexpr double kMaxZ = 1e3;
template <typename Scalar>
Scalar ZScore(Scalar raw, Scalar mean, Scalar inv_std) noexcept {
  return std::clamp((raw - mean) * inv_std, Scalar(-kMaxZ), Scalar(kMaxZ));
}
}  // namespace

template <typename Scalar>
NetworkDecoder<Scalar>::NetworkDecoder(const v1::DecoderModel& m, DecoderOptions options)
    : window_(static_cast<int>(m.force().window())), radius_mm_(m.surface_radius_mm()), max_missing_(options.max_missing) {
  const auto& f = m.force();
  for (int i = 0; i < 16; ++i) {
    f_mean_[static_cast<std::size_t>(i)] = static_cast<Scalar>(f.input().mean(i));
    f_inv_std_[static_cast<std::size_t>(i)] = static_cast<Scalar>(1.0 / f.input().std(i));
  }
  int channels = window_, length = 16;
  for (const auto& c : f.conv()) {
    const int out = static_cast<int>(c.weight().shape(0)), kernel = static_cast<int>(c.weight().shape(2));
    const int pad = static_cast<int>(c.pad_left());
    Layer l;
    l.w = Matrix::Zero(out * length, channels * length);
    l.b.resize(out * length);
    for (int o = 0; o < out; ++o) {
      for (int p = 0; p < length; ++p) {
        l.b[o * length + p] = static_cast<Scalar>(c.bias().values(o));
        for (int i = 0; i < channels; ++i) {
          for (int k = 0; k < kernel; ++k) {
            const int q = p + k - pad;  // cross-correlation, zero padding
            if (q < 0 || q >= length) continue;
            l.w(o * length + p, i * length + q) += static_cast<Scalar>(c.weight().values((o * channels + i) * kernel + k));
          }
        }
      }
    }
    l.channels = out;
    l.length = length;
    l.pool = static_cast<int>(c.pool());
    force_.push_back(std::move(l));
    channels = out;
    length /= static_cast<int>(c.pool());
  }
  auto dense = [](const v1::DenseLayer& d) {
    Layer l;
    const auto out = static_cast<Eigen::Index>(d.weight().shape(0)), in = static_cast<Eigen::Index>(d.weight().shape(1));
    l.w.resize(out, in);
    for (Eigen::Index r = 0; r < out; ++r) {
      for (Eigen::Index c = 0; c < in; ++c) l.w(r, c) = static_cast<Scalar>(d.weight().values(static_cast<int>(r * in + c)));
    }
    l.b.resize(out);
    for (Eigen::Index r = 0; r < out; ++r) l.b[r] = static_cast<Scalar>(d.bias().values(static_cast<int>(r)));
    l.relu = d.relu();
    return l;
  };
  for (const auto& d : f.dense()) force_.push_back(dense(d));
  out_scale_ = static_cast<Scalar>(f.output_scale_n());
  out_offset_ = static_cast<Scalar>(f.output_offset_n());

  std::vector<int> chosen = options.grids;
  if (chosen.empty()) {
    for (int k = 0; k < m.location_size(); ++k) chosen.push_back(k);
  }
  std::vector<GridSpec> grids;
  for (int k : chosen) {
    if (k < 0 || k >= m.location_size()) throw InputError("decoder option names location net " + std::to_string(k) + ", the model has " + std::to_string(m.location_size()));
    const auto& ln = m.location(k);
    Mlp mlp;
    for (int i = 0; i < 16; ++i) {
      mlp.mean[static_cast<std::size_t>(i)] = static_cast<Scalar>(ln.input().mean(i));
      mlp.inv_std[static_cast<std::size_t>(i)] = static_cast<Scalar>(1.0 / ln.input().std(i));
    }
    for (const auto& d : ln.dense()) mlp.layers.push_back(dense(d));
    mlp.unit = ln.input_kind() == v1::LocationNet::UNIT;
    mlp.unit_floor = static_cast<Scalar>(mlp.unit ? ln.unit_floor_pm() : 1.0f);
    if (!(mlp.unit_floor > 0)) throw InputError("location net " + ln.grid().name() + ": unit_floor_pm must be > 0");
    location_.push_back(std::move(mlp));
    const auto& g = ln.grid();
    grids.push_back(GridSpec{g.name(), g.y0_mm(), g.r0_deg(), g.cell_y_mm(), g.cell_r_deg(), static_cast<int>(g.ny()),
                             static_cast<int>(g.nr())});
  }
  nip_ = std::make_unique<Nip>(grids);
  if (m.has_creep()) {
    if (!(options.sample_rate_hz > 0)) throw InputError("decoder option sample_rate_hz must be > 0");
    creep_terms_ = std::min(4, m.creep().g_size());
    for (int k = 0; k < creep_terms_; ++k) {
      creep_g_[static_cast<std::size_t>(k)] = m.creep().g(k);
      creep_a_[static_cast<std::size_t>(k)] = 1.0 - std::exp(-1.0 / (options.sample_rate_hz * m.creep().tau_s(k)));
    }
  }
  gate_on_n_ = m.gating().on_n();
  gate_off_n_ = m.gating().off_n();
}

template <typename Scalar>
NetworkDecoder<Scalar>::Data::Data(const NetworkDecoder& d) {
  window.setZero(d.window_, 16);
  flat.setZero(d.window_ * 16);
  for (const auto& l : d.force_) act.push_back(Vector::Zero(l.w.rows()));
  std::size_t widest = 16;
  for (const auto& m : d.location_) {
    for (const auto& l : m.layers) widest = std::max(widest, static_cast<std::size_t>(l.w.rows()));
  }
  // Two ping-pong buffers of the widest location layer, plus the input.
  loc.assign(3, Vector::Zero(static_cast<Eigen::Index>(widest)));
  probabilities.assign(d.nip_->inputs(), 0.0f);
}

template <typename Scalar>
void NetworkDecoder<Scalar>::RunForce(Data& d) const noexcept {
  const Vector* x = &d.flat;
  for (std::size_t k = 0; k < force_.size(); ++k) {
    const Layer& l = force_[k];
    Vector& y = d.act[k];
    y.noalias() = l.w * (*x);
    y += l.b;
    if (l.relu) y = y.cwiseMax(Scalar(0));
    if (l.pool > 1) {  // max-pool in place along each channel: y[c*L/p + j] = max over the pool
      const int out_len = l.length / l.pool;
      for (int c = 0; c < l.channels; ++c) {
        for (int j = 0; j < out_len; ++j) {
          Scalar v = y[c * l.length + j * l.pool];
          for (int t = 1; t < l.pool; ++t) v = std::max(v, y[c * l.length + j * l.pool + t]);
          y[c * out_len + j] = v;  // writes never overtake reads (c*out_len + j <= c*L + j*p)
        }
      }
      // The next layer reads the first channels*out_len entries: expose them as a segment.
      x = &y;
      continue;
    }
    x = &y;
  }
}

template <typename Scalar>
void NetworkDecoder<Scalar>::Reset(Data& d, const ShiftsPm* fill) const noexcept {
  d.gate = false;
  d.head = 0;
  d.filled = 0;
  d.creep_x.fill(0.0);
  if (fill == nullptr) return;
  for (int t = 0; t < window_ - 1; ++t) {
    for (std::size_t i = 0; i < 16; ++i) {
      const Scalar raw = std::isfinite((*fill)[i]) ? static_cast<Scalar>((*fill)[i]) : f_mean_[i];
      d.window(t, static_cast<Eigen::Index>(i)) = ZScore(raw, f_mean_[i], f_inv_std_[i]);
    }
  }
  d.head = (window_ - 1) % window_;
  d.filled = window_ - 1;
}

template <typename Scalar>
float NetworkDecoder<Scalar>::ForceOnWindow(const float* w, Data& d) const noexcept {
  for (int t = 0; t < window_; ++t) {
    for (int i = 0; i < 16; ++i) {
      const auto ui = static_cast<std::size_t>(i);
      d.flat[t * 16 + i] = ZScore(static_cast<Scalar>(w[t * 16 + i]), f_mean_[ui], f_inv_std_[ui]);
    }
  }
  RunForce(d);
  return static_cast<float>(d.act.back()[0] * out_scale_ + out_offset_);
}

template <typename Scalar>
void NetworkDecoder<Scalar>::RunLocation(const std::array<Scalar, kGratings>& raw, const std::array<bool, kGratings>& present,
                                          Data& d) const noexcept {
  // The norm of the present gratings' shifts, for nets that see the unit pattern. Shifts are clamped to
  // +-1e6 pm first so the sum of squares stays finite in float.
  Scalar norm2 = 0;
  for (std::size_t i = 0; i < 16; ++i) {
    if (!present[i]) continue;
    const Scalar v = std::clamp(raw[i], Scalar(-1e6), Scalar(1e6));
    norm2 += v * v;
  }
  const Scalar norm = std::sqrt(norm2);
  std::size_t offset = 0;
  for (const Mlp& m : location_) {
    Vector& in = d.loc[2];
    const Scalar scale = m.unit ? Scalar(1) / std::max(norm, m.unit_floor) : Scalar(1);
    for (std::size_t i = 0; i < 16; ++i) {
      // A missing grating is z = 0 (no information), as in training.
      in[static_cast<Eigen::Index>(i)] = present[i] ? ZScore(raw[i] * scale, m.mean[i], m.inv_std[i]) : Scalar(0);
    }
    const Vector* x = &in;
    Eigen::Index n = 16;
    for (std::size_t k = 0; k < m.layers.size(); ++k) {
      const Layer& l = m.layers[k];
      Vector& y = d.loc[k % 2];
      const Eigen::Index rows = l.w.rows();
      y.head(rows).noalias() = l.w * x->head(n);
      y.head(rows) += l.b;
      if (l.relu) y.head(rows) = y.head(rows).cwiseMax(Scalar(0));
      x = &y;
      n = rows;
    }
    // Stable softmax: subtract the largest logit (no overflow however large the logits are).
    const Scalar top = x->head(n).maxCoeff();
    Scalar sum = 0;
    for (Eigen::Index k = 0; k < n; ++k) sum += std::exp((*x)[k] - top);
    for (Eigen::Index k = 0; k < n; ++k) {
      d.probabilities[offset + static_cast<std::size_t>(k)] = static_cast<float>(std::exp((*x)[k] - top) / sum);
    }
    offset += static_cast<std::size_t>(n);
  }
}

template <typename Scalar>
DecodeOutput NetworkDecoder<Scalar>::Decode(const ShiftsPm& shift, Data& d) const noexcept {
  DecodeOutput out;
  // Missing peaks (NaN/Inf) take the training mean: they carry no information, and z = 0 says so.
  std::array<Scalar, kGratings> raw{};
  std::array<bool, kGratings> present{};
  int missing = 0;
  for (std::size_t i = 0; i < 16; ++i) {
    present[i] = std::isfinite(shift[i]);
    if (present[i]) {
      raw[i] = static_cast<Scalar>(shift[i]);
    } else {
      raw[i] = f_mean_[i];
      ++missing;
    }
  }
  out.missing = static_cast<std::uint8_t>(missing);
  for (std::size_t i = 0; i < 16; ++i) d.window(d.head, static_cast<Eigen::Index>(i)) = ZScore(raw[i], f_mean_[i], f_inv_std_[i]);
  d.head = (d.head + 1) % window_;
  d.filled = std::min(d.filled + 1, window_);
  if (missing > max_missing_ || d.filled < window_) {
    d.gate = false;
    return out;  // invalid: force 0, not located
  }
  for (int t = 0; t < window_; ++t) {  // oldest first
    const int row = (d.head + t) % window_;
    d.flat.segment(t * 16, 16) = d.window.row(row).transpose();
  }
  RunForce(d);
  Scalar f = d.act.back()[0] * out_scale_ + out_offset_;
  if (creep_terms_ > 0 && std::isfinite(static_cast<double>(f))) {
    double num = static_cast<double>(f), den = 1.0;
    for (int k = 0; k < creep_terms_; ++k) {
      const auto u = static_cast<std::size_t>(k);
      num -= creep_g_[u] * (1.0 - creep_a_[u]) * d.creep_x[u];
      den += creep_g_[u] * creep_a_[u];
    }
    const double applied = num / den;
    // The state follows the applied force; never below 0 (the cover is not pulled), so a long negative
    // excursion of the nets' output cannot wind the filter up.
    for (int k = 0; k < creep_terms_; ++k) {
      const auto u = static_cast<std::size_t>(k);
      d.creep_x[u] += creep_a_[u] * (std::max(0.0, applied) - d.creep_x[u]);
    }
    f = static_cast<Scalar>(applied);
  }
  out.force_n = std::isfinite(static_cast<float>(f)) ? static_cast<float>(f) : 0.0f;
  out.valid = std::isfinite(static_cast<float>(f));
  if (!out.valid) return out;
  d.gate = d.gate ? out.force_n > gate_off_n_ : out.force_n > gate_on_n_;
  out.in_contact = d.gate;
  if (!d.gate) return out;
  RunLocation(raw, present, d);
  const Nip::Estimate e = nip_->Fuse(d.probabilities, radius_mm_);
  out.confidence = static_cast<float>(e.confidence);
  out.location_sigma_mm = static_cast<float>(e.spread_mm);
  out.cov_yy_mm2 = static_cast<float>(e.cov_yy_mm2);
  out.cov_ya_mm2 = static_cast<float>(e.cov_ya_mm2);
  out.cov_aa_mm2 = static_cast<float>(e.cov_aa_mm2);
  out.y_mm = static_cast<float>(e.y_mm);
  out.r_deg = static_cast<float>(e.r_deg);
  out.located = e.ok;
  return out;
}

template <typename Scalar>
void NetworkDecoder<Scalar>::Probabilities(const ShiftsPm& shift, Data& d, std::vector<float>& out) const {
  std::array<Scalar, kGratings> raw{};
  std::array<bool, kGratings> present{};
  for (std::size_t i = 0; i < 16; ++i) {
    present[i] = std::isfinite(shift[i]);
    raw[i] = present[i] ? static_cast<Scalar>(shift[i]) : Scalar(0);
  }
  RunLocation(raw, present, d);
  out = d.probabilities;
}

template class NetworkDecoder<float>;
template class NetworkDecoder<double>;

}  // namespace ruffini::decode
