#pragma once
// Viscoelastic silicone as a linear filter on the applied force (a Prony-series creep compliance).
//
//   F_eff(t) = F(t) + sum_k g_k x_k(t),   dx_k/dt = (F(t) - x_k(t)) / tau_k
//
// F is the force applied at one site, F_eff the force whose elastic strain field the gratings see. Under a
// held load F_eff creeps from F to (1 + sum g_k) F with the retardation times tau_k; after release it decays
// to zero with the same times (the residual a decoder may take for a "phantom contact"); on the way up x_k
// lags F (F_eff below its creep limit), on the way down it leads (F_eff above): the loading and unloading
// paths differ at the same force (hysteresis). Discretised exactly for a force held over each frame:
// x_k <- x_k + (F - x_k)(1 - exp(-dt / tau_k)).
//
// Sources. Platinum-cure silicones of the Dragon Skin / Ecoflex family relax and creep measurably:
//   - Case, White, Kramer, "Soft material characterization for robotic applications", Soft Robotics 2(2),
//     80-87 (2015), doi:10.1089/soro.2015.0002: stress-relaxation and cyclic tests of EcoFlex 00-30,
//     Smooth-Sil 950 and Sylgard 184; all relax under a held strain and show loading/unloading hysteresis.
//   - Porte, Eristoff, Agrawala, Kramer-Bottiglio, "Characterization of temperature and humidity dependence
//     in soft elastomer behavior", Soft Robotics (2023), doi:10.1089/soro.2023.0004: stress relaxation of
//     EcoFlex 00-30 and Dragon Skin 10 (the paper's cover) from -40 to 80 C.
//   - Liao, Hossain, Yao, "Ecoflex polymer of different Shore hardnesses: experimental investigations and
//     constitutive modelling", Mechanics of Materials 144 (2020) 103366: an equilibrium plus an overstress
//     (viscous) part; marked relaxation in virgin samples, much less after pre-stretching.
// We could read only these papers' abstracts here, not their fitted coefficients: the default terms
// (g = 0.05 / 0.04 / 0.03 at tau = 1 / 10 / 100 s, 12 % creep in all) are our assumption inside the range
// such relaxation tests describe (several % to ~15 % over seconds to minutes), not a fit. Refit them from
// Porte et al.'s Dragon Skin 10 curves when the data are at hand; a scene can set its own terms.
#include <array>
#include <cstddef>
#include <span>

#include "ruffini/patch/geometry.h"
#include "ruffini/twin/effects.h"
#include "ruffini/twin/twin.h"

namespace ruffini::twin {

// One site's filter. Default-constructed: the identity (no terms).
class ViscoelasticFilter {
 public:
  static constexpr std::size_t kMaxTerms = 4;

  ViscoelasticFilter() = default;
  // dt_s: the frame period. Throws InputError for more than kMaxTerms terms, g < 0, tau_s <= 0 or dt_s <= 0.
  ViscoelasticFilter(const ViscoelasticEffect& e, double dt_s);

  // Advances one frame under the applied force; returns F_eff.
  // Real-time safe: no allocation, no lock, no throw.
  double Step(double force_n) noexcept;
  // F_eff with no applied force now (what is left of earlier loads).
  [[nodiscard]] double residual_n() const noexcept;
  void Reset() noexcept { x_.fill(0.0); }

 private:
  std::size_t n_ = 0;
  std::array<double, kMaxTerms> g_{}, alpha_{}, x_{};
};

// The sites a probe has pressed lately, each with its filter, so the residual of an earlier press keeps
// fading where it was while the probe presses elsewhere. For protocols and the interrogator simulator.
class ViscoelasticSites {
 public:
  static constexpr std::size_t kSites = 4;  // the current site and the three before it

  // e == nullptr: no viscoelasticity; Step returns the applied contact only (or none when unloaded).
  ViscoelasticSites(const ViscoelasticEffect* e, double dt_s, const Probe& probe);

  // The probe moves to a new site (the oldest site's residual is dropped).
  // Real-time safe: no allocation, no lock, no throw.
  void MoveTo(const patch::SurfacePoint& at) noexcept;
  // One frame with force_n applied at the current site (0 = probe off the skin). Returns the contacts to
  // superpose (valid until the next call). Real-time safe: no allocation, no lock, no throw.
  std::span<const Contact> Step(double force_n) noexcept;

 private:
  bool enabled_ = false;
  Probe probe_;
  std::size_t current_ = 0;
  bool placed_ = false;
  std::array<ViscoelasticFilter, kSites> filters_{};
  std::array<patch::SurfacePoint, kSites> at_{};
  std::array<bool, kSites> used_{};
  std::array<Contact, kSites> out_{};
};

}  // namespace ruffini::twin
