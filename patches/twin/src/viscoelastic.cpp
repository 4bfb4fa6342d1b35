#include "ruffini/twin/viscoelastic.h"

#include <cmath>
#include <string>

#include "ruffini/error.h"

namespace ruffini::twin {

ViscoelasticFilter::ViscoelasticFilter(const ViscoelasticEffect& e, double dt_s) {
  if (e.terms.size() > kMaxTerms) {
    throw InputError("viscoelastic: " + std::to_string(e.terms.size()) + " Prony terms; at most " +
                     std::to_string(kMaxTerms) + " are supported");
  }
  if (!(dt_s > 0.0)) throw InputError("viscoelastic: the frame period must be positive");
  for (const PronyTerm& t : e.terms) {
    if (!(t.g >= 0.0) || !(t.tau_s > 0.0)) {
      throw InputError("viscoelastic: every Prony term needs g >= 0 and tau_s > 0");
    }
    g_[n_] = t.g;
    alpha_[n_] = -std::expm1(-dt_s / t.tau_s);  // 1 - exp(-dt / tau), accurate for dt << tau
    ++n_;
  }
}

double ViscoelasticFilter::Step(double force_n) noexcept {
  double eff = force_n;
  for (std::size_t k = 0; k < n_; ++k) {
    x_[k] += (force_n - x_[k]) * alpha_[k];
    eff += g_[k] * x_[k];
  }
  return eff;
}

double ViscoelasticFilter::residual_n() const noexcept {
  double r = 0.0;
  for (std::size_t k = 0; k < n_; ++k) r += g_[k] * x_[k];
  return r;
}

ViscoelasticSites::ViscoelasticSites(const ViscoelasticEffect* e, double dt_s, const Probe& probe)
    : enabled_(e != nullptr), probe_(probe) {
  if (enabled_) {
    for (auto& f : filters_) f = ViscoelasticFilter(*e, dt_s);
  }
}

void ViscoelasticSites::MoveTo(const patch::SurfacePoint& at) noexcept {
  if (placed_) current_ = (current_ + 1) % kSites;
  placed_ = true;
  filters_[current_].Reset();
  at_[current_] = at;
  used_[current_] = true;
}

std::span<const Contact> ViscoelasticSites::Step(double force_n) noexcept {
  std::size_t n = 0;
  if (!enabled_) {
    if (placed_ && force_n != 0.0) out_[n++] = Contact{at_[current_], force_n, probe_};
    return {out_.data(), n};
  }
  for (std::size_t i = 0; i < kSites; ++i) {
    if (!used_[i]) continue;
    const double applied = (placed_ && i == current_) ? force_n : 0.0;
    const double eff = filters_[i].Step(applied);
    if (eff != 0.0) out_[n++] = Contact{at_[i], eff, probe_};
  }
  return {out_.data(), n};
}

}  // namespace ruffini::twin
