#include "ruffini/decode/grids.h"

#include <algorithm>
#include <stdexcept>
#include <cmath>
#include <numbers>

namespace ruffini::decode {

int GridSpec::ClassOf(double y_mm, double r_deg) const {
  const double fy = (y_mm - y0_mm) / cell_y_mm, fr = (r_deg - r0_deg) / cell_r_deg;
  if (!(fy >= 0.0 && fr >= 0.0 && fy < ny && fr < nr)) return -1;
  return static_cast<int>(fy) * nr + static_cast<int>(fr);
}

patch::SurfacePoint GridSpec::Centre(int k) const {
  return {y0_mm + (k / nr + 0.5) * cell_y_mm, r0_deg + (k % nr + 0.5) * cell_r_deg};
}

void GridSpec::SoftLabels(double y_mm, double r_deg, double sigma_mm, double radius_mm, std::span<float> out) const {
  const double arc_mm_per_deg = radius_mm * std::numbers::pi / 180.0;
  const double s = sigma_mm * std::numbers::sqrt2;
  // The Gaussian is separable: a cell's share is the product of its Y and R shares (differences of erf).
  auto share = [s](double lo, double hi) { return 0.5 * (std::erf(hi / s) - std::erf(lo / s)); };
  auto cell = [&](int k) {
    const double ylo = y0_mm + (k / nr) * cell_y_mm - y_mm;
    const double rlo = (r0_deg + (k % nr) * cell_r_deg - r_deg) * arc_mm_per_deg;
    return share(ylo, ylo + cell_y_mm) * share(rlo, rlo + cell_r_deg * arc_mm_per_deg);
  };
  double total = 0.0;
  for (int k = 0; k < classes(); ++k) total += cell(k);
  if (!(total > 1e-12)) {
    int nearest = 0;
    double best = 1e300;
    for (int k = 0; k < classes(); ++k) {
      const auto c = Centre(k);
      const double d = std::hypot(c.y_mm - y_mm, (c.r_deg - r_deg) * arc_mm_per_deg);
      if (d < best) best = d, nearest = k;
    }
    for (int k = 0; k < classes(); ++k) out[static_cast<std::size_t>(k)] = k == nearest ? 1.0f : 0.0f;
    return;
  }
  for (int k = 0; k < classes(); ++k) out[static_cast<std::size_t>(k)] = static_cast<float>(cell(k) / total);
}

std::array<GridSpec, 4> PaperGrids(const patch::Region& a) { return PaperGrids(a, 6, 5); }

std::array<GridSpec, 4> PaperGrids(const patch::Region& a, int ny, int nr) {
  if (ny < 1 || nr < 1 || !(a.y_max_mm > a.y_min_mm) || !(a.r_max_deg > a.r_min_deg)) {
    throw std::invalid_argument("PaperGrids: need a non-empty area and at least one cell each way");
  }
  const double cy = (a.y_max_mm - a.y_min_mm) / ny, cr = (a.r_max_deg - a.r_min_deg) / nr;
  return {GridSpec{"SG", a.y_min_mm, a.r_min_deg, cy, cr, ny, nr},
          GridSpec{"VSG", a.y_min_mm - cy / 2, a.r_min_deg, cy, cr, ny + 1, nr},
          GridSpec{"HSG", a.y_min_mm, a.r_min_deg - cr / 2, cy, cr, ny, nr + 1},
          GridSpec{"DSG", a.y_min_mm - cy / 2, a.r_min_deg - cr / 2, cy, cr, ny + 1, nr + 1}};
}

std::array<GridSpec, 4> WholeSurfaceGrids(const patch::PatchSpec& spec) {
  const patch::Region& a = spec.indented_area;
  const double paper_cy = (a.y_max_mm - a.y_min_mm) / 6.0, paper_cr = (a.r_max_deg - a.r_min_deg) / 5.0;
  const patch::Region whole = spec.Extent();
  auto cells = [](double length, double paper_cell) {
    return paper_cell > 0 ? std::max(1, static_cast<int>(std::lround(length / paper_cell))) : 1;
  };
  return PaperGrids(whole, cells(whole.y_max_mm - whole.y_min_mm, paper_cy), cells(whole.r_max_deg - whole.r_min_deg, paper_cr));
}

Nip::Nip(std::span<const GridSpec> grids) : grids_(grids.size()) {
  // The fine grid: half-cell steps over the union of the grids' extents.
  double y0 = 1e300, r0 = 1e300, y1 = -1e300, r1 = -1e300, fy = 1e300, fr = 1e300;
  for (const auto& g : grids) {
    y0 = std::min(y0, g.y0_mm);
    r0 = std::min(r0, g.r0_deg);
    y1 = std::max(y1, g.y0_mm + g.ny * g.cell_y_mm);
    r1 = std::max(r1, g.r0_deg + g.nr * g.cell_r_deg);
    fy = std::min(fy, g.cell_y_mm / 2);
    fr = std::min(fr, g.cell_r_deg / 2);
    inputs_ += static_cast<std::size_t>(g.classes());
  }
  const int ny = static_cast<int>(std::lround((y1 - y0) / fy)), nr = static_cast<int>(std::lround((r1 - r0) / fr));
  for (int i = 0; i < ny; ++i) {
    for (int j = 0; j < nr; ++j) {
      const double y = y0 + (i + 0.5) * fy, r = r0 + (j + 0.5) * fr;
      centre_y_.push_back(y);
      centre_r_.push_back(r);
      std::size_t offset = 0;
      for (const auto& g : grids) {
        const int k = g.ClassOf(y, r);
        parent_.push_back(static_cast<std::int32_t>(k < 0 ? std::size_t{0} : offset + static_cast<std::size_t>(k)));
        if (k < 0) none_.push_back(parent_.size() - 1);
        offset += static_cast<std::size_t>(g.classes());
      }
    }
  }
  // A missing parent reads index `inputs_`: Weights() sees it as probability 0 (no branch per lookup).
  for (std::size_t k : none_) parent_[k] = static_cast<std::int32_t>(inputs_);
  none_.clear();
  if (centre_y_.size() > kMaxFineCells) throw std::length_error("NIP fine grid larger than kMaxFineCells");
}

void Nip::Weights(std::span<const float> p, float* w) const noexcept {
  const std::size_t cells = centre_y_.size();
  const std::int32_t* par = parent_.data();
  for (std::size_t c = 0; c < cells; ++c) {
    float acc = 0.0f;
    for (std::size_t g = 0; g < grids_; ++g) {
      const auto k = static_cast<std::size_t>(par[c * grids_ + g]);
      acc += k < inputs_ ? p[k] : 0.0f;
    }
    w[c] = acc;
  }
}

Nip::Estimate Nip::Fuse(std::span<const float> p, double radius_mm) const noexcept {
  std::array<float, kMaxFineCells> w;
  Weights(p, w.data());
  Estimate e;
  double sw = 0, sy = 0, sr = 0, best = 0;
  for (std::size_t c = 0; c < centre_y_.size(); ++c) {
    sw += w[c];
    sy += w[c] * centre_y_[c];
    sr += w[c] * centre_r_[c];
    best = std::max(best, static_cast<double>(w[c]));
  }
  if (!(sw > 0)) return e;
  e.ok = true;
  e.y_mm = sy / sw;
  e.r_deg = sr / sw;
  e.confidence = best / static_cast<double>(grids_);
  const double mm_per_deg = radius_mm * std::numbers::pi / 180.0;
  double syy = 0, sya = 0, saa = 0;
  for (std::size_t c = 0; c < centre_y_.size(); ++c) {
    const double dy = centre_y_[c] - e.y_mm, da = (centre_r_[c] - e.r_deg) * mm_per_deg;
    syy += w[c] * dy * dy;
    sya += w[c] * dy * da;
    saa += w[c] * da * da;
  }
  e.cov_yy_mm2 = syy / sw;
  e.cov_ya_mm2 = sya / sw;
  e.cov_aa_mm2 = saa / sw;
  e.spread_mm = std::sqrt(e.cov_yy_mm2 + e.cov_aa_mm2);
  return e;
}

double Nip::Locate(std::span<const float> p, double& y_mm, double& r_deg) const noexcept {
  const Estimate e = Fuse(p, 1.0);
  if (!e.ok) return 0.0;
  y_mm = e.y_mm;
  r_deg = e.r_deg;
  return e.confidence;
}

}  // namespace ruffini::decode
