#include "ruffini/decode/touches.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "ruffini/error.h"

namespace ruffini::decode {
namespace {

// The misfit's noise allowance per grating, pm: the interrogator's noise (0.3 pm) and the baseline's wander
// leave a light touch's shifts a few tenths of a pm from any model; 1 pm per grating keeps them from reading
// as a misfit.
constexpr double kNoisePm = 1.0;
// The two-touch fit's refinement window (nodes), the single check's default: +-2 nodes (+-3 mm at the fit's 1.5 mm).
constexpr int kWindow = TouchCheck::kDefaultWindow;
// The two-touch fit's search stride over the map (nodes), then a +-kWindow refinement at full resolution.
constexpr int kStride = 2;

struct Frame {
  std::array<double, kGratings> s{}, use{};
  double ss = 0.0;
  int n = 0;
};

Frame Prepare(const ShiftsPm& shift) {
  Frame f;
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (!std::isfinite(shift[i])) continue;
    f.s[i] = shift[i];
    f.use[i] = 1.0;
    f.ss += f.s[i] * f.s[i];
    ++f.n;
  }
  return f;
}

}  // namespace

TouchCheck::TouchCheck(const v1::ResponseMap& map) : model_(FromProto(map)), limit_(map.multiple_misfit()) {
  if (!(limit_ >= 0 && limit_ <= 1)) throw InputError("response map: multiple_misfit must be 0..1");
}

TouchCheck::Best TouchCheck::SearchOne(const ShiftsPm& shift, int iy0, int iy1, int ir0, int ir1, int stride) const noexcept {
  const Frame f = Prepare(shift);
  Best best{-1, f.ss, 0.0};
  for (int iy = std::max(0, iy0); iy <= std::min(model_.ny - 1, iy1); iy += stride) {
    for (int ir = std::max(0, ir0); ir <= std::min(model_.nr - 1, ir1); ir += stride) {
      const int node = iy * model_.nr + ir;
      const auto& g = model_.g[static_cast<std::size_t>(node)];
      double sg = 0, gg = 0;
      for (std::size_t i = 0; i < kGratings; ++i) {
        sg += f.use[i] * f.s[i] * g[i];
        gg += f.use[i] * static_cast<double>(g[i]) * g[i];
      }
      if (!(gg > 0) || sg <= 0) continue;  // a press pushes: a negative amplitude explains nothing
      const double cost = f.ss - sg * sg / gg;
      if (cost < best.cost) best = {node, cost, sg / gg};
    }
  }
  return best;
}

TouchCheck::Best TouchCheck::SearchPair(const ShiftsPm& shift, int other, int iy0, int iy1, int ir0, int ir1, int stride,
                                        double& a_other) const noexcept {
  const Frame f = Prepare(shift);
  const auto& h = model_.g[static_cast<std::size_t>(other)];
  double sh = 0, hh = 0;
  for (std::size_t i = 0; i < kGratings; ++i) {
    sh += f.use[i] * f.s[i] * h[i];
    hh += f.use[i] * static_cast<double>(h[i]) * h[i];
  }
  Best best{-1, std::numeric_limits<double>::infinity(), 0.0};
  for (int iy = std::max(0, iy0); iy <= std::min(model_.ny - 1, iy1); iy += stride) {
    for (int ir = std::max(0, ir0); ir <= std::min(model_.nr - 1, ir1); ir += stride) {
      const int node = iy * model_.nr + ir;
      if (node == other) continue;
      const auto& g = model_.g[static_cast<std::size_t>(node)];
      double sg = 0, gg = 0, gh = 0;
      for (std::size_t i = 0; i < kGratings; ++i) {
        sg += f.use[i] * f.s[i] * g[i];
        gg += f.use[i] * static_cast<double>(g[i]) * g[i];
        gh += f.use[i] * static_cast<double>(g[i]) * h[i];
      }
      // Least squares of s on (g, h), both amplitudes >= 0 (else that node does not make a pair).
      const double det = gg * hh - gh * gh;
      if (!(det > 1e-9 * gg * hh)) continue;
      const double a = (sg * hh - sh * gh) / det, b = (sh * gg - sg * gh) / det;
      if (a <= 0 || b <= 0) continue;
      const double cost = f.ss - (a * sg + b * sh);
      if (cost < best.cost) {
        best = {node, cost, a};
        a_other = b;
      }
    }
  }
  return best;
}

double TouchCheck::Unexplained(const ShiftsPm& shift) const noexcept {
  const Best coarse = SearchOne(shift, 0, model_.ny - 1, 0, model_.nr - 1, kStride);
  if (coarse.node < 0) return coarse.cost;
  const int iy = coarse.node / model_.nr, ir = coarse.node % model_.nr;
  const Best fine = SearchOne(shift, iy - kStride, iy + kStride, ir - kStride, ir + kStride, 1);
  return std::min(coarse.cost, fine.cost);
}

Touch TouchCheck::Place(int node, double amplitude) const noexcept {
  return Touch{model_.y0_mm + (node / model_.nr) * model_.dy_mm, model_.r0_deg + (node % model_.nr) * model_.dr_deg,
               std::max(0.0, Force(amplitude))};
}

double TouchCheck::Force(double amplitude) const noexcept {
  // amplitude = F (1 + c F)
  const double c = model_.stiffening;
  if (std::abs(c) < 1e-9) return amplitude;
  const double disc = 1.0 + 4.0 * c * amplitude;
  return disc > 0 ? (std::sqrt(disc) - 1.0) / (2.0 * c) : amplitude;
}

TouchVerdict TouchCheck::Check(const ShiftsPm& shift, double y_mm, double r_deg, bool fit_pair,
                               bool confirm_anywhere, int window_nodes) const noexcept {
  TouchVerdict v;
  const Frame f = Prepare(shift);
  if (limit_ <= 0 || f.n < 4 || model_.g.empty()) return v;
  const double energy = f.ss + f.n * kNoisePm * kNoisePm;
  const int cy = static_cast<int>(std::lround((y_mm - model_.y0_mm) / model_.dy_mm));
  const int cr = static_cast<int>(std::lround((r_deg - model_.r0_deg) / model_.dr_deg));
  const int w = std::max(0, window_nodes);
  const Best one = SearchOne(shift, cy - w, cy + w, cr - w, cr + w, 1);
  v.misfit = std::clamp(one.cost / energy, 0.0, 1.0);
  if (one.node >= 0) v.touch[0] = Place(one.node, one.a);
  if (v.misfit <= limit_) return v;
  if (confirm_anywhere) {
    const double anywhere = std::clamp(Unexplained(shift) / energy, 0.0, 1.0);
    if (anywhere <= limit_) {
      v.misfit = anywhere;
      return v;
    }
  }
  v.multiple = true;
  if (!fit_pair) return v;
  // Two touches: start from the best single touch anywhere, then search each place with the other held
  // (over the map every kStride nodes, then refined), keeping a move only when it lowers the cost.
  const Best first = SearchOne(shift, 0, model_.ny - 1, 0, model_.nr - 1, kStride);
  if (first.node < 0) return v;
  struct Pair {
    int p = -1, q = -1;
    double a_p = 0, a_q = 0, cost = std::numeric_limits<double>::infinity();
  };
  const auto partner = [&](int fixed) {
    Pair out;
    double a_fixed = 0;
    Best b = SearchPair(shift, fixed, 0, model_.ny - 1, 0, model_.nr - 1, kStride, a_fixed);
    if (b.node < 0) return out;
    const int by = b.node / model_.nr, br = b.node % model_.nr;
    double a_fixed2 = 0;
    const Best fine = SearchPair(shift, fixed, by - kWindow, by + kWindow, br - kWindow, br + kWindow, 1, a_fixed2);
    if (fine.node >= 0 && fine.cost < b.cost) {
      b = fine;
      a_fixed = a_fixed2;
    }
    return Pair{fixed, b.node, a_fixed, b.a, b.cost};
  };
  Pair best = partner(first.node);
  if (best.q < 0) return v;
  for (int pass = 0; pass < 2; ++pass) {
    const Pair moved = partner(best.q);  // hold q, move p
    if (!(moved.q >= 0 && moved.cost < best.cost)) break;
    best = moved;
  }
  // Polish each place with the other held, at full resolution in its window.
  for (int k = 0; k < 2; ++k) {
    const int moving = k == 0 ? best.p : best.q, fixed = k == 0 ? best.q : best.p;
    const int my = moving / model_.nr, mr = moving % model_.nr;
    double a_fixed = 0;
    const Best b = SearchPair(shift, fixed, my - kWindow, my + kWindow, mr - kWindow, mr + kWindow, 1, a_fixed);
    if (b.node < 0) continue;
    best = Pair{fixed, b.node, a_fixed, b.a, b.cost};
  }
  const double pair_cost = best.cost;
  const int p_node = best.p, q_node = best.q;
  v.misfit_two = std::clamp(pair_cost / energy, 0.0, 1.0);
  // The pair explains the frame when it leaves at most the limit's misfit (what one touch is allowed).
  if (!(v.misfit_two <= limit_)) return v;
  v.found = 2;
  SolvePair(shift, p_node, q_node, v);
  return v;
}

void TouchCheck::SolvePair(const ShiftsPm& shift, int p, int q, TouchVerdict& v) const noexcept {
  const Frame f = Prepare(shift);
  const auto& g = model_.g[static_cast<std::size_t>(p)];
  const auto& h = model_.g[static_cast<std::size_t>(q)];
  double sg = 0, sh = 0, gg = 0, hh = 0, gh = 0;
  for (std::size_t i = 0; i < kGratings; ++i) {
    sg += f.use[i] * f.s[i] * g[i];
    sh += f.use[i] * f.s[i] * h[i];
    gg += f.use[i] * static_cast<double>(g[i]) * g[i];
    hh += f.use[i] * static_cast<double>(h[i]) * h[i];
    gh += f.use[i] * static_cast<double>(g[i]) * h[i];
  }
  const double det = gg * hh - gh * gh;
  double a = 0, b = 0;
  if (det > 1e-9 * gg * hh && gg > 0 && hh > 0) {
    a = (sg * hh - sh * gh) / det;
    b = (sh * gg - sg * gh) / det;
    if (a < 0) {
      a = 0;
      b = std::max(0.0, sh / hh);
    } else if (b < 0) {
      b = 0;
      a = std::max(0.0, sg / gg);
    }
  }
  v.touch[0] = Place(p, a);
  v.touch[1] = Place(q, b);
  v.touch[0].node = p;
  v.touch[1].node = q;
  for (std::size_t i = 0; i < kGratings; ++i) {
    v.touch[0].gain_pm_per_n = std::max(v.touch[0].gain_pm_per_n, std::abs(static_cast<double>(g[i])));
    v.touch[1].gain_pm_per_n = std::max(v.touch[1].gain_pm_per_n, std::abs(static_cast<double>(h[i])));
  }
  if (!(det > 1e-9 * gg * hh && gg > 0 && hh > 0) || f.n <= 2) {
    v.touch[0].force_sd_n = v.touch[1].force_sd_n = std::numeric_limits<double>::infinity();
    return;
  }
  // The residual per grating is the noise the amplitudes are read against (the map's own error grows with the
  // force, so it is in the residual too); never below the interrogator's and the baseline's kNoisePm.
  const double cost = std::max(0.0, f.ss - 2 * (a * sg + b * sh) + a * a * gg + 2 * a * b * gh + b * b * hh);
  const double noise2 = std::max(kNoisePm * kNoisePm, cost / (f.n - 2));
  const double sd_a = std::sqrt(noise2 * hh / det), sd_b = std::sqrt(noise2 * gg / det);
  // amplitude = F (1 + c F): dF/da = 1 / (1 + 2 c F).
  const auto sd_force = [&](double sd_amp, double force) {
    const double slope = 1.0 + 2.0 * model_.stiffening * force;
    return slope > 0.1 ? sd_amp / slope : sd_amp / 0.1;
  };
  v.touch[0].force_sd_n = sd_force(sd_a, v.touch[0].force_n);
  v.touch[1].force_sd_n = sd_force(sd_b, v.touch[1].force_n);
}

void TouchCheck::Amplitudes(const ShiftsPm& shift, TouchVerdict& pair) const noexcept {
  const int p = pair.touch[0].node, q = pair.touch[1].node;
  const int nodes = model_.ny * model_.nr;
  if (pair.found != 2 || p < 0 || q < 0 || p >= nodes || q >= nodes) return;
  SolvePair(shift, p, q, pair);
}

v1::ResponseMap ToProto(const ResponseModel& m, double multiple_misfit, const std::string& source) {
  v1::ResponseMap p;
  p.set_y0_mm(m.y0_mm);
  p.set_r0_deg(m.r0_deg);
  p.set_dy_mm(m.dy_mm);
  p.set_dr_deg(m.dr_deg);
  p.set_ny(static_cast<std::uint32_t>(m.ny));
  p.set_nr(static_cast<std::uint32_t>(m.nr));
  for (const auto& node : m.g) {
    for (float v : node) p.add_g_pm_per_n(v);
  }
  p.set_stiffening(m.stiffening);
  p.set_multiple_misfit(multiple_misfit);
  p.set_source(source);
  return p;
}

ResponseModel FromProto(const v1::ResponseMap& p) {
  ResponseModel m;
  const auto bad = [](const std::string& what) { return InputError("response map: " + what); };
  // Bounded so that a flagged frame's two-touch fit stays well inside a 1 kHz frame period (the shipped maps:
  // 81 x 41 nodes of 1.5 mm, about 80 us; the cost grows with the node count).
  constexpr std::uint32_t kMaxNodes = 8000;
  if (!(p.ny() >= 2 && p.nr() >= 2 && static_cast<std::uint64_t>(p.ny()) * p.nr() <= kMaxNodes)) {
    throw bad("ny and nr must be at least 2 and ny * nr at most " + std::to_string(kMaxNodes) + " (got " +
              std::to_string(p.ny()) + " x " + std::to_string(p.nr()) + ")");
  }
  if (!(p.dy_mm() >= 0.1 && p.dr_deg() >= 0.1 && p.dy_mm() <= 100 && p.dr_deg() <= 100)) {
    throw bad("dy_mm and dr_deg must be 0.1..100");
  }
  if (!std::isfinite(p.y0_mm()) || !std::isfinite(p.r0_deg()) || !(std::abs(p.stiffening()) <= 1.0)) {
    throw bad("y0_mm, r0_deg must be finite and |stiffening| <= 1");
  }
  const std::size_t nodes = static_cast<std::size_t>(p.ny()) * p.nr();
  if (static_cast<std::size_t>(p.g_pm_per_n_size()) != nodes * kGratings) {
    throw bad("g_pm_per_n holds " + std::to_string(p.g_pm_per_n_size()) + " values, ny * nr * 16 = " +
              std::to_string(nodes * kGratings) + " expected");
  }
  m.y0_mm = p.y0_mm();
  m.r0_deg = p.r0_deg();
  m.dy_mm = p.dy_mm();
  m.dr_deg = p.dr_deg();
  m.ny = static_cast<int>(p.ny());
  m.nr = static_cast<int>(p.nr());
  m.stiffening = p.stiffening();
  m.g.resize(nodes);
  for (std::size_t k = 0; k < nodes; ++k) {
    for (std::size_t i = 0; i < kGratings; ++i) {
      const float v = p.g_pm_per_n(static_cast<int>(k * kGratings + i));
      if (!std::isfinite(v)) throw bad("a sensitivity is not finite (node " + std::to_string(k) + ")");
      m.g[k][i] = v;
    }
  }
  return m;
}

}  // namespace ruffini::decode
