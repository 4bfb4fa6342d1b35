#include "ruffini/decode/inversion.h"

#include <Eigen/LU>
#include <unsupported/Eigen/NonLinearOptimization>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "ruffini/error.h"

namespace ruffini::decode {

ResponseModel ResponseModel::Fit(const std::vector<ShiftsPm>& s, const std::vector<float>& force,
                                 const std::vector<float>& y, const std::vector<float>& r, const patch::Region& a,
                                 double radius_mm, double min_force_n) {
  ResponseModel m;
  m.surface_radius_mm = radius_mm;
  m.dy_mm = 3.0;
  m.dr_deg = 3.0;
  m.y0_mm = a.y_min_mm;
  m.r0_deg = a.r_min_deg;
  m.ny = static_cast<int>(std::ceil((a.y_max_mm - a.y_min_mm) / m.dy_mm)) + 1;
  m.nr = static_cast<int>(std::ceil((a.r_max_deg - a.r_min_deg) / m.dr_deg)) + 1;
  const auto nodes = static_cast<std::size_t>(m.ny * m.nr);
  // Two passes: g with c = 0 from moderate forces, then c from the ratio at all forces, then g again.
  for (int pass = 0; pass < 3; ++pass) {
    std::vector<std::array<double, 16>> num(nodes, std::array<double, 16>{});
    std::vector<double> den(nodes, 0.0);
    std::vector<double> ratio_x, ratio_y;
    for (std::size_t k = 0; k < s.size(); ++k) {
      const double f = force[k];
      if (!(f > min_force_n) || !std::isfinite(y[k]) || !std::isfinite(r[k])) continue;
      if (pass == 0 && f > 0.8) continue;
      if (pass == 1) {  // stiffening: observed / predicted against force, where the signal is strong
        std::array<double, 16> g{};
        m.Eval(y[k], r[k], g);
        double sg = 0, gg = 0;
        for (std::size_t i = 0; i < 16; ++i) {
          if (!std::isfinite(s[k][i])) continue;
          sg += s[k][i] * g[i];
          gg += g[i] * g[i];
        }
        if (gg > 0) {
          ratio_x.push_back(f);
          ratio_y.push_back(sg / (gg * f));
        }
        continue;
      }
      const double fe = f * (1.0 + m.stiffening * f);
      // Bilinear splat onto the 4 surrounding nodes.
      const double fy = std::clamp((y[k] - m.y0_mm) / m.dy_mm, 0.0, m.ny - 1.000001);
      const double fr = std::clamp((r[k] - m.r0_deg) / m.dr_deg, 0.0, m.nr - 1.000001);
      const int iy = static_cast<int>(fy), ir = static_cast<int>(fr);
      const double wy = fy - iy, wr = fr - ir;
      const double w[4] = {(1 - wy) * (1 - wr), (1 - wy) * wr, wy * (1 - wr), wy * wr};
      const int idx[4] = {iy * m.nr + ir, iy * m.nr + ir + 1, (iy + 1) * m.nr + ir, (iy + 1) * m.nr + ir + 1};
      for (int c = 0; c < 4; ++c) {
        const auto n = static_cast<std::size_t>(idx[c]);
        for (std::size_t i = 0; i < 16; ++i) num[n][i] += w[c] * (std::isfinite(s[k][i]) ? s[k][i] : 0.0) * fe;
        den[n] += w[c] * fe * fe;
      }
    }
    if (pass == 1) {
      // ratio = 1 + c f (least squares through the intercept-free form ratio - 1 = c f, using the mean level).
      if (ratio_x.empty()) continue;
      double mean_ratio_low = 0, n_low = 0, sxy = 0, sxx = 0;
      for (std::size_t k = 0; k < ratio_x.size(); ++k) {
        if (ratio_x[k] < 0.5) {
          mean_ratio_low += ratio_y[k];
          ++n_low;
        }
      }
      const double base = n_low > 0 ? mean_ratio_low / n_low : 1.0;
      for (std::size_t k = 0; k < ratio_x.size(); ++k) {
        sxy += ratio_x[k] * (ratio_y[k] / base - 1.0);
        sxx += ratio_x[k] * ratio_x[k];
      }
      m.stiffening = sxx > 0 ? std::clamp(sxy / sxx, -0.3, 0.3) : 0.0;
      continue;
    }
    m.g.assign(nodes, std::array<float, 16>{});
    std::vector<char> have(nodes, 0);
    std::size_t filled = 0;
    for (std::size_t n = 0; n < nodes; ++n) {
      if (den[n] > 1e-6) {
        for (std::size_t i = 0; i < 16; ++i) m.g[n][i] = static_cast<float>(num[n][i] / den[n]);
        have[n] = 1;
        ++filled;
      }
    }
    if (filled == 0) throw InputError("inversion: no frames above " + std::to_string(min_force_n) + " N with positions to learn from");
    // Nodes no indentation reached: average of their filled neighbours, repeated until all are set.
    while (filled < nodes) {
      std::vector<char> next = have;
      for (int iy = 0; iy < m.ny; ++iy) {
        for (int ir = 0; ir < m.nr; ++ir) {
          const auto n = static_cast<std::size_t>(iy * m.nr + ir);
          if (have[n]) continue;
          std::array<double, 16> acc{};
          int cnt = 0;
          for (const auto& d : {std::pair{-1, 0}, std::pair{1, 0}, std::pair{0, -1}, std::pair{0, 1}}) {
            const int jy = iy + d.first, jr = ir + d.second;
            if (jy < 0 || jy >= m.ny || jr < 0 || jr >= m.nr) continue;
            const auto nn = static_cast<std::size_t>(jy * m.nr + jr);
            if (!have[nn]) continue;
            for (std::size_t i = 0; i < 16; ++i) acc[i] += m.g[nn][i];
            ++cnt;
          }
          if (cnt == 0) continue;
          for (std::size_t i = 0; i < 16; ++i) m.g[n][i] = static_cast<float>(acc[i] / cnt);
          next[n] = 1;
          ++filled;
        }
      }
      have.swap(next);
    }
  }
  return m;
}

void ResponseModel::Eval(double y, double r, std::array<double, 16>& out, std::array<double, 16>* gy,
                         std::array<double, 16>* gr) const noexcept {
  const double fy = std::clamp((y - y0_mm) / dy_mm, 0.0, ny - 1.000001);
  const double fr = std::clamp((r - r0_deg) / dr_deg, 0.0, nr - 1.000001);
  const int iy = static_cast<int>(fy), ir = static_cast<int>(fr);
  const double wy = fy - iy, wr = fr - ir;
  const auto& a = g[static_cast<std::size_t>(iy * nr + ir)];
  const auto& b = g[static_cast<std::size_t>(iy * nr + ir + 1)];
  const auto& c = g[static_cast<std::size_t>((iy + 1) * nr + ir)];
  const auto& d = g[static_cast<std::size_t>((iy + 1) * nr + ir + 1)];
  for (std::size_t i = 0; i < 16; ++i) {
    out[i] = (1 - wy) * ((1 - wr) * a[i] + wr * b[i]) + wy * ((1 - wr) * c[i] + wr * d[i]);
    if (gy) (*gy)[i] = ((1 - wr) * (c[i] - a[i]) + wr * (d[i] - b[i])) / dy_mm;
    if (gr) (*gr)[i] = ((1 - wy) * (b[i] - a[i]) + wy * (d[i] - c[i])) / dr_deg;
  }
}

namespace {

struct FitFunctor {
  using Scalar = double;
  enum { InputsAtCompileTime = Eigen::Dynamic, ValuesAtCompileTime = Eigen::Dynamic };
  using InputType = Eigen::VectorXd;
  using ValueType = Eigen::VectorXd;
  using JacobianType = Eigen::MatrixXd;
  const ResponseModel* m;
  const ShiftsPm* s;
  std::array<int, 16> used;
  int n_used;
  [[nodiscard]] int inputs() const { return 3; }
  [[nodiscard]] int values() const { return n_used; }
  int operator()(const Eigen::VectorXd& x, Eigen::VectorXd& res) const {
    std::array<double, 16> g{};
    m->Eval(x[0], x[1], g);
    const double fe = x[2] * (1 + m->stiffening * x[2]);
    for (int k = 0; k < n_used; ++k) {
      const auto i = static_cast<std::size_t>(used[static_cast<std::size_t>(k)]);
      res[k] = (fe * g[i] - (*s)[i]) / m->noise_pm;
    }
    return 0;
  }
  int df(const Eigen::VectorXd& x, Eigen::MatrixXd& j) const {
    std::array<double, 16> g{}, gy{}, gr{};
    m->Eval(x[0], x[1], g, &gy, &gr);
    const double fe = x[2] * (1 + m->stiffening * x[2]), dfe = 1 + 2 * m->stiffening * x[2];
    for (int k = 0; k < n_used; ++k) {
      const auto i = static_cast<std::size_t>(used[static_cast<std::size_t>(k)]);
      j(k, 0) = fe * gy[i] / m->noise_pm;
      j(k, 1) = fe * gr[i] / m->noise_pm;
      j(k, 2) = dfe * g[i] / m->noise_pm;
    }
    return 0;
  }
};

}  // namespace

InversionDecoder::InversionDecoder(ResponseModel model, InversionOptions options)
    : model_(std::move(model)), options_(options) {
  const int st = std::max(1, options_.search_stride);
  for (int iy = 0; iy < model_.ny; iy += st) {
    for (int ir = 0; ir < model_.nr; ir += st) search_nodes_.push_back(iy * model_.nr + ir);
  }
}

InversionDecoder::Fit InversionDecoder::Solve(const ShiftsPm& s, int& used_count) const noexcept {
  FitFunctor fn{&model_, &s, {}, 0};
  for (int i = 0; i < 16; ++i) {
    if (std::isfinite(s[static_cast<std::size_t>(i)])) fn.used[static_cast<std::size_t>(fn.n_used++)] = i;
  }
  used_count = fn.n_used;
  Fit out{0, 0, 0, 0, 0, 0};
  // Coarse search: F in closed form (linear least squares) at each node.
  double best = 1e300;
  for (int node : search_nodes_) {
    const auto& g = model_.g[static_cast<std::size_t>(node)];
    double sg = 0, gg = 0, ss = 0;
    for (int k = 0; k < fn.n_used; ++k) {
      const auto i = static_cast<std::size_t>(fn.used[static_cast<std::size_t>(k)]);
      sg += s[i] * g[i];
      gg += static_cast<double>(g[i]) * g[i];
      ss += static_cast<double>(s[i]) * s[i];
    }
    if (!(gg > 0)) continue;
    const double cost = ss - sg * sg / gg;
    if (cost < best) {
      best = cost;
      out.y_mm = model_.y0_mm + (node / model_.nr) * model_.dy_mm;
      out.r_deg = model_.r0_deg + (node % model_.nr) * model_.dr_deg;
      out.force_n = std::max(0.0, sg / gg);
    }
  }
  Eigen::VectorXd x(3);
  x << out.y_mm, out.r_deg, std::max(out.force_n, 1e-3);
  if (options_.iterations > 0 && fn.n_used > 3) {
    Eigen::LevenbergMarquardt<FitFunctor> lm(fn);
    lm.parameters.maxfev = options_.iterations;
    if (lm.minimizeInit(x) != Eigen::LevenbergMarquardtSpace::ImproperInputParameters) {
      for (int it = 0; it < options_.iterations; ++it) {
        if (lm.minimizeOneStep(x) != Eigen::LevenbergMarquardtSpace::Running) break;
      }
    }
  }
  // Keep the estimate on the modelled area.
  x[0] = std::clamp(x[0], model_.y0_mm, model_.y0_mm + (model_.ny - 1) * model_.dy_mm);
  x[1] = std::clamp(x[1], model_.r0_deg, model_.r0_deg + (model_.nr - 1) * model_.dr_deg);
  x[2] = std::max(0.0, x[2]);
  Eigen::VectorXd res(fn.n_used);
  Eigen::MatrixXd jac(fn.n_used, 3);
  fn(x, res);
  fn.df(x, jac);
  const int dof = std::max(1, fn.n_used - 3);
  out.y_mm = x[0];
  out.r_deg = x[1];
  out.force_n = x[2];
  out.chi2_reduced = res.squaredNorm() / dof;
  const Eigen::Matrix3d jtj = jac.transpose() * jac;
  const Eigen::Matrix3d cov = jtj.fullPivLu().isInvertible() ? Eigen::Matrix3d(jtj.inverse() * std::max(1.0, out.chi2_reduced))
                                                             : Eigen::Matrix3d::Constant(1e6);
  const double mm_per_deg = model_.surface_radius_mm * std::numbers::pi / 180.0;
  out.sigma_y_mm = std::sqrt(std::max(0.0, cov(0, 0)));
  out.sigma_r_mm = std::sqrt(std::max(0.0, cov(1, 1))) * mm_per_deg;
  return out;
}

DecodeOutput InversionDecoder::Decode(const ShiftsPm& s) const noexcept {
  DecodeOutput o;
  int missing = 0;
  double peak = 0;
  for (float v : s) {
    if (!std::isfinite(v)) {
      ++missing;
    } else {
      peak = std::max(peak, static_cast<double>(std::abs(v)));
    }
  }
  o.missing = static_cast<std::uint8_t>(missing);
  if (missing > options_.max_missing) return o;
  o.valid = true;
  if (peak < options_.detect_pm) return o;  // untouched: force 0
  int used = 0;
  const Fit f = Solve(s, used);
  o.force_n = static_cast<float>(f.force_n);
  o.in_contact = f.force_n > 0.05;
  if (!o.in_contact) return o;
  o.located = true;
  o.y_mm = static_cast<float>(f.y_mm);
  o.r_deg = static_cast<float>(f.r_deg);
  o.location_sigma_mm = static_cast<float>(std::hypot(f.sigma_y_mm, f.sigma_r_mm));
  // A single contact explains the shifts to within the model's error: chi2 near its typical level. Two
  // touches or a lying grating leave large residuals, and the confidence drops.
  o.confidence = static_cast<float>(1.0 / (1.0 + f.chi2_reduced / 100.0));
  return o;
}

}  // namespace ruffini::decode
