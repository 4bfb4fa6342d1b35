#pragma once
// Contact mechanics of a probe pressed into the bonded silicone layer.
// Force-depth law: Dimitriadis et al. (2002), a sphere indenting a thin elastic layer bonded to a rigid
// substrate, F = 4E/(3(1-nu^2)) R^1/2 d^3/2 * P(chi), chi = sqrt(R d)/h, with the bonded-case polynomial
// P = 1 - 2a/pi chi + 4a^2/pi^2 chi^2 - 8/pi^3 (a^3 + 4 pi^2 b/15) chi^3 + 16a/pi^4 (a^3 + 3 pi^2 b/5) chi^4,
// a = -(1.2876 - 1.4678 nu + 1.3442 nu^2)/(1-nu), b = (0.6387 - 1.0277 nu + 1.5164 nu^2)/(1-nu).
// Contact radius a_c = sqrt(R d) (geometric), capped at the probe radius.
#include <vector>

namespace ruffini::twin {

struct Probe {
  enum class Shape { kSphere, kPoint };
  Shape shape = Shape::kSphere;
  double radius_mm = 5.5;  // sphere radius, or the tip radius of a point-like probe (von Frey filament)
};

class ContactLaw {
 public:
  ContactLaw(double thickness_mm, double youngs_modulus_kpa, double poisson_ratio, double probe_radius_mm);

  [[nodiscard]] double ForceN(double depth_mm) const noexcept;  // Dimitriadis law
  // Inverse of ForceN (monotone); forces beyond the table's end return the deepest depth. noexcept, O(1).
  [[nodiscard]] double DepthMm(double force_n) const noexcept;
  [[nodiscard]] double ContactRadiusMm(double force_n) const noexcept;
  [[nodiscard]] double max_depth_mm() const noexcept { return max_depth_mm_; }
  // Beyond 30 % nominal compression (depth / thickness) linear elasticity no longer describes the layer:
  // the twin saturates the response at this force and flags the frame.
  static constexpr double kLinearCompressionLimit = 0.3;
  [[nodiscard]] double linear_limit_force_n() const noexcept { return ForceN(kLinearCompressionLimit * h_); }

 private:
  double h_, e_eff_mpa_, radius_, alpha_, beta_;
  double max_depth_mm_;
  double df_;                    // force step of the inverse table
  std::vector<double> depth_of_force_;
};

}  // namespace ruffini::twin
