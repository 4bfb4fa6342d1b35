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
                                 double radius_mm, double min_force_n, const patch::Region* within) {
  // 1. Sites: consecutive frames at one probe position (an indentation). At each site, least squares of
  //    every grating's shift on (F, F^2) gives its sensitivity g = slope at small force and the curvature.
  struct Site {
    double y, r;
    std::array<double, kGratings> g;
    double curvature;  // b / a of s = a F + b F^2 on the strongest grating
  };
  std::vector<Site> sites;
  std::size_t k = 0;
  while (k < s.size()) {
    std::size_t e = k;
    while (e < s.size() && y[e] == y[k] && r[e] == r[k]) ++e;
    if (std::isfinite(y[k]) && std::isfinite(r[k])) {
      double s11 = 0, s12 = 0, s22 = 0;
      std::array<double, kGratings> t1{}, t2{};
      int n = 0;
      for (std::size_t j = k; j < e; ++j) {
        const double f = force[j];
        if (!(f > min_force_n)) continue;
        s11 += f * f;
        s12 += f * f * f;
        s22 += f * f * f * f;
        for (std::size_t i = 0; i < 16; ++i) {
          const double v = std::isfinite(s[j][i]) ? s[j][i] : 0.0;
          t1[i] += v * f;
          t2[i] += v * f * f;
        }
        ++n;
      }
      const double det = s11 * s22 - s12 * s12;
      if (n >= 8 && det > 1e-12) {
        Site site{y[k], r[k], {}, 0.0};
        double best = 0, best_b = 0;
        for (std::size_t i = 0; i < 16; ++i) {
          const double ai = (t1[i] * s22 - t2[i] * s12) / det, bi = (t2[i] * s11 - t1[i] * s12) / det;
          site.g[i] = ai;
          if (std::abs(ai) > std::abs(best)) {
            best = ai;
            best_b = bi;
          }
        }
        // Curvature only where the signal is clear (> 5 pm/N on some grating); the sensitivities always count.
        site.curvature = std::abs(best) > 5.0 ? best_b / best : std::nan("");
        sites.push_back(site);
      }
    }
    k = e;
  }
  if (sites.empty()) {
    throw InputError("inversion: no indentation with frames above " + std::to_string(min_force_n) + " N to learn from");
  }
  ResponseModel m;
  m.surface_radius_mm = radius_mm;
  m.dy_mm = 1.5;
  m.dr_deg = 1.5 * 180.0 / (std::numbers::pi * radius_mm);  // 1.5 mm of arc
  m.y0_mm = a.y_min_mm;
  m.r0_deg = a.r_min_deg;
  // (A whole number of steps, up to rounding, is that many steps: 1e-6 of a step of slack.)
  m.ny = static_cast<int>(std::ceil((a.y_max_mm - a.y_min_mm) / m.dy_mm - 1e-6)) + 1;
  m.nr = static_cast<int>(std::ceil((a.r_max_deg - a.r_min_deg) / m.dr_deg - 1e-6)) + 1;
  // The last node lies on or up to a step past the area's far edge (the grid has always been laid out so; the
  // indented area's maps keep it), but never past `within` (the patch: a map reaching beyond it is refused by the
  // pipeline). A grid that would is squeezed to end on `within`'s edge: the step shrinks to fit that many nodes
  // (`fit-response --area whole`, whose area is the patch, once wrote a map the decoders refused).
  if (within != nullptr) {
    const auto fit_step = [](double start, double end, int n, double& step) {
      if (n > 1 && start + (n - 1) * step > end + 1e-6 * step) step = (end - start) / (n - 1);
    };
    fit_step(m.y0_mm, within->y_max_mm, m.ny, m.dy_mm);
    fit_step(m.r0_deg, within->r_max_deg, m.nr, m.dr_deg);
  }
  std::vector<double> curv;
  for (const auto& st : sites) {
    if (std::isfinite(st.curvature)) curv.push_back(st.curvature);
  }
  if (!curv.empty()) {
    std::nth_element(curv.begin(), curv.begin() + static_cast<std::ptrdiff_t>(curv.size() / 2), curv.end());
    m.stiffening = std::clamp(curv[curv.size() / 2], -0.3, 0.3);
  }
  // 2. The map: Gaussian kernel regression of the site sensitivities (bandwidth h on the surface). The
  //    bandwidth adapts to the site density: the local sites must cover the kernel.
  const double mm_per_deg = std::numbers::pi * radius_mm / 180.0;
  const double area_mm2 = (a.y_max_mm - a.y_min_mm) * (a.r_max_deg - a.r_min_deg) * mm_per_deg;
  const double spacing = std::sqrt(area_mm2 / static_cast<double>(sites.size()));
  const double h = std::clamp(0.6 * spacing, 0.75, 6.0);
  const double cutoff2 = 9.0 * h * h;
  m.g.assign(static_cast<std::size_t>(m.ny * m.nr), std::array<float, kGratings>{});
  for (int iy = 0; iy < m.ny; ++iy) {
    for (int ir = 0; ir < m.nr; ++ir) {
      const double ny_mm = m.y0_mm + iy * m.dy_mm, nr_deg = m.r0_deg + ir * m.dr_deg;
      std::array<double, kGratings> acc{};
      double wsum = 0, nearest = 1e300;
      std::size_t nearest_site = 0;
      for (std::size_t j = 0; j < sites.size(); ++j) {
        const double dy = sites[j].y - ny_mm, da = (sites[j].r - nr_deg) * mm_per_deg;
        const double d2 = dy * dy + da * da;
        if (d2 < nearest) {
          nearest = d2;
          nearest_site = j;
        }
        if (d2 > cutoff2) continue;
        const double w = std::exp(-0.5 * d2 / (h * h));
        for (std::size_t i = 0; i < 16; ++i) acc[i] += w * sites[j].g[i];
        wsum += w;
      }
      auto& out = m.g[static_cast<std::size_t>(iy * m.nr + ir)];
      for (std::size_t i = 0; i < 16; ++i) {
        out[i] = static_cast<float>(wsum > 1e-9 ? acc[i] / wsum : sites[nearest_site].g[i]);
      }
    }
  }
  return m;
}

void ResponseModel::Eval(double y, double r, std::array<double, kGratings>& out, std::array<double, kGratings>* gy,
                         std::array<double, kGratings>* gr) const noexcept {
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
    std::array<double, kGratings> g{};
    m->Eval(x[0], x[1], g);
    const double fe = x[2] * (1 + m->stiffening * x[2]);
    for (int k = 0; k < n_used; ++k) {
      const auto i = static_cast<std::size_t>(used[static_cast<std::size_t>(k)]);
      res[k] = (fe * g[i] - (*s)[i]) / m->noise_pm;
    }
    return 0;
  }
  int df(const Eigen::VectorXd& x, Eigen::MatrixXd& j) const {
    std::array<double, kGratings> g{}, gy{}, gr{};
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
  o.cov_yy_mm2 = static_cast<float>(f.sigma_y_mm * f.sigma_y_mm);
  o.cov_aa_mm2 = static_cast<float>(f.sigma_r_mm * f.sigma_r_mm);
  // A single contact explains the shifts to within the model's error: chi2 near its typical level. Two
  // touches or a lying grating leave large residuals, and the confidence drops.
  o.confidence = static_cast<float>(1.0 / (1.0 + f.chi2_reduced / 100.0));
  return o;
}

}  // namespace ruffini::decode
