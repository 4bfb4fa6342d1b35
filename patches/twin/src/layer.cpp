#include "ruffini/twin/layer.h"

#include <Eigen/Dense>
#include <cmath>
#include <numbers>

namespace ruffini::twin {
namespace {

// Values and first three z-derivatives of the four basis functions at depth z, each divided by the power
// of k its derivative order brings (so entries stay O(1) for every k): row d holds g^(d)(z) / k^d.
Eigen::Matrix4d Basis(double k, double z, double h) {
  const double x = k * z, s = k * (h - z);
  const double ex = std::exp(-x), es = std::exp(-s);
  Eigen::Matrix4d b;
  // g1 = e^{-kz}
  b.col(0) << ex, -ex, ex, -ex;
  // g2 = kz e^{-kz}: g' = k e(1 - x), g'' = k^2 e(x - 2), g''' = k^3 e(3 - x)
  b.col(1) << x * ex, ex * (1 - x), ex * (x - 2), ex * (3 - x);
  // g3 = e^{-k(h-z)}: every derivative brings +k
  b.col(2) << es, es, es, es;
  // g4 = k(h-z) e^{-k(h-z)}: d/dz = -d/ds with s = h - z
  b.col(3) << s * es, -es * (1 - s), es * (s - 2), -es * (3 - s);
  return b;
}

}  // namespace

// Bessel J0 and J1 by the rational/asymptotic approximations of Abramowitz & Stegun 9.4.1-9.4.6
// (absolute error < 1e-7). Hand-written on purpose: libstdc++'s std::cyl_bessel_j is exact but costs
// ~150 ns a call, and building a twin needs ~2 million calls; these cost ~10 ns. Tested against
// std::cyl_bessel_j (LayerTest.FastBesselMatchesTheLibrary).
void BesselJ01(double x, double& j0, double& j1) noexcept {
  const double ax = std::abs(x);
  if (ax <= 3.0) {
    const double y = (x / 3.0) * (x / 3.0);
    j0 = 1.0 + y * (-2.2499997 + y * (1.2656208 + y * (-0.3163866 + y * (0.0444479 + y * (-0.0039444 + y * 0.0002100)))));
    j1 = x * (0.5 + y * (-0.56249985 + y * (0.21093573 + y * (-0.03954289 + y * (0.00443319 + y * (-0.00031761 + y * 0.00001109))))));
    return;
  }
  const double t = 3.0 / ax;
  const double f0 = 0.79788456 + t * (-0.00000077 + t * (-0.00552740 + t * (-0.00009512 + t * (0.00137237 + t * (-0.00072805 + t * 0.00014476)))));
  const double th0 = ax - 0.78539816 + t * (-0.04166397 + t * (-0.00003954 + t * (0.00262573 + t * (-0.00054125 + t * (-0.00029333 + t * 0.00013558)))));
  const double f1 = 0.79788456 + t * (0.00000156 + t * (0.01659667 + t * (0.00017105 + t * (-0.00249511 + t * (0.00113653 + t * -0.00020033)))));
  const double th1 = ax - 2.35619449 + t * (0.12499612 + t * (0.00005650 + t * (-0.00637879 + t * (0.00074348 + t * (0.00079824 + t * -0.00029166)))));
  const double s = 1.0 / std::sqrt(ax);
  j0 = s * f0 * std::cos(th0);
  j1 = s * f1 * std::cos(th1) * (x < 0 ? -1.0 : 1.0);
}

namespace {
double Interpolate(const std::vector<double>& v, double dr, double r_mm) noexcept {
  const double x = r_mm / dr;
  if (!(x >= 0.0 && x < static_cast<double>(v.size()) - 1.0)) return 0.0;
  const auto i = static_cast<std::size_t>(x);
  const double w = x - static_cast<double>(i);
  return v[i] * (1 - w) + v[i + 1] * w;
}
}  // namespace

double StrainProfile::Rr(double r_mm) const noexcept { return Interpolate(eps_rr, dr_mm, r_mm); }
double StrainProfile::Tt(double r_mm) const noexcept { return Interpolate(eps_tt, dr_mm, r_mm); }

std::vector<StrainProfile> ComputeStrainProfiles(const LayerParams& layer, const std::vector<double>& radii,
                                                 double r_max_mm, double dr_mm) {
  const double nu = layer.poisson_ratio;
  const double h = layer.thickness_mm, zm = layer.depth_mm;
  const double g_mpa = layer.youngs_modulus_kpa * 1e-3 / (2.0 * (1.0 + nu));  // N/mm^2
  // Wavenumber grid: the fields decay like e^{-k min(z, h-z)}; stop where that is below 1e-13, and resolve
  // the Bessel oscillation at r_max with >= 25 points a period.
  const double depth_min = std::min(zm, h - zm);
  const double k_max = 30.0 / depth_min;
  const double dk = std::min(2.0 * std::numbers::pi / r_max_mm / 25.0, k_max / 2000.0);
  const auto nk = static_cast<std::size_t>(std::ceil(k_max / dk));
  const auto nr = static_cast<std::size_t>(std::floor(r_max_mm / dr_mm)) + 1;

  // Per k: the response of u_r at depth zm to a unit surface pressure mode, V(k) = U(k) / p(k).
  std::vector<double> ks(nk), v(nk);
  for (std::size_t j = 0; j < nk; ++j) {
    const double k = (static_cast<double>(j) + 0.5) * dk;
    ks[j] = k;
    const Eigen::Matrix4d b0 = Basis(k, 0.0, h), bh = Basis(k, h, h), bm = Basis(k, zm, h);
    Eigen::Matrix4d a;
    // s_zz(0) / k^3 = (1-nu) g''' - (2-nu) g'   (rows of Basis are already divided by k^d)
    a.row(0) = (1 - nu) * b0.row(3) - (2 - nu) * b0.row(1);
    // s_rz(0) / k^3 = nu g'' + (1-nu) g
    a.row(1) = nu * b0.row(2) + (1 - nu) * b0.row(0);
    // u_r(h) ∝ g'(h)
    a.row(2) = bh.row(1);
    // u_z(h) / k^2 ∝ (1-2nu) g'' - 2(1-nu) g
    a.row(3) = (1 - 2 * nu) * bh.row(2) - 2 * (1 - nu) * bh.row(0);
    Eigen::Vector4d rhs(-1.0, 0.0, 0.0, 0.0);  // s_zz = -p with p = 1, divided by k^3 below
    const Eigen::Vector4d c = a.fullPivLu().solve(rhs);
    // True coefficients are c / k^3; u_r = k f'(zm) / 2G with f'(zm) = k * (c . bm.row(1)) / k^3.
    v[j] = (c.dot(bm.row(1).transpose())) / (k * 2.0 * g_mpa);
  }

  std::vector<StrainProfile> out(radii.size());
  for (auto& p : out) {
    p.dr_mm = dr_mm;
    p.eps_rr.assign(nr, 0.0);
    p.eps_tt.assign(nr, 0.0);
  }
  // Load transforms per radius.
  std::vector<std::vector<double>> uk(radii.size(), std::vector<double>(nk));
  for (std::size_t a = 0; a < radii.size(); ++a) {
    for (std::size_t j = 0; j < nk; ++j) {
      const double x = ks[j] * radii[a];
      const double shape = x < 1e-3 ? 1.0 - x * x / 10.0 : 3.0 * (std::sin(x) - x * std::cos(x)) / (x * x * x);
      uk[a][j] = v[j] * shape / (2.0 * std::numbers::pi);
    }
  }
  for (std::size_t i = 0; i < nr; ++i) {
    const double r = static_cast<double>(i) * dr_mm;
    std::vector<double> ur(radii.size(), 0.0), d2(radii.size(), 0.0);
    for (std::size_t j = 0; j < nk; ++j) {
      const double k = ks[j];
      const double kr = k * r;
      double j0 = 0.0, j1 = 0.0;
      BesselJ01(kr, j0, j1);
      // For r = 0 use u_r / r -> int U k^2 / 2 dk (J1(x) / x -> 1/2).
      const double j1_over_r = r > 0 ? j1 / r : 0.5 * k;
      for (std::size_t a = 0; a < radii.size(); ++a) {
        ur[a] += uk[a][j] * j1_over_r * k;
        d2[a] += uk[a][j] * k * k * j0;
      }
    }
    for (std::size_t a = 0; a < radii.size(); ++a) {
      out[a].eps_tt[i] = ur[a] * dk;              // u_r / r
      out[a].eps_rr[i] = (d2[a] - ur[a]) * dk;    // du_r/dr
    }
  }
  return out;
}

BoussinesqStrain Boussinesq(double youngs_modulus_kpa, double nu, double z, double r) {
  const double g = youngs_modulus_kpa * 1e-3 / (2.0 * (1.0 + nu));
  const double c = 1.0 / (4.0 * std::numbers::pi * g);
  const double rr = std::hypot(r, z);
  // u_r = c [ r z / R^3 - (1-2nu) r / (R (R + z)) ]
  const double ur_over_r = c * (z / (rr * rr * rr) - (1 - 2 * nu) / (rr * (rr + z)));
  // d/dr of u_r
  const double d_first = z * (rr * rr - 3 * r * r) / std::pow(rr, 5);
  // d/dr [ r / (R (R+z)) ] = 1/(R(R+z)) - r^2 (2R + z) / (R^3 (R+z)^2)
  const double d_second = 1.0 / (rr * (rr + z)) - r * r * (2 * rr + z) / (rr * rr * rr * (rr + z) * (rr + z));
  return {c * (d_first - (1 - 2 * nu) * d_second), ur_over_r};
}

}  // namespace ruffini::twin
