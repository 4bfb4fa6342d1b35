#include "ruffini/twin/contact.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace ruffini::twin {

ContactLaw::ContactLaw(double thickness_mm, double youngs_modulus_kpa, double nu, double probe_radius_mm, Yeoh yeoh)
    : h_(thickness_mm),
      e_eff_mpa_(youngs_modulus_kpa * 1e-3 * 4.0 / (3.0 * (1.0 - nu * nu))),
      radius_(probe_radius_mm),
      alpha_(-(1.2876 - 1.4678 * nu + 1.3442 * nu * nu) / (1.0 - nu)),
      beta_((0.6387 - 1.0277 * nu + 1.5164 * nu * nu) / (1.0 - nu)),
      max_depth_mm_(0.9 * thickness_mm) {
  // Tabulate depth(force) on a uniform force grid up to the force at 90 % of the layer thickness
  // (beyond that the layer is crushed: the twin clips there and flags saturation).
  const double f_max = ForceN(max_depth_mm_);
  const int n = 8192;
  df_ = f_max / (n - 1);
  depth_of_force_.resize(n);
  double lo = 0.0;
  for (int i = 0; i < n; ++i) {
    const double target = df_ * i;
    double a = lo, b = max_depth_mm_;
    for (int it = 0; it < 60; ++it) {
      const double m = 0.5 * (a + b);
      (ForceN(m) < target ? a : b) = m;
    }
    depth_of_force_[static_cast<std::size_t>(i)] = lo = 0.5 * (a + b);
  }
  // The hard-press law beyond the linear limit: a table uniform in log force up to the bottomed-out force.
  yeoh_ = yeoh;
  const double d_lin = kLinearCompressionLimit * h_;
  f_lin_ = ForceN(d_lin);
  b_lin_ = Stiffening(d_lin);
  const double d_bot = kBottomCompression * h_;
  const double f_bot = HardForceN(d_bot);
  const int m = 4096;
  log_f_lin_ = std::log(f_lin_);
  dlog_f_ = (std::log(f_bot) - log_f_lin_) / (m - 1);
  hard_depth_.resize(m);
  for (int i = 0; i < m; ++i) {
    const double target = std::exp(log_f_lin_ + dlog_f_ * i);
    double a = d_lin, b = d_bot;
    for (int it = 0; it < 60; ++it) {
      const double mid = 0.5 * (a + b);
      (HardForceN(mid) < target ? a : b) = mid;
    }
    hard_depth_[static_cast<std::size_t>(i)] = 0.5 * (a + b);
  }
  hard_depth_.front() = d_lin;
  hard_depth_.back() = d_bot;
}

double ContactLaw::Stiffening(double depth_mm) const noexcept {
  const double lambda = 1.0 - std::clamp(depth_mm / h_, 1e-9, kBottomCompression);
  const double i1 = lambda * lambda + 2.0 / lambda - 3.0;
  const double w1 = yeoh_.c1_pa + 2.0 * yeoh_.c2_pa * i1 + 3.0 * yeoh_.c3_pa * i1 * i1;
  return 2.0 * (lambda - 1.0 / (lambda * lambda)) * w1 / (6.0 * yeoh_.c1_pa * (lambda - 1.0));
}

double ContactLaw::HardForceN(double d) const noexcept {
  const double d_lin = kLinearCompressionLimit * h_;
  if (!(d > d_lin)) return ForceN(d);
  return ForceN(d) * Stiffening(d) / b_lin_;
}

double ContactLaw::HardDepthMm(double force_n) const noexcept {
  if (!(force_n > f_lin_)) return DepthMm(force_n);
  const double x = (std::log(force_n) - log_f_lin_) / dlog_f_;
  if (!(x < static_cast<double>(hard_depth_.size() - 1))) return hard_depth_.back();  // also catches inf
  const auto i = static_cast<std::size_t>(x);
  const double w = x - static_cast<double>(i);
  return hard_depth_[i] * (1 - w) + hard_depth_[i + 1] * w;
}

double ContactLaw::StrainForceN(double force_n) const noexcept {
  if (!(force_n > f_lin_)) return force_n;
  return ForceN(HardDepthMm(force_n));
}

double ContactLaw::ForceN(double d) const noexcept {
  if (!(d > 0.0)) return 0.0;
  const double pi = std::numbers::pi;
  const double chi = std::sqrt(radius_ * d) / h_;
  const double a = alpha_, b = beta_;
  const double poly = 1.0 - 2.0 * a / pi * chi + 4.0 * a * a / (pi * pi) * chi * chi -
                      8.0 / (pi * pi * pi) * (a * a * a + 4.0 * pi * pi * b / 15.0) * chi * chi * chi +
                      16.0 * a / (pi * pi * pi * pi) * (a * a * a + 3.0 * pi * pi * b / 5.0) * chi * chi * chi * chi;
  return e_eff_mpa_ * std::sqrt(radius_) * std::pow(d, 1.5) * poly;
}

double ContactLaw::DepthMm(double force_n) const noexcept {
  if (!(force_n > 0.0)) return 0.0;
  const double x = force_n / df_;
  if (!(x < static_cast<double>(depth_of_force_.size() - 1))) return max_depth_mm_;  // also catches inf
  const auto i = static_cast<std::size_t>(x);
  const double w = x - static_cast<double>(i);
  return depth_of_force_[i] * (1 - w) + depth_of_force_[i + 1] * w;
}

double ContactLaw::ContactRadiusMm(double force_n) const noexcept {
  return std::min(radius_, std::sqrt(radius_ * DepthMm(force_n)));
}

}  // namespace ruffini::twin
